// sonotrace.Scene: a scene loaded once, frames made from it at any pose and settings; and
// sonotrace.DatasetFrames: frame i of a dataset spec, as `sonotrace dataset` makes it
// (what sonotrace.torch.FrameDataset yields).
#include <pybind11/stl.h>

#include <algorithm>
#include <array>
#include <string_view>

#include "probe/pose.h"
#include "ui/dataset/frames.h"
#include "ui/python/bindings.h"

namespace sonotrace::python {

namespace {

constexpr const char* kSceneSource = "sonotrace.Scene";
constexpr const char* kFrameSource = "sonotrace.Scene.frame";

// What loads a scene: given to Scene(...), refused by frame(...).
constexpr std::array<std::string_view, 6> kSceneKeys = {"volume",  "spacing", "tf",
                                                        "outside", "phantom", "view"};

class Scene {
  public:
    static constexpr uint64_t kWarmUpFrames = 3;

    explicit Scene(const py::kwargs& kwargs) : base_(parse(kwargs, kSceneSource)) {
        if (!base_.frame.sweep.empty())
            throw base::InputError(kSceneSource, "sweep",
                                   "a Scene makes one frame per call: sonotrace.sweep(...) "
                                   "makes a sweep's");
        {
            py::gil_scoped_release release;
            setup_ = scene::prepare_frames(base_.frame);
        }
        // A few frames at the start, thrown away: the probe's aperture tables (kept for
        // every frame of the same probe set-up) and the plane echoes they fill as
        // reflections ask for them, the thread pool and the allocator's memory are ready,
        // so the first frame asked for costs what the next ones do (bench/scene_frames.py:
        // 5x without, 1.24x after one frame, 1.10x after three). The tables are the probe's,
        // not the quality's: interactive frames fill them at the least cost. Frames do not
        // depend on what the tables hold (test_module.py: a Scene's frame is simulate's).
        Request warm = base_;
        warm.frame.quality = "interactive";
        scene::FrameSetup setup = setup_;
        for (uint64_t k = 1; k <= kWarmUpFrames; ++k) {
            warm.frame.seed = base_.frame.seed + k;
            setup.settings = scene::make_settings(warm.frame, *setup_.scene, kSceneSource);
            make_frame(warm, setup, setup_.placements.front().scene);
        }
    }

    Frame frame(const py::kwargs& kwargs) const {
        for (const auto& [key, value] : kwargs) {
            std::string name = py::str(key).cast<std::string>();
            std::replace(name.begin(), name.end(), '_', '-');
            for (std::string_view k : kSceneKeys)
                if (name == k)
                    throw base::InputError(kFrameSource, name,
                                           "belongs to the scene: give it to sonotrace.Scene(...), "
                                           "which loads it once");
            if (name == "sweep")
                throw base::InputError(kFrameSource, name,
                                       "sonotrace.sweep(...) makes a sweep's frames");
        }
        Request request = base_;
        apply_kwargs(request, kwargs, kFrameSource);
        scene::FrameSetup setup;
        setup.scene = setup_.scene;
        imaging::ScenePlacement placement = setup_.scene->start;
        {
            py::gil_scoped_release release;
            setup.settings = scene::make_settings(request.frame, *setup.scene, kFrameSource);
            if (request.frame.pose != "default") {
                placement.pose = probe::parse_pose(request.frame.pose, "pose");
                setup.scene->require_inside(placement.pose, std::string(kFrameSource) + " (pose)");
            }
        }
        setup.placements = {{placement, 0.0}};
        return make_frame(request, setup, placement);
    }

    std::string name() const { return setup_.scene->name; }
    std::string probe() const { return setup_.scene->probe_preset; }
    py::object start_pose() const { return to_python(scene::pose_json(setup_.scene->start.pose)); }

  private:
    Request base_;
    scene::FrameSetup setup_;
};

// The frames of a dataset spec, each made alone as `sonotrace dataset` makes it.
class DatasetFrames {
  public:
    DatasetFrames(const std::string& spec, int threads) : threads_(threads) {
        if (threads < 0 || threads > 1024)
            throw base::InputError("sonotrace.DatasetFrames", "threads",
                                   "must be a whole number from 0 to 1024");
        py::gil_scoped_release release;
        maker_ = std::make_unique<dataset::FrameMaker>(dataset::read_spec(spec));
    }
    std::size_t size() const { return std::size_t(maker_->spec().frames); }

    py::dict frame(uint64_t index) const {
        const dataset::Spec& spec = maker_->spec();
        if (index >= spec.frames)
            throw py::index_error("frame " + std::to_string(index) + " of a dataset of " +
                                  std::to_string(spec.frames));
        auto made = std::make_shared<dataset::DatasetFrame>();
        {
            py::gil_scoped_release release;
            std::optional<tbb::global_control> thread_limit;
            if (threads_ > 0)
                thread_limit.emplace(tbb::global_control::max_allowed_parallelism,
                                     std::size_t(threads_));
            *made = maker_->make(index);
        }
        py::dict out;
        out["index"] = made->draw.index;
        out["seed"] = made->draw.seed;
        out["source"] = made->draw.source;
        out["probe"] = made->transducer.name;
        py::dict drawn;
        for (const dataset::DrawnValue& v : dataset::drawn_values(spec, made->draw))
            drawn[py::str(v.name)] = v.value;
        out["drawn"] = drawn;
        auto image = [&](const char* name, const cv::Mat& m) {
            if (m.depth() == CV_8U)
                out[name] = view<uint8_t>(made, m.ptr<uint8_t>(), {m.rows, m.cols});
            else if (m.depth() == CV_16U)
                out[name] = view<uint16_t>(made, m.ptr<uint16_t>(), {m.rows, m.cols});
            else
                out[name] = view<float>(made, m.ptr<float>(), {m.rows, m.cols});
        };
        // The shard's names for what the spec writes (ui/dataset/shard.h).
        if (spec.write_bmode) image("bmode", made->bmode);
        if (spec.write_labels) image("labels", made->labels);
        if (spec.write_echo_labels) image("labels_echo", made->echo_labels);
        if (spec.write_depth) image("depth", made->true_depth);
        if (spec.write_echogenicity) image("echogenicity", made->echogenicity);
        if (spec.write_instances) image("instances", made->instances);
        auto lines = [&](const char* name, const imaging::LineData& d) {
            out[name] = view<float>(made, d.values.data(), {d.lines, d.samples});
        };
        if (spec.write_envelope) lines("envelope", made->envelope);
        if (spec.write_rf) lines("rf", made->rf);
        return out;
    }

  private:
    int threads_ = 0;
    std::unique_ptr<dataset::FrameMaker> maker_;
};

}  // namespace

void bind_scenes(py::module_& m) {
    py::class_<Scene>(m, "Scene",
                      "Scene(**options): a scene loaded once (volume, spacing, tf, outside, "
                      "phantom, view: what `simulate` scans) with default frame options (any "
                      "other of `simulate`'s, e.g. probe, quality, depth); frame(**options) "
                      "makes a frame of it, the scene's options fixed, the others as given "
                      "(pose='at=X,Y,Z beam=DX,DY,DZ ...' places the probe). The scene's maps "
                      "and the probe's aperture tables are kept between frames.")
        .def(py::init<const py::kwargs&>())
        .def("frame", &Scene::frame,
             "frame(**options) -> Frame: a frame of the scene with these options (the "
             "Scene's defaults for the rest)")
        .def_property_readonly("name", &Scene::name)
        .def_property_readonly("probe", &Scene::probe, "the scene's probe preset")
        .def_property_readonly("start_pose", &Scene::start_pose,
                               "dict: where the probe starts (the default pose)");
    py::class_<DatasetFrames>(m, "DatasetFrames",
                              "DatasetFrames(spec, threads=0): the frames of a dataset spec "
                              "(`sonotrace dataset`), each made alone: frame(i) is the dict of "
                              "frame i's arrays (the shard's names: bmode, labels, ...), its "
                              "index, seed, source, probe and drawn values, equal to the "
                              "shard's")
        .def(py::init<const std::string&, int>(), py::arg("spec"), py::arg("threads") = 0)
        .def("__len__", &DatasetFrames::size)
        .def("frame", &DatasetFrames::frame, py::arg("index"));
}

}  // namespace sonotrace::python
