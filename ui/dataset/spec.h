#pragma once
// A dataset's specification (`sonotrace dataset SPEC.json`): which scenes, probes,
// parameter ranges, poses and outputs, how many frames, and the seed. imaging::Frame i is a pure
// function of (spec, i): its draws come from a counter-based stream keyed by (seed, i),
// so any frame can be made again alone and the result does not depend on how the work
// was split among threads, shards or ranks.
//
// {
//   "frames": 1000,                  required, 1 .. 100,000,000
//   "frames_per_shard": 64,          frames per HDF5 shard, 1 .. 100,000
//   "seed": 1,                       0 .. 2^53
//   "image": {"width": 256, "height": 256},   pixels of every frame (4 .. 4096)
//   "sources": [                     at least one, drawn by weight (default 1)
//     {"scene": "head-craniotomy", "weight": 2},    or head-temporal
//     {"phantom": "phantoms/cyst_and_stone.json"},
//     {"volume": "scan.nii.gz", "tf": "generic-soft-tissue", "spacing": "0.5,0.5"}
//                                    a volume: anything --volume reads (NIfTI, a DICOM
//                                    series directory, raw, images)
//   ],
//   "probes": ["convex", "linear"],  presets drawn uniformly; default: each source's own
//   "frequency_mhz": [3, 5],         a number, or [low, high] drawn uniformly; default
//   "depth_mm": [60, 90],            the preset's (frequency, depth, focus) or the CLI's
//   "focus_mm": 40,                  default (gain 36 dB, dynamic range 60 dB)
//   "gain_db": [30, 45],
//   "dynamic_range_db": 60,
//   "pose": {"lateral_mm": 10, "elevation_mm": 10, "rotation_deg": 15, "tilt_deg": 5},
//                                    half-ranges about the source's start pose (uniform);
//                                    a moved probe is laid back on the skin or cortex
//   "disable": ["refraction"],       physics switched off (as simulate --disable)
//   "quality": "interactive",        interactive, standard or high (default standard)
//   "trace": "3d",                   2d (default) or 3d: the slab of the elevation beam
//                                    (simulate --trace)
//   "write": ["bmode", "labels"]     also "labels_echo" (the labels where the echoes show
//                                    them, simulate's NAME_labels_echo.png), "envelope",
//                                    "rf", "energy"
// }
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "probe/pose.h"
#include "probe/transducer.h"

namespace sonotrace::dataset {

// A parameter drawn uniformly from [low, high] (low == high: fixed); unset: the default.
struct Range {
    bool set = false;
    double low = 0.0, high = 0.0;
};

struct SourceSpec {
    scene::SceneOptions scene;  // what scene::load_scene takes
    std::string label;          // how the manifest and the frame table name it
    double weight = 1.0;
};

struct Spec {
    std::string path;  // the spec file, for messages
    uint64_t frames = 0;
    uint64_t frames_per_shard = 64;
    uint64_t seed = 1;
    int width = 256, height = 256;
    std::vector<SourceSpec> sources;
    std::vector<std::string> probes;  // empty: each source's own
    Range frequency_mhz, depth_mm, focus_mm, gain_db, dynamic_range_db;
    double lateral_mm = 0.0, elevation_mm = 0.0, rotation_deg = 0.0, tilt_deg = 0.0;
    std::string disable;  // comma list
    imaging::Quality quality = imaging::Quality::standard;
    int trace_dimensions = 2;
    bool write_bmode = true, write_labels = true, write_echo_labels = false, write_envelope = false,
         write_rf = false, write_energy = false;
    // The spec as read, canonical (sorted keys, no whitespace), and a digest of what it
    // names and what makes the frames: each source file's content (a phantom, a volume
    // file, a DICOM directory's files, an image stack's files, a transfer-function file)
    // and the program's version. Together they identify a dataset.
    std::string canonical;
    uint64_t inputs = 0;

    uint64_t shards() const { return (frames + frames_per_shard - 1) / frames_per_shard; }
    // Shard k's frames: [first_frame(k), first_frame(k) + frames_in_shard(k)).
    uint64_t first_frame(uint64_t k) const { return k * frames_per_shard; }
    uint64_t frames_in_shard(uint64_t k) const {
        return std::min(frames, first_frame(k) + frames_per_shard) - first_frame(k);
    }
    // A 64-bit digest of `canonical` and `inputs`: shards of another spec, or of the same
    // spec over files that changed since, are refused, not mixed in.
    uint64_t digest() const;
};

// Reads and validates a spec: unknown keys, wrong types, impossible ranges, unknown
// presets, scenes or outputs, and missing files are InputErrors naming the file and field.
Spec read_spec(const std::string& path);
Spec parse_spec(const nlohmann::json& j, const std::string& source);

// What frame `index` is: its source, probe, parameters, pose offsets and seed.
struct FrameDraw {
    uint64_t index = 0;
    uint64_t seed = 0;  // of the frame's simulation (beams, tracing, speckle)
    int source = 0;     // index into Spec::sources
    std::string probe;  // preset; empty = the source's own
    double frequency_mhz = 0.0, depth_mm = 0.0, focus_mm = 0.0;  // 0 = the preset's
    double gain_db = 36.0, dynamic_range_db = 60.0;
    double lateral_mm = 0.0, elevation_mm = 0.0, rotation_deg = 0.0, tilt_deg = 0.0;
};
FrameDraw draw_frame(const Spec& spec, uint64_t index);

}  // namespace sonotrace::dataset
