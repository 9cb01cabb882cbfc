#pragma once
// A frame request: every parameter of a frame (what is scanned, the probe, the imaging,
// the quality, the physics, the label and energy maps) once, in one table of
// {key, unit, range, description, member}; the default is a default request's value.
// `sonotrace simulate` binds its options from the table (--KEY), the Python module sets
// keywords through it (KEY=, '_' for '-'), the GUI quotes its descriptions, and the
// dataset fills a request for each frame; one function makes the settings from a request
// and a scene, one writes its sidecar.
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "phantoms/scene/sweep.h"

namespace sonotrace::scene {

struct FrameRequest : VolumeOptions {
    std::string pose = "default";     // text of probe::parse_pose, or "default"
    std::string phantom;              // a phantom file instead of a volume
    std::string view = "craniotomy";  // of the default head
    std::string probe;                // preset; empty = the scene's
    // Transducer parameters by probe::transducer_parameter_docs() key, as given (unset =
    // the preset's value).
    std::map<std::string, std::optional<std::string>> transducer;
    std::string quality = "standard";
    std::string receive = "monostatic";
    std::string transmit = "focused";  // or probe::parse_transmit_scheme's text
    bool channels = false;             // write the channel data (transmit not focused)
    std::string trace = "2d";
    std::string disable;            // physics switched off (simulator::kPhysicsSwitches)
    std::optional<double> gain_db;  // unset: the scene's (Scene::gain_db)
    double dynamic_range_db = 60.0;
    std::string tgc = "auto";
    std::optional<double> noise_snr_db;  // unset: no receiver noise
    double pixel_mm = 0.2;
    double step_texels = 0.0;               // 0 = the quality's
    double refraction_smoothing_mm = -1.0;  // -1 = the probe's Fresnel scale
    uint64_t seed = 1;
    bool labels = false;  // the tissue label maps of the frame
    bool energy = false;  // the deposition map
    std::string sweep;    // placements (sweep.h); empty = the scene's start

    // What to scan: the volume options, phantom, view and the parsed pose.
    SceneOptions scene_options() const;
};

// One parameter of a request.
struct RequestParameter {
    using Member = std::variant<std::string FrameRequest::*, double FrameRequest::*,
                                std::optional<double> FrameRequest::*, uint64_t FrameRequest::*,
                                bool FrameRequest::*>;
    std::string key;  // --key on the command line, key= in Python ('_' for '-')
    std::string unit;
    std::string description;
    Member member;
    std::optional<imaging::ValueRange> range = std::nullopt;  // checked with the settings

    // "description [unit] (range low..high)": the CLI's help and the GUI's tooltip.
    std::string help() const;
};
// The frame's own parameters, in the order --help lists them; the transducer's follow
// "probe" there (probe::transducer_parameter_docs()).
const std::vector<RequestParameter>& request_parameters();
// The row of `key` (a programming error if there is none).
const RequestParameter& request_parameter(std::string_view key);

// Sets `key` (a request's or a transducer's parameter, '-' or '_') from text, as the CLI
// reads it: numbers must be finite, seeds whole, flags true or false. Throws
// base::InputError(source, key) for an unknown key (listing the known ones) or a value
// that is not of the parameter's kind; ranges and names are checked by make_settings.
void set_request_parameter(FrameRequest& request, std::string_view key, const std::string& text,
                           const std::string& source);
// What `key` ('-' or '_') names: no parameter, a flag (no value), or one with a value.
enum class ParameterKind { unknown, flag, value };
ParameterKind request_parameter_kind(std::string_view key);

// The settings of a frame of `scene` (its probe preset unless the request names one):
// every parameter checked (throws base::InputError naming the option; `source` names the
// request in range errors), the scene's medium applied. What a frame of the request is,
// whoever asks for it.
imaging::SimulationSettings make_settings(const FrameRequest& request, const Scene& scene,
                                          const std::string& source = "simulate options");

// A request made ready: every parameter checked before anything is loaded, then the scene
// loaded, the settings made and the probe's placements found (one without a sweep).
struct FrameSetup {
    imaging::SimulationSettings settings;
    std::shared_ptr<const Scene> scene;
    std::vector<SweepPlacement> placements;
};
FrameSetup prepare_frames(const FrameRequest& request, base::StageObserver* stages = nullptr);

// The sidecar of a frame (probe, pose, quality, physics, image geometry, statistics,
// timings): what `simulate` writes as NAME.json without its list of files, and what
// Python's frame.sidecar holds.
nlohmann::json frame_sidecar(const FrameRequest& request, const FrameSetup& setup,
                             const imaging::Frame& frame);

}  // namespace sonotrace::scene
