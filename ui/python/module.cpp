// The `sonotrace` Python module: frames and sweeps as NumPy arrays, with the options of
// `sonotrace simulate` as keyword arguments (each documented once, in the CLI; the same
// checks and the same messages), and dataset shards read back.
//
//   import sonotrace
//   frame = sonotrace.simulate(phantom="phantoms/cyst_and_stone.json", seed=3, labels=True)
//   frame.bmode, frame.labels, frame.envelope, frame.rf, frame.sidecar
//   for frame in sonotrace.sweep(sweep="lateral:4:1", quality="interactive"): ...
//
// The GIL is released while C++ works, so Python threads can run simulations at once.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <filesystem>
#include <memory>
#include <sstream>

#include <tbb/global_control.h>

#include "imaging/picture.h"
#include "phantoms/scene/records.h"
#include "phantoms/scene/request.h"
#include "sonotrace_version.h"
#include "tissue/base/error.h"
#include "tissue/base/file_read.h"
#include "tissue/base/memory.h"
#include "ui/dataset/shard.h"

namespace py = pybind11;
using namespace sonotrace;

namespace {

// A NumPy array over memory that `owner` keeps alive (no copy).
template <typename T, typename Owner>
py::array_t<T> view(std::shared_ptr<Owner> owner, const T* data, std::vector<py::ssize_t> shape) {
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
Request parse(const py::kwargs& kwargs) {
    constexpr const char* kSource = "sonotrace.simulate";
    Request out;
    for (const auto& [key, value] : kwargs) {
        const std::string name = py::str(key).cast<std::string>();
        if (name == "threads") {
            if (py::isinstance<py::bool_>(value) || !py::isinstance<py::int_>(value) ||
                value.cast<long long>() < 0 || value.cast<long long>() > 1024)
                throw base::InputError(kSource, name, "must be a whole number from 0 to 1024");
            out.threads = value.cast<int>();
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
    return out;
}

// One frame and what describes it, owned by the arrays that view it.
struct FrameData {
    imaging::SimulatedFrame simulated;
    std::optional<cv::Mat> instances;  // with the labels
    cv::Mat bmode;                     // the png8 grey levels
    nlohmann::json sidecar;
};

py::object to_python(const nlohmann::json& j) {
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
    py::object sidecar() const { return to_python(data_->sidecar); }

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

// A prepared run (every option checked, the scene loaded) and its placements, one frame
// at a time.
class Run {
  public:
    explicit Run(const py::kwargs& kwargs) : request_(parse(kwargs)) {
        py::gil_scoped_release release;
        setup_ = scene::prepare_frames(request_.frame);
    }
    std::size_t size() const { return setup_.placements.size(); }
    Frame frame(std::size_t index) const {
        auto data = std::make_shared<FrameData>();
        {
            py::gil_scoped_release release;
            std::optional<tbb::global_control> thread_limit;
            if (request_.threads > 0)
                thread_limit.emplace(tbb::global_control::max_allowed_parallelism,
                                     std::size_t(request_.threads));
            const scene::SweepPlacement& placement = setup_.placements.at(index);
            data->simulated = imaging::simulate_plane(setup_.scene->mapper, placement.scene,
                                                      setup_.settings, request_.frame.labels);
            data->bmode = imaging::grey_levels(data->simulated.frame.image.image);
            if (request_.frame.labels)
                data->instances = scene::instance_map(*setup_.scene, data->simulated);
            data->sidecar = scene::frame_sidecar(request_.frame, setup_, data->simulated.frame);
            data->sidecar["pose"] = scene::pose_json(placement.scene.pose);
            if (setup_.placements.size() > 1)
                data->sidecar["sweep_offset_mm"] = placement.offset_mm;
        }
        return Frame(std::move(data));
    }

  private:
    Request request_;
    scene::FrameSetup setup_;
};

class Sweep {
  public:
    explicit Sweep(const py::kwargs& kwargs) : run_(std::make_shared<Run>(kwargs)) {}
    Frame next() {
        if (next_ >= run_->size()) throw py::stop_iteration();
        return run_->frame(next_++);
    }
    std::size_t size() const { return run_->size(); }

  private:
    std::shared_ptr<Run> run_;
    std::size_t next_ = 0;
};

}  // namespace

PYBIND11_MODULE(sonotrace, m) {
    m.doc() =
        "sonotrace: ultrasound frames by particle tracing through tissue maps. Keyword "
        "arguments are the frame's parameters, the options of `sonotrace simulate` that are "
        "not about its files (see `sonotrace simulate --help` for units and defaults), with "
        "'_' for '-', and threads; errors are sonotrace.InputError naming the option or file "
        "and field.";
    m.attr("__version__") = SONOTRACE_VERSION;
    static py::exception<base::InputError> input_error(m, "InputError", PyExc_ValueError);
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const base::InputError& e) {
            PyErr_SetString(input_error.ptr(), e.what());
        } catch (const std::filesystem::filesystem_error& e) {
            // A path the system refuses (too long, a loop): bad input, as the CLI says.
            PyErr_SetString(input_error.ptr(), e.what());
        }
    });

    py::class_<Frame>(m, "Frame", "A simulated frame; its arrays share the frame's memory.")
        .def_property_readonly("bmode", &Frame::bmode,
                               "uint8 [rows, cols]: the grey levels `simulate` writes as png8")
        .def_property_readonly("image", &Frame::image,
                               "float32 [rows, cols]: the scan-converted display, 0..1")
        .def_property_readonly(
            "labels", &Frame::labels,
            "uint8 [rows, cols]: tissue index per pixel (labels=True), else None")
        .def_property_readonly(
            "echo_labels", &Frame::echo_labels,
            "uint8 [rows, cols]: the labels where the echoes show them (labels=True), else None")
        .def_property_readonly("true_depth", &Frame::true_depth,
                               "float32 [rows, cols]: the true depth (mm, along each pixel's "
                               "line from the face) of what each pixel shows (labels=True), "
                               "else None")
        .def_property_readonly("echogenicity", &Frame::echogenicity,
                               "float32 [rows, cols]: the backscatter (0..1) of what each pixel "
                               "shows, with no attenuation or shadowing on the way "
                               "(labels=True), else None")
        .def_property_readonly("instances", &Frame::instances,
                               "uint16 [rows, cols]: the phantom shape each pixel lies in (its "
                               "place in the phantom's shapes from 1, 0 background; all 0 for "
                               "a volume) (labels=True), else None")
        .def_property_readonly("envelope", &Frame::envelope, "float32 [lines, samples]")
        .def_property_readonly("rf", &Frame::rf, "float32 [lines, samples]")
        .def_property_readonly("sidecar", &Frame::sidecar,
                               "dict: the frame's JSON sidecar (probe, pose, image geometry, ...)");

    m.def(
        "simulate", [](py::kwargs kwargs) { return Run(kwargs).frame(0); },
        "simulate(**options) -> Frame: one frame; options as `sonotrace simulate` (e.g. "
        "phantom='phantoms/cyst_and_stone.json', probe='linear', seed=3, labels=True). With "
        "sweep=..., the first frame of the sweep.");

    m.def(
        "read_shard",
        [](const std::string& path) {
            // Our reader takes the bytes (a regular file only, never blocking on a FIFO, its
            // size checked); h5py reads the HDF5 (a shard is plain HDF5, shard.h) from memory.
            const std::string bytes = base::read_regular_file(path, dataset::kMaxShardBytes);
            // Only a shard whose header and content checksum agree reaches h5py.
            const dataset::ShardCheck check =
                dataset::check_shard_bytes(bytes, std::nullopt, std::nullopt);
            if (check.verdict != dataset::ShardCheck::ok)
                throw base::InputError(path, "", "not a sound shard: " + check.why);
            // HDF5 reads all of it in a child process first: a malformed shard (its checksum
            // resealed) made h5py's read crash the interpreter.
            if (const std::optional<std::string> why = dataset::unreadable_shard(bytes))
                throw base::InputError(path, "", "not a readable shard: " + *why);
            try {
                py::object image = py::module_::import("io").attr("BytesIO")(py::bytes(bytes));
                py::object file = py::module_::import("h5py").attr("File")(image, "r");
                py::dict out, attributes;
                // Sizes and layouts were checked, and every part read, by the child.
                auto read_all = [](const py::object& dataset) { return dataset[py::tuple()]; };
                for (const char* name : {"bmode", "labels", "labels_echo", "frames"})
                    if (file.attr("__contains__")(name).cast<bool>())
                        out[name] = read_all(file[name]);
                for (const char* name : {"envelope", "rf", "energy"}) {
                    if (!file.attr("__contains__")(name).cast<bool>()) continue;
                    py::dict per_frame;
                    const py::object group = file[name];
                    for (const auto& key : group.attr("keys")())
                        per_frame[py::int_(py::reinterpret_borrow<py::object>(key))] =
                            read_all(group[key]);
                    out[name] = per_frame;
                }
                const py::object attrs = file.attr("attrs");
                for (const auto& item : attrs.attr("items")()) {
                    const py::tuple pair = item.cast<py::tuple>();
                    attributes[pair[0]] = pair[1];
                }
                out["attributes"] = attributes;
                file.attr("close")();
                return out;
            } catch (const py::error_already_set& e) {
                // Whatever a damaged file makes h5py or NumPy raise, the user sees one kind of
                // error naming the file.
                throw base::InputError(path, "", std::string("not a readable shard: ") + e.what());
            } catch (const py::cast_error& e) {
                throw base::InputError(path, "", std::string("not a readable shard: ") + e.what());
            }
        },
        "read_shard(path) -> dict: a dataset shard (`sonotrace dataset`) as NumPy arrays: "
        "bmode, labels, frames (a record array), envelope / rf / energy ({frame index: "
        "array}) when written, and the shard's attributes (spec, spec_digest, ...).");

    py::class_<Sweep>(m, "Sweep", "Frames of a sweep, simulated as they are asked for.")
        .def("__iter__", [](Sweep& s) -> Sweep& { return s; })
        .def("__next__", &Sweep::next)
        .def("__len__", &Sweep::size);
    m.def(
        "sweep", [](py::kwargs kwargs) { return Sweep(kwargs); },
        "sweep(sweep='lateral:10:1', **options) -> iterator of Frame: the frames of "
        "`sonotrace simulate --sweep`, one at a time.");
}
