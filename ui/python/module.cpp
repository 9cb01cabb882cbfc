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
#include "ui/python/bindings.h"

namespace py = pybind11;
using namespace sonotrace;
using namespace sonotrace::python;

namespace {

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
        const scene::SweepPlacement& placement = setup_.placements.at(index);
        Frame frame = make_frame(request_, setup_, placement.scene);
        if (setup_.placements.size() > 1)
            frame.data()->sidecar["sweep_offset_mm"] = placement.offset_mm;
        return frame;
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

PYBIND11_MODULE(_sonotrace, m) {
    m.doc() =
        "sonotrace: ultrasound frames by particle tracing through tissue maps. Keyword "
        "arguments are the frame's parameters, the options of `sonotrace simulate` that are "
        "not about its files (see `sonotrace simulate --help` for units and defaults), with "
        "'_' for '-', and threads; errors are sonotrace.InputError naming the option or file "
        "and field.";
    m.attr("__version__") = SONOTRACE_VERSION;
    // As our programs do at their start (tissue/base/memory.h): a frame's transient buffers
    // are kept by the allocator for the next frame, not mapped and zeroed afresh (half a
    // frame's time in the kernel otherwise: bench/scene_frames.py).
    base::keep_freed_memory();
    static py::exception<base::InputError> input_error(m, "InputError", PyExc_ValueError);
    input_error.attr("__module__") = "sonotrace";  // as users name it: sonotrace.InputError
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
        .def_property_readonly("channels", &Frame::channels,
                               "float32 [transmits, elements, samples]: each element's RF "
                               "under each unfocused transmit (transmit='plane:...' or "
                               "'diverging:...'; sampling and geometry in sidecar['transmit'] "
                               "and docs/guide/channel-data.md), else None")
        .def_property_readonly("channel_elements", &Frame::channel_elements,
                               "float64 [elements, 4]: each element's x, z (mm, z below 0 along "
                               "a convex arc) and unit normal x, z, with channels; else None")
        .def_property_readonly("sidecar", &Frame::sidecar,
                               "dict: the frame's JSON sidecar (probe, pose, image geometry, ...)");

    bind_scenes(m);

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
                for (const char* name : {"bmode", "labels", "labels_echo", "depth", "echogenicity",
                                         "instances", "frames"})
                    if (file.attr("__contains__")(name).cast<bool>())
                        out[name] = read_all(file[name]);
                for (const char* name :
                     {"envelope", "rf", "energy", "channels", "channel_elements"}) {
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
        "bmode, labels, frames (a record array), labels_echo / depth / echogenicity / "
        "instances and envelope / rf / energy / channels / channel_elements ({frame index: "
        "array}; channel_elements: each element's x, z, normal x, normal z) when written, "
        "and the shard's attributes (spec, spec_digest, ...). The channels' sampling and "
        "pitch are attributes of their datasets (h5py).");

    py::class_<Sweep>(m, "Sweep", "Frames of a sweep, simulated as they are asked for.")
        .def("__iter__", [](Sweep& s) -> Sweep& { return s; })
        .def("__next__", &Sweep::next)
        .def("__len__", &Sweep::size);
    m.def(
        "sweep", [](py::kwargs kwargs) { return Sweep(kwargs); },
        "sweep(sweep='lateral:10:1', **options) -> iterator of Frame: the frames of "
        "`sonotrace simulate --sweep`, one at a time.");
}
