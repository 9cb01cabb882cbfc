#include "phantoms/scene/request.h"

#include "imaging/channel_frame.h"

#include <algorithm>
#include <sstream>
#include <type_traits>

#include "phantoms/scene/records.h"
#include "probe/pose.h"
#include "probe/transducer.h"
#include "sonotrace_version.h"
#include "tissue/base/error.h"
#include "tissue/base/number_list.h"

namespace sonotrace::scene {

namespace {

using nlohmann::json;

std::string probe_description() {
    std::string t = "transducer preset: ";
    for (const probe::Transducer& p : probe::transducer_presets()) {
        t += (&p == &probe::transducer_presets().front() ? "" : ", ") + p.name + " (" +
             base::number_text(p.frequency_mhz) + " MHz, " + std::to_string(p.elements) +
             " elements)";
    }
    return t + "; empty = the view's probe (the phantom's, or linear)";
}

std::string quality_description() {
    std::string t;
    for (const imaging::QualityName& q : imaging::quality_names()) {
        const imaging::QualityLevel level = imaging::quality_level(q.quality);
        t += (t.empty() ? "" : ", ") + std::string(q.name) + " (" +
             base::number_text(level.map_pixel_mm) + " mm map, " +
             std::to_string(level.particles_per_line) + " particles per line, " +
             (level.step_texels < 1.0 ? "half-texel" : "whole-texel") +
             " steps, speckle sub-lines " + base::number_text(level.sub_line_sigmas) +
             (level.sub_line_sigmas == 1.0 ? " beam sigma" : " beam sigmas") + " apart)";
    }
    return t;
}

std::vector<RequestParameter> make_table() {
    using R = FrameRequest;
    return {
        {"view", "",
         "scene of the default head: 'craniotomy' (convex probe on the right parietal cortex "
         "through a virtual craniotomy, coronal plane through the lateral ventricles) or "
         "'temporal' (phased probe on the right temple, imaging through the skull). Other "
         "volumes, or --pose, place the probe without a craniotomy",
         &R::view},
        {"volume", "",
         "volume to load: 'default' (Colin27 T1 head MRI from mricron-data), a NIfTI file "
         "(.nii/.nii.gz), a raw sidecar (.json), a DICOM file or a directory holding one DICOM "
         "series (slices ordered by position; values rescaled, e.g. to Hounsfield units), an "
         "image (PNG/TIFF/JPEG/EXR), a directory of numbered images or a printf pattern "
         "(img_%03d.png)",
         &R::volume},
        {"spacing", "mm",
         "pixel spacing of image inputs as 'SX,SY' or 'SX,SY,SZ' (SZ = slice spacing of a "
         "stack); required for images, ignored for NIfTI, DICOM and raw volumes",
         &R::spacing},
        {"tf", "",
         "transfer function: a preset name (mri-t1-head, ct-hounsfield, generic-soft-tissue) "
         "or a JSON file; empty = mri-t1-head for the default volume, ct-hounsfield for a CT "
         "DICOM series, generic-soft-tissue otherwise",
         &R::tf},
        {"pose", "mm, degrees", probe::kPoseHelp, &R::pose},
        {"outside", "volume units",
         "value assumed outside the volume; default: the volume's minimum (air for MRI)",
         &R::outside},
        {"phantom", "",
         "JSON phantom (phantoms/*.json: background tissue and analytic shapes, mm) to image "
         "instead of a volume; its 'probe' entry places the probe (default: top centre, "
         "looking down +y), the probe preset defaults to the phantom's or 'linear'",
         &R::phantom},
        {"probe", "", probe_description(), &R::probe},
        {"quality", "", quality_description(), &R::quality},
        {"receive", "",
         "echo model: 'monostatic' (each reflection echoes at twice its time, two-way loss) or "
         "'capture' (only particles that reach the probe face; the face reflects part back)",
         &R::receive},
        {"transmit", "",
         "'focused' (line by line, the default) or unfocused transmits with per-element "
         "channel data, beamformed by delay-and-sum and compounded (linear, phased and "
         "convex arrays): 'plane:A' (a plane wave steered A degrees), 'plane:A,B,...', "
         "'plane:FROM:TO:N' (N angles), 'diverging:D' (a virtual source D mm behind the face), "
         "'diverging:D:ANGLES' (its axis steered, angles as for plane); on a convex array "
         "diverging:RADIUS puts the source at the arc's centre of curvature",
         &R::transmit},
        {"channels", "",
         "write the channel data of an unfocused --transmit (transmit x element x sample, "
         "float32) as HDF5 (docs/guide/channel-data.md)",
         &R::channels},
        {"trace", "",
         "'2d': particles traced in the scan plane (fast); '3d': in the slab the elevation "
         "beam spans, launched over the element height through the lens and received through "
         "it, so the frame integrates over the slice thickness (small cysts fill in, "
         "structures off the plane show, the skull refracts out of the plane); slower and "
         "larger",
         &R::trace},
        {"disable", "",
         "comma list of physics to switch off, to take an artifact apart (as the GUI's "
         "toggles): " +
             imaging::physics_switch_help(),
         &R::disable},
        {"gain", "dB",
         "overall receive gain before log compression (default: the scene's: " +
             std::to_string(int(kDefaultGainDb)) + ", the temporal view " +
             std::to_string(int(kTemporalGainDb)) + ", where the skull costs about 27 dB two-way)",
         &R::gain_db, imaging::kGainRange},
        {"dynamic-range", "dB", "range of echo levels mapped from black to white",
         &R::dynamic_range_db, imaging::kDynamicRangeRange},
        {"tgc", "mm:dB",
         "time-gain compensation: 'auto' (2 x 0.6 dB/(cm MHz) x f x depth, brain attenuation), "
         "'none', or a curve 'DEPTH:GAIN,DEPTH:GAIN,...' (linear in between)",
         &R::tgc},
        {"noise-snr", "dB",
         "receiver (electronic) noise: white Gaussian noise in the pulse's band added to the "
         "RF lines, at this ratio of the frame's mean echo power to the noise power "
         "(imaging/electronic_noise.h); TGC lifts it at depth as on a scanner; unset: none",
         &R::noise_snr_db, imaging::kNoiseSnrRange},
        {"pixel", "mm", "pixel size of the scan-converted image", &R::pixel_mm,
         imaging::kPixelRange},
        {"step", "texels",
         "integration step s, in texels of the map; 0 = the quality's (interactive and "
         "standard 1, high 0.5)",
         &R::step_texels, imaging::kStepTexelsRange},
        {"refraction-smoothing", "mm",
         "Gaussian sigma of the soft-tissue speed of sound the rays bend in: a beam's "
         "wavefront spans its Fresnel zone, so structures thinner than that (sulci, "
         "partial-volume fringes) aberrate it instead of deflecting it; bone and air stay "
         "sharp. -1 = the probe's Fresnel scale sqrt(wavelength x depth) / 2 (convex 3.0, "
         "linear 1.4, phased 4.1 mm), 0 = none",
         &R::refraction_smoothing_mm, imaging::kRefractionSmoothingRange},
        {"seed", "", "random seed of the beams, tracing and scatterer field", &R::seed},
        {"labels", "",
         "also the ground-truth tissue labels in the frame's pixels (values = tissue index "
         "listed in the sidecar), and the same where the echoes show the anatomy (behind fast "
         "bone it shows closer than it lies)",
         &R::labels},
        {"energy", "", "also the energy deposition map", &R::energy},
        {"sweep", "mm",
         "move the probe and make a numbered frame sequence: 'AXIS:LENGTH:STEP' from "
         "-LENGTH/2 to +LENGTH/2 about the pose, AXIS = elevation, lateral, axial (the "
         "probe's axes) or X,Y,Z (world); or a text file with one --pose per line",
         &R::sweep},
    };
}

std::string normalised(std::string_view key) {
    std::string k(key);
    std::replace(k.begin(), k.end(), '_', '-');
    return k;
}

const probe::TransducerParameterDoc* transducer_row(std::string_view key) {
    for (const auto& doc : probe::transducer_parameter_docs())
        if (key == doc.key) return &doc;
    return nullptr;
}

[[noreturn]] void unknown_key(std::string_view key, const std::string& source) {
    std::string known;
    for (const RequestParameter& p : request_parameters()) {
        known += (known.empty() ? "" : ", ") + p.key;
        if (p.key == "probe")
            for (const auto& doc : probe::transducer_parameter_docs())
                known += std::string(", ") + doc.key;
    }
    throw base::InputError(source, std::string(key), "unknown parameter; known: " + known);
}

std::vector<imaging::TgcPoint> parse_tgc(const std::string& text, const probe::Transducer& t) {
    if (text == "none") return {};
    if (text == "auto") {
        return {{0.0, 0.0}, {t.depth_mm, imaging::automatic_tgc_db(t.frequency_mhz, t.depth_mm)}};
    }
    std::vector<imaging::TgcPoint> curve;
    std::istringstream list(text);
    for (std::string item; std::getline(list, item, ',');) {
        const auto colon = item.find(':');
        const std::optional<double> depth =
            colon == std::string::npos ? std::nullopt : base::finite_number(item.substr(0, colon));
        const std::optional<double> gain =
            colon == std::string::npos ? std::nullopt : base::finite_number(item.substr(colon + 1));
        if (!depth || !gain)
            throw base::InputError("--tgc", item, "expected DEPTH:GAIN (mm:dB), 'auto' or 'none'");
        curve.push_back({*depth, *gain});
    }
    return curve;
}

template <typename E>
E parse_choice(const std::string& text, const char* flag,
               const std::vector<std::pair<std::string, E>>& choices) {
    std::string names;
    for (const auto& [name, value] : choices) {
        if (name == text) return value;
        names += (names.empty() ? "" : ", ") + name;
    }
    throw base::InputError(flag, "", "must be one of " + names + ", got '" + text + "'");
}

// The settings a request makes before the scene is known (every name and range checked),
// with `preset` as the probe unless the request names one.
imaging::SimulationSettings settings_of(const FrameRequest& r, const std::string& preset,
                                        const std::string& source) {
    imaging::SimulationSettings settings;
    probe::Transducer t = probe::find_transducer(r.probe.empty() ? preset : r.probe, "--probe");
    for (const auto& doc : probe::transducer_parameter_docs()) {
        const auto given = r.transducer.find(doc.key);
        if (given != r.transducer.end() && given->second)
            doc.set(t, *given->second, std::string("--") + doc.key);
    }
    settings.transducer = t;
    settings.quality = imaging::parse_quality(r.quality, "--quality", "");
    settings.receive =
        parse_choice<imaging::ReceiveModel>(r.receive, "--receive",
                                            {{"monostatic", imaging::ReceiveModel::monostatic},
                                             {"capture", imaging::ReceiveModel::capture}});
    settings.trace_dimensions = parse_choice<int>(r.trace, "--trace", {{"2d", 2}, {"3d", 3}});
    settings.seed = r.seed;
    imaging::apply(imaging::disabled_physics(r.disable, "--disable", ""), settings);
    settings.trace.deposition_maps = r.energy;  // the energy map is their only reader
    settings.step_texels = r.step_texels;
    if (r.refraction_smoothing_mm != -1.0)
        settings.refraction_smoothing_mm = r.refraction_smoothing_mm;
    settings.imaging.gain_db = r.gain_db.value_or(kDefaultGainDb);
    settings.imaging.dynamic_range_db = r.dynamic_range_db;
    settings.imaging.pixel_mm = r.pixel_mm;
    settings.imaging.tgc = parse_tgc(r.tgc, settings.transducer);
    settings.imaging.noise_snr_db = r.noise_snr_db;
    if (r.transmit != "focused")
        settings.transmit = probe::parse_transmit_scheme(r.transmit, "--transmit", "");
    else if (r.channels)
        throw base::InputError("--channels", "",
                               "channel data come from unfocused transmits: give --transmit "
                               "plane:... or diverging:...");
    settings.validate(source);
    return settings;
}

}  // namespace

SceneOptions FrameRequest::scene_options() const {
    SceneOptions o;
    static_cast<VolumeOptions&>(o) = *this;
    o.phantom = phantom;
    o.view = view;
    if (pose != "default") o.pose = probe::parse_pose(pose, "--pose");
    return o;
}

std::string RequestParameter::help() const {
    std::string text = description;
    if (!unit.empty()) text += " [" + unit + "]";
    if (range)
        text += " (range " + base::number_text(range->low) + " to " +
                base::number_text(range->high) + ")";
    return text;
}

const std::vector<RequestParameter>& request_parameters() {
    static const std::vector<RequestParameter> table = make_table();
    return table;
}

const RequestParameter& request_parameter(std::string_view key) {
    for (const RequestParameter& p : request_parameters())
        if (p.key == key) return p;
    throw std::logic_error("no request parameter " + std::string(key));
}

ParameterKind request_parameter_kind(std::string_view key) {
    const std::string k = normalised(key);
    if (transducer_row(k)) return ParameterKind::value;
    for (const RequestParameter& p : request_parameters())
        if (p.key == k)
            return std::holds_alternative<bool FrameRequest::*>(p.member) ? ParameterKind::flag
                                                                          : ParameterKind::value;
    return ParameterKind::unknown;
}

void set_request_parameter(FrameRequest& request, std::string_view key, const std::string& text,
                           const std::string& source) {
    const std::string k = normalised(key);
    auto fail = [&](const std::optional<std::string>& why) {
        if (why) throw base::InputError(source, k, *why);
    };
    if (const probe::TransducerParameterDoc* doc = transducer_row(k)) {
        // The kind of the value (a number, a whole number, a name) is checked here, as for
        // every parameter; its range when the transducer is made.
        std::visit(
            [&](const auto& kind) {
                using V = std::decay_t<decltype(kind)>;
                if constexpr (std::is_same_v<V, double>) fail(base::not_a_finite_number(text));
                if constexpr (std::is_same_v<V, int>) {
                    const bool negative = !text.empty() && text[0] == '-';
                    fail(base::not_a_whole_number(negative ? text.substr(1) : text));
                }
            },
            doc->get(probe::Transducer{}));
        request.transducer[k] = text;
        return;
    }
    for (const RequestParameter& p : request_parameters()) {
        if (p.key != k) continue;
        std::visit(
            [&](auto member) {
                using V = std::decay_t<decltype(request.*member)>;
                if constexpr (std::is_same_v<V, std::string>) {
                    request.*member = text;
                } else if constexpr (std::is_same_v<V, bool>) {
                    if (text != "true" && text != "false")
                        throw base::InputError(source, k, "is a flag: true or false");
                    request.*member = text == "true";
                } else if constexpr (std::is_same_v<V, uint64_t>) {
                    fail(base::not_a_whole_number(text));
                    request.*member = std::stoull(text);
                } else {
                    fail(base::not_a_finite_number(text));
                    request.*member = *base::finite_number(text);
                }
            },
            p.member);
        return;
    }
    unknown_key(k, source);
}

imaging::SimulationSettings make_settings(const FrameRequest& request, const Scene& scene,
                                          const std::string& source) {
    imaging::SimulationSettings settings = settings_of(request, scene.probe_preset, source);
    scene.apply_to(settings);
    if (!request.gain_db) settings.imaging.gain_db = scene.gain_db;
    return settings;
}

FrameSetup prepare_frames(const FrameRequest& request, base::StageObserver* stages) {
    FrameSetup setup;
    // ---- everything that needs no file, checked before anything is loaded ----
    const SceneOptions scene_options = request.scene_options();
    scene_options.validate();
    // A phantom is read first: it is small, and it names the default probe.
    if (!request.phantom.empty()) setup.scene = load_scene(scene_options, stages);
    settings_of(request,
                setup.scene ? setup.scene->probe_preset : scene_options.volume_probe_preset(),
                "simulate options");
    // ---- the scene, and the probe placed ----
    if (!setup.scene) setup.scene = load_scene(scene_options, stages);
    setup.settings = make_settings(request, *setup.scene);
    setup.placements = sweep_placements(request.sweep, setup.scene->start);
    const std::string pose_source = (setup.scene->phantom ? request.phantom + " " : "") +
                                    (request.sweep.empty() ? "--pose" : "--sweep");
    for (const SweepPlacement& p : setup.placements)
        setup.scene->require_inside(p.scene.pose, pose_source);
    return setup;
}

json frame_sidecar(const FrameRequest& request, const FrameSetup& setup,
                   const imaging::Frame& frame) {
    const imaging::SimulationSettings& settings = setup.settings;
    const Scene& scene = *setup.scene;
    const imaging::QualityLevel level = imaging::quality_level(settings.quality);
    json off = json::array();
    for (const auto& n : simulator::kPhysicsSwitches)
        if (!settings.trace.physics.on(n.id)) off.push_back(n.name);
    return {
        {"command", "simulate"},
        {"version", SONOTRACE_VERSION},
        {"seed", request.seed},
        {"view", request.view},
        {"scene", scene.start.description},
        {"source", scene.phantom ? json{{"phantom", request.phantom},
                                        {"name", scene.phantom->name},
                                        {"description", scene.phantom->description}}
                                 : volume_source_json(*scene.volume, request)},
        {"probe", transducer_json(settings.transducer)},
        {"pose", pose_json(scene.start.pose)},
        {"quality",
         {{"name", imaging::to_string(settings.quality)},
          {"map_pixel_mm", level.map_pixel_mm},
          {"particles_per_line", level.particles_per_line},
          {"step_texels", settings.step_texels > 0.0 ? settings.step_texels : level.step_texels},
          {"refraction_smoothing_mm", imaging::refraction_smoothing_mm(settings)}}},
        {"receive", imaging::to_string(settings.receive)},
        {"transmit", frame.channels ? json{{"scheme", request.transmit},
                                           {"transmits", frame.channels->transmits},
                                           {"particles_per_transmit",
                                            imaging::particles_per_transmit(settings)},
                                           {"channels",
                                            {{"elements", frame.channels->elements},
                                             {"samples", frame.channels->samples},
                                             {"sampling_hz", frame.channels->fs_hz},
                                             {"start_s", frame.channels->start_s}}}}
                                    : json("focused")},
        {"trace", settings.trace_dimensions == 3 ? "3d" : "2d"},
        {"disabled_physics", off},
        {"craniotomy",
         {{"radius_mm", scene.start.craniotomy_radius_mm},
          {"depth_mm", scene.start.craniotomy_depth_mm}}},
        {"image",
         {{"width", frame.image.image.cols},
          {"height", frame.image.image.rows},
          {"pixel_spacing_mm", {request.pixel_mm, request.pixel_mm}},
          {"origin_mm", {frame.image.origin.x, frame.image.origin.y}},
          {"axes", "x = lateral, y = depth from the probe face apex (mm); row 0 at origin.y"},
          {"gain_db", settings.imaging.gain_db},
          {"dynamic_range_db", request.dynamic_range_db},
          {"tgc", request.tgc},
          {"noise_snr_db",
           settings.imaging.noise_snr_db ? json(*settings.imaging.noise_snr_db) : json(nullptr)}}},
        {"rf",
         {{"lines", frame.rf.lines},
          {"samples", frame.rf.samples},
          {"sampling_hz", frame.rf.fs_hz}}},
        {"stats",
         {{"particles", frame.stats.particles},
          {"steps", frame.stats.steps},
          {"reflections", frame.stats.reflections},
          {"scatter_events", frame.stats.scatter_events},
          {"captured", frame.stats.captured},
          {"energy_balance_error", frame.ledger.relative_error()}}},
        {"timings_s", frame.timings},
    };
}

}  // namespace sonotrace::scene
