#pragma once
// A dataset's specification (`sonotrace dataset SPEC.json`): which scenes, probes,
// parameter ranges, poses and outputs, how many frames, and the seed. Frame i is a pure
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
//   "transducer": {"frequency": [3, 5], "depth": [60, 90], "focus": 40, "f-number": [1.5, 3]},
//                                    any numeric transducer parameter (`simulate --help`
//                                    lists them with units): a number, or [low, high]
//                                    drawn uniformly (whole-number parameters such as
//                                    "elements" uniformly among the whole numbers in it);
//                                    unset: the preset's
//   "gain_db": [30, 45],             a number or [low, high]; default the scene's (36 dB)
//   "dynamic_range_db": 60,          default 60 dB
//   "tgc": {"slope": [0.3, 0.9], "sliders": 8, "slider_db": 3},
//                                    a TGC curve drawn per frame: the attenuation it
//                                    makes up for, 2 x slope x f x depth (dB/(cm MHz),
//                                    0 .. 5, default 0.6: simulate's auto), plus at
//                                    "sliders" (2 .. 32) depths evenly from the face to
//                                    the frame's depth a slider offset drawn uniformly in
//                                    +-slider_db (0 .. 40 dB); linear in between; default:
//                                    simulate's auto curve
//   "noise_snr_db": [10, 40],        receiver noise at this SNR (simulate --noise-snr:
//                                    the frame's mean echo power over the noise's, dB,
//                                    -40 .. 120); default none
//   "tissues": {"brain": {"speed_of_sound": [1520, 1580], "attenuation": {"spread": 0.2}}},
//                                    per tissue (tissue table key), per property (the
//                                    transfer-function keys): a value or [low, high] drawn
//                                    uniformly, or {"spread": s}, a factor drawn uniformly
//                                    in [1 - s, 1 + s] (s 0 .. 0.95); every texel of the
//                                    tissue is scaled by (value / table value) or the
//                                    factor, held to the property's range. Shapes with
//                                    explicit properties have no tissue and keep theirs
//   "pose": {"lateral_mm": 10, "elevation_mm": 10, "rotation_deg": 15, "tilt_deg": 5},
//                                    half-ranges about the source's start pose (uniform);
//                                    a moved probe is laid back on the skin or cortex
//   "disable": ["refraction"],       physics switched off (as simulate --disable)
//   "quality": "interactive",        interactive, standard or high (default standard)
//   "trace": "3d",                   2d (default) or 3d: the slab of the elevation beam
//                                    (simulate --trace)
//   "transmit": "plane:-16:16:75",   unfocused transmits (simulate --transmit, flat
//                                    arrays); default focused
//   "write": ["bmode", "labels"]     also "labels_echo" (the labels where the echoes show
//                                    them, simulate's NAME_labels_echo.png), "depth" (the
//                                    true depth of what each pixel shows, mm),
//                                    "echogenicity" (its backscatter with nothing in the
//                                    way), "instances" (a phantom's shape index per pixel),
//                                    "envelope", "rf", "energy", "channels" (each
//                                    element's RF under each transmit: needs "transmit")
// }
#include <algorithm>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "probe/pose.h"
#include "probe/transducer.h"
#include "tissue/property_maps.h"

namespace sonotrace::dataset {

// A parameter drawn uniformly from [low, high] (low == high: fixed); unset: the default.
struct Range {
    bool set = false;
    double low = 0.0, high = 0.0;
};

// A numeric transducer parameter drawn per frame (probe::transducer_parameter_docs key).
struct TransducerRange {
    std::string key;
    Range range;
    bool whole = false;  // an integer parameter: drawn among the whole numbers in range
};

// A tissue property drawn per frame: an absolute value, or a factor about its own.
struct TissueRange {
    std::string tissue;  // tissue_table() key
    int label = 0;       // its label (tissue::tissue_label_of)
    tissue::Property property = tissue::Property::speed_of_sound;
    Range values;         // set: the value drawn from it, the factor value / table_value
    double spread = 0.0;  // otherwise: a factor drawn from [1 - spread, 1 + spread]
    double table_value = 0.0;
};

// A TGC curve drawn per frame (the key list above).
struct TgcRange {
    bool set = false;
    Range slope;  // dB/(cm MHz); unset: 0.6
    int sliders = 0;
    double slider_db = 0.0;
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
    std::vector<TransducerRange> transducer;
    Range gain_db, dynamic_range_db;
    TgcRange tgc;
    Range noise_snr_db;
    std::vector<TissueRange> tissues;
    double lateral_mm = 0.0, elevation_mm = 0.0, rotation_deg = 0.0, tilt_deg = 0.0;
    std::string disable;  // comma list
    imaging::Quality quality = imaging::Quality::standard;
    int trace_dimensions = 2;
    std::string transmit = "focused";  // simulate --transmit
    bool write_channels = false;
    bool write_depth = false, write_echogenicity = false, write_instances = false;
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
    uint64_t seed = 0;               // of the frame's simulation (beams, tracing, speckle)
    int source = 0;                  // index into Spec::sources
    std::string probe;               // preset; empty = the source's own
    std::vector<double> transducer;  // a value per Spec::transducer
    std::optional<double> gain_db;   // unset: the scene's
    double dynamic_range_db = 60.0;
    double lateral_mm = 0.0, elevation_mm = 0.0, rotation_deg = 0.0, tilt_deg = 0.0;
    std::vector<tissue::LabelScale> tissue_scales;  // a factor per Spec::tissues
    std::vector<double> tissue_values;              // the tissue's table value x factor
    std::optional<double> tgc_slope;                // with Spec::tgc
    std::vector<double> tgc_sliders_db;             // a slider offset per Spec::tgc.sliders
    std::optional<double> noise_snr_db;
};
FrameDraw draw_frame(const Spec& spec, uint64_t index);

// The values a frame drew from the spec's transducer, tgc, noise and tissue entries,
// named as the frame table's columns ("transducer.focus", "tgc.slope", "tgc.slider3",
// "noise_snr_db", "tissues.brain.attenuation"), in a fixed order: the same names for
// every frame of a spec.
struct DrawnValue {
    std::string name;
    double value = 0.0;
};
std::vector<DrawnValue> drawn_values(const Spec& spec, const FrameDraw& draw);

// The TGC curve of a frame drawn with a TgcRange, for the transducer it is made with:
// simulate's --tgc text (DEPTH:GAIN,..., numbers to the bit); "auto" without one.
std::string tgc_curve(const FrameDraw& draw, const probe::Transducer& t);

}  // namespace sonotrace::dataset
