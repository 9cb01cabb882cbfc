#pragma once
// What the module's files share: arrays over C++ memory, keyword arguments as a frame
// request, and the Frame a simulation returns.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <tbb/global_control.h>

#include "imaging/picture.h"
#include "imaging/simulation.h"
#include "phantoms/scene/records.h"
#include "phantoms/scene/request.h"
#include "tissue/base/error.h"
#include "tissue/base/number_list.h"

namespace sonotrace::python {

namespace py = pybind11;

// A NumPy array over memory that `owner` keeps alive (no copy).
template <typename T, typename Owner>
inline py::array_t<T> view(std::shared_ptr<Owner> owner, const T* data,
                           std::vector<py::ssize_t> shape) {
    auto* keep = new std::shared_ptr<Owner>(std::move(owner));
    py::capsule free(keep, [](void* p) { delete static_cast<std::shared_ptr<Owner>*>(p); });
    return py::array_t<T>(shape, data, free);
}

// Keyword arguments as a frame request (phantoms/scene/request.h): the keys of its table
// ('_' for '-'; the CLI's --key), True for a flag, a list as comma-separated text; and
// `threads` (0 = all cores), which changes no pixel.
struct Request {
    scene::FrameRequest frame;
    int threads = 0;
};
inline void apply_kwargs(Request& out, const py::kwargs& kwargs, const char* kSource) {
    for (const auto& [key, value] : kwargs) {
        const std::string name = py::str(key).cast<std::string>();
        if (name == "threads") {
            // Read from its text: an int beyond 64 bits cannot be cast (RuntimeError).
            const std::string digits =
                py::isinstance<py::bool_>(value) || !py::isinstance<py::int_>(value)
                    ? std::string()
                    : py::str(value).cast<std::string>();
            if (base::not_a_whole_number(digits) || std::stoull(digits) > 1024)
                throw base::InputError(kSource, name, "must be a whole number from 0 to 1024");
            out.threads = int(std::stoull(digits));
            continue;
        }
        const scene::ParameterKind kind = scene::request_parameter_kind(name);
        std::string text;
        if (py::isinstance<py::bool_>(value)) {
            // A bare True for a parameter with a value is a mistake, not the text "True".
            if (kind == scene::ParameterKind::value)
                throw base::InputError(
                    kSource, name,
                    "takes a value, not " + std::string(value.cast<bool>() ? "True" : "False"));
            text = value.cast<bool>() ? "true" : "false";
        } else if (py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value)) {
            for (const auto& item : value) {
                if (!text.empty()) text += ',';
                text += py::str(item).cast<std::string>();
            }
        } else {
            text = py::str(value).cast<std::string>();
        }
        scene::set_request_parameter(out.frame, name, text, kSource);
    }
}
inline Request parse(const py::kwargs& kwargs, const char* source = "sonotrace.simulate") {
    Request out;
    apply_kwargs(out, kwargs, source);
    return out;
}

// One frame and what describes it, owned by the arrays that view it.
struct FrameData {
    imaging::SimulatedFrame simulated;
    std::optional<cv::Mat> instances;  // with the labels
    cv::Mat bmode;                     // the png8 grey levels
    nlohmann::json sidecar;
};

inline py::object to_python(const nlohmann::json& j) {
    return py::module_::import("json").attr("loads")(j.dump());
}

class Frame {
  public:
    explicit Frame(std::shared_ptr<FrameData> data) : data_(std::move(data)) {}
    py::array_t<uint8_t> bmode() const {
        const cv::Mat& m = data_->bmode;
        return view<uint8_t>(data_, m.ptr<uint8_t>(), {m.rows, m.cols});
    }
    py::array_t<float> image() const {
        const cv::Mat& m = data_->simulated.frame.image.image;
        return view<float>(data_, m.ptr<float>(), {m.rows, m.cols});
    }
    py::object labels() const {
        if (!data_->simulated.labels) return py::none();
        const cv::Mat& m = *data_->simulated.labels;
        return view<uint8_t>(data_, m.ptr<uint8_t>(), {m.rows, m.cols});
    }
    py::object echo_labels() const {
        if (!data_->simulated.echo_labels) return py::none();
        const cv::Mat& m = *data_->simulated.echo_labels;
        return view<uint8_t>(data_, m.ptr<uint8_t>(), {m.rows, m.cols});
    }
    py::object true_depth() const { return float_map(data_->simulated.true_depth); }
    py::object echogenicity() const { return float_map(data_->simulated.echogenicity); }
    py::object instances() const {
        if (!data_->instances) return py::none();
        const cv::Mat& m = *data_->instances;
        return view<uint16_t>(data_, m.ptr<uint16_t>(), {m.rows, m.cols});
    }
    py::array_t<float> envelope() const { return lines(data_->simulated.frame.envelope); }
    py::array_t<float> rf() const { return lines(data_->simulated.frame.rf); }
    py::object channels() const {
        if (!data_->simulated.frame.channels) return py::none();
        const imaging::ChannelData& c = *data_->simulated.frame.channels;
        return view<float>(data_, c.values.data(), {c.transmits, c.elements, c.samples});
    }
    // Each element's x, z (mm) and unit normal (x, z), as the shards' channel_elements.
    py::object channel_elements() const {
        if (!data_->simulated.frame.channels) return py::none();
        const imaging::ChannelData& c = *data_->simulated.frame.channels;
        py::array_t<double> out({py::ssize_t(c.elements), py::ssize_t(4)});
        auto v = out.mutable_unchecked<2>();
        for (int e = 0; e < c.elements; ++e) {
            const probe::ArrayPoint& p = c.element_points[std::size_t(e)];
            v(e, 0) = p.position.x, v(e, 1) = p.position.y;
            v(e, 2) = p.normal.x, v(e, 3) = p.normal.y;
        }
        return out;
    }
    py::object sidecar() const { return to_python(data_->sidecar); }
    const std::shared_ptr<FrameData>& data() const { return data_; }

  private:
    py::object float_map(const std::optional<cv::Mat>& m) const {
        if (!m) return py::none();
        return view<float>(data_, m->ptr<float>(), {m->rows, m->cols});
    }
    py::array_t<float> lines(const imaging::LineData& d) const {
        return view<float>(data_, d.values.data(), {d.lines, d.samples});
    }
    std::shared_ptr<FrameData> data_;
};

// One frame of `setup` at `placement`, on at most `request.threads` cores (0: all), the
// GIL released while it is made: the arrays, the labels' instance map with the labels,
// and the sidecar with the placement's pose.
inline Frame make_frame(const Request& request, const scene::FrameSetup& setup,
                        const imaging::ScenePlacement& placement) {
    auto data = std::make_shared<FrameData>();
    {
        py::gil_scoped_release release;
        std::optional<tbb::global_control> thread_limit;
        if (request.threads > 0)
            thread_limit.emplace(tbb::global_control::max_allowed_parallelism,
                                 std::size_t(request.threads));
        data->simulated = imaging::simulate_plane(setup.scene->mapper, placement, setup.settings,
                                                  request.frame.labels);
        data->bmode = imaging::grey_levels(data->simulated.frame.image.image);
        if (request.frame.labels)
            data->instances = scene::instance_map(*setup.scene, data->simulated);
        data->sidecar = scene::frame_sidecar(request.frame, setup, data->simulated.frame);
        data->sidecar["pose"] = scene::pose_json(placement.pose);
    }
    return Frame(std::move(data));
}

// The classes the other files bind (scenes.cpp).
void bind_scenes(py::module_& m);

}  // namespace sonotrace::python
