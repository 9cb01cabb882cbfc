#pragma once
// `sonotrace simulate`: B-mode frames from a volume and a transducer.
#include <map>
#include <optional>
#include <string>

#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "probe/transducer.h"
#include "ui/cli/command_common.h"
#include "ui/cli/volume_slice.h"

namespace sonotrace::ui {

// Imaging parameters, documented once (the GUI reuses them as tooltips).
inline constexpr ParameterDoc kQualityDoc = {
    "--quality", "",
    "interactive (0.5 mm map, 8 particles per line, whole-texel steps, speckle sub-lines 1.5 "
    "beam sigmas apart), standard (0.25 mm, 32, whole-texel steps, 1 sigma), high (0.125 mm, "
    "128, half-texel steps, 1 sigma)"};
inline constexpr ParameterDoc kReceiveDoc = {
    "--receive", "",
    "echo model: 'monostatic' (each reflection echoes at twice its time, two-way loss) or "
    "'capture' (only particles that reach the probe face; the face reflects part back)"};
inline constexpr ParameterDoc kTraceDoc = {
    "--trace", "",
    "'2d': particles traced in the scan plane (fast); '3d': in the slab the elevation beam "
    "spans, launched over the element height through the lens and received through it, so "
    "the frame integrates over the slice thickness (small cysts fill in, structures off "
    "the plane show, the skull refracts out of the plane); slower and larger"};
inline constexpr ParameterDoc kGainDoc = {"--gain", "dB",
                                          "overall receive gain before log compression"};
inline constexpr ParameterDoc kRangeDoc = {"--dynamic-range", "dB",
                                           "range of echo levels mapped from black to white"};
inline constexpr ParameterDoc kTgcDoc = {
    "--tgc", "mm:dB",
    "time-gain compensation: 'auto' (2 x 0.6 dB/(cm MHz) x f x depth, brain attenuation), "
    "'none', or a curve 'DEPTH:GAIN,DEPTH:GAIN,...' (linear in between)"};

// A transducer's parameters as in the sidecars (JSON keys with units).
nlohmann::json transducer_json(const probe::Transducer& t);

struct SimulateOptions {
    std::string view = "craniotomy";  // craniotomy | temporal | custom (needs --pose)
    SliceOptions volume;
    std::string phantom;  // JSON phantom file instead of a volume
    std::string probe;    // preset; empty = the view's probe
    // Transducer overrides by probe::transducer_parameter_docs() key, as given (unset =
    // the preset's value).
    std::map<std::string, std::optional<std::string>> transducer;
    std::string quality = "standard";
    std::string receive = "monostatic";
    std::string trace = "2d";
    std::string disable;            // physics switched off (imaging::physics_switch_names)
    std::optional<double> gain_db;  // unset: the scene's (scene::Scene::gain_db)
    double dynamic_range_db = 60.0;
    std::string tgc = "auto";
    double pixel_mm = 0.2;
    double step_texels = 0.0;               // 0 = the quality's
    double refraction_smoothing_mm = -1.0;  // -1 = the probe's Fresnel scale
    uint64_t seed = 1;
    std::string formats = "png8";
    bool write_rf = false, write_envelope = false, write_labels = false, write_energy = false;
    std::string sweep;
    bool resume = false;  // keep the frames a stopped sweep already wrote
    std::string video = "mp4";
    double fps = 10.0;
    std::string scene;            // --scene JSON file
    CLI::App* command = nullptr;  // set by add_simulate_command (for --scene)
    std::string out_dir = "out";
    std::string name = "bmode";
    std::string json_path;
    int threads = 0;
    bool quiet = false;
};

CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& options);

// One probe position of a run: where it is and what the scene does there.
struct SweepPlacement {
    imaging::ScenePlacement scene;
    double offset_mm = 0.0;  // along the sweep
};
// --sweep: AXIS:LENGTH:STEP moves the scene's probe from -LENGTH/2 to +LENGTH/2 along
// AXIS (elevation, lateral, axial: the probe's own axes; or X,Y,Z in world mm); or a
// text file with one --pose per line (ui/cli/simulate_sweep.cpp). Empty: `base` alone.
std::vector<SweepPlacement> sweep_placements(const std::string& sweep,
                                             const imaging::ScenePlacement& base);

// What a simulate run is made of, every option validated and the scene loaded: the
// settings, the scene, and the probe's placements (one without --sweep).
struct SimulateSetup {
    imaging::SimulationSettings settings;
    std::shared_ptr<const scene::Scene> scene;
    std::vector<SweepPlacement> placements;
    imaging::PhysicsSwitches physics;
};
// Everything but the output options (--formats, --name, --video, --resume, --fps), which
// only a run that writes files checks.
SimulateSetup prepare_simulate(const SimulateOptions& options, StageTimer& timer);

// The sidecar of a frame (probe, pose, quality, physics, image geometry, statistics,
// timings): what `simulate` writes as NAME.json, without the list of files.
nlohmann::json frame_sidecar(const SimulateOptions& options, const SimulateSetup& setup,
                             const imaging::Frame& frame);
// Applies --scene to the options bound to `options.command`, then runs.
int run_simulate_command(const SimulateOptions& options);

}  // namespace sonotrace::ui
