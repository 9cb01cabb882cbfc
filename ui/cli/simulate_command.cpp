#include "ui/cli/simulate_command.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "imaging/picture.h"
#include "imaging/simulation.h"
#include "probe/placement.h"
#include "sonotrace_version.h"
#include "tissue/atomic_output.h"
#include "tissue/error.h"
#include "tissue/image_io.h"
#include "tissue/property_maps.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::ui {

namespace {

using nlohmann::json;

// ---- parameters, documented once ----
constexpr ParameterDoc kViewDoc = {
    "--view", "",
    "scene of the default head: 'craniotomy' (convex probe on the right parietal cortex "
    "through a virtual craniotomy, coronal plane through the lateral ventricles) or "
    "'temporal' (phased probe on the right temple, imaging through the skull). Other "
    "volumes, or --pose, place the probe without a craniotomy"};
constexpr ParameterDoc kProbeDoc = {
    "--probe", "",
    "transducer preset: linear (7.6 MHz, like the L11-5v), convex (3.5 MHz, like the C5-2v), "
    "phased (2.7 MHz, like the P4-2v); empty = the view's probe"};
constexpr ParameterDoc kQualityDoc = {
    "--quality", "",
    "interactive (0.5 mm map, 8 particles per line), standard (0.25 mm, 32), high "
    "(0.125 mm, 128)"};
constexpr ParameterDoc kReceiveDoc = {
    "--receive", "",
    "echo model: 'monostatic' (each reflection echoes at twice its time, two-way loss) or "
    "'capture' (only particles that reach the probe face; the face reflects part back)"};
constexpr ParameterDoc kGainDoc = {"--gain", "dB", "overall receive gain before log compression"};
constexpr ParameterDoc kRangeDoc = {"--dynamic-range", "dB",
                                    "range of echo levels mapped from black to white"};
constexpr ParameterDoc kTgcDoc = {
    "--tgc", "mm:dB",
    "time-gain compensation: 'auto' (2 x 0.6 dB/(cm MHz) x f x depth, brain attenuation), "
    "'none', or a curve 'DEPTH:GAIN,DEPTH:GAIN,...' (linear in between)"};
constexpr ParameterDoc kPixelDoc = {"--pixel", "mm", "pixel size of the scan-converted image"};
constexpr ParameterDoc kStepDoc = {"--step", "texels", simulator::doc::kStep};
constexpr ParameterDoc kSeedDoc = {"--seed", "",
                                   "random seed of the beams, tracing and scatterer field"};
constexpr ParameterDoc kFormatsDoc = {
    "--formats", "",
    "comma list of frame formats: png8 (NAME.png), png16 (NAME_16.png), exr (NAME.exr, float "
    "0..1)"};
constexpr ParameterDoc kOutDoc = {"--out", "", "output directory"};
constexpr ParameterDoc kNameDoc = {"--name", "", "file stem of the frame and its sidecar"};
constexpr ParameterDoc kJsonDoc = {
    "--json", "", "also write the run record (description and timings); '-' = stdout"};
constexpr ParameterDoc kThreadsDoc = {"--threads", "", "worker threads; 0 = all cores"};

std::vector<imaging::TgcPoint> parse_tgc(const std::string& text, const probe::Transducer& t) {
    if (text == "none") return {};
    if (text == "auto") {
        // Compensates the two-way attenuation of brain, 0.6 dB/(cm MHz).
        return {{0.0, 0.0}, {t.depth_mm, 2.0 * 0.6 * t.frequency_mhz * t.depth_mm / 10.0}};
    }
    std::vector<imaging::TgcPoint> curve;
    std::istringstream list(text);
    for (std::string item; std::getline(list, item, ',');) {
        const auto colon = item.find(':');
        imaging::TgcPoint p;
        try {
            if (colon == std::string::npos) throw std::invalid_argument("no colon");
            std::size_t used = 0;
            p.depth_mm = std::stod(item.substr(0, colon), &used);
            p.gain_db = std::stod(item.substr(colon + 1));
        } catch (const std::exception&) {
            throw tissue::InputError("--tgc", item,
                                     "expected DEPTH:GAIN (mm:dB), 'auto' or 'none'");
        }
        curve.push_back(p);
    }
    return curve;
}

probe::Transducer make_transducer(const SimulateOptions& o, const std::string& preset) {
    probe::Transducer t = probe::find_transducer(preset, "--probe");
    if (o.type) {
        if (*o.type == "linear")
            t.type = probe::TransducerType::linear;
        else if (*o.type == "convex")
            t.type = probe::TransducerType::convex;
        else if (*o.type == "phased")
            t.type = probe::TransducerType::phased;
        else
            throw tissue::InputError("--type", "", "must be linear, convex or phased");
    }
    if (o.elements) t.elements = *o.elements;
    if (o.lines) t.lines = *o.lines;
    if (o.pitch) t.pitch_mm = *o.pitch;
    if (o.radius) t.radius_mm = *o.radius;
    if (o.fov) t.fov_deg = *o.fov;
    if (o.frequency) t.frequency_mhz = *o.frequency;
    if (o.bandwidth) t.bandwidth = *o.bandwidth;
    if (o.focus) t.focus_mm = *o.focus;
    if (o.f_number) t.f_number = *o.f_number;
    if (o.elevation_focus) t.elevation_focus_mm = *o.elevation_focus;
    if (o.slice_thickness) t.slice_thickness_mm = *o.slice_thickness;
    if (o.depth) t.depth_mm = *o.depth;
    if (o.face_reflectivity) t.face_reflectivity = *o.face_reflectivity;
    return t;
}

json transducer_json(const probe::Transducer& t) {
    return {{"name", t.name},
            {"description", t.description},
            {"type", probe::to_string(t.type)},
            {"elements", t.elements},
            {"pitch_mm", t.pitch_mm},
            {"radius_mm", t.radius_mm},
            {"fov_deg", t.fov_deg},
            {"frequency_mhz", t.frequency_mhz},
            {"bandwidth", t.bandwidth},
            {"focus_mm", t.focus_mm},
            {"f_number", t.f_number},
            {"elevation_focus_mm", t.elevation_focus_mm},
            {"slice_thickness_mm", t.slice_thickness_mm},
            {"depth_mm", t.depth_mm},
            {"lines", t.lines},
            {"face_reflectivity", t.face_reflectivity}};
}

template <typename E>
E parse_enum(const std::string& text, const char* flag,
             const std::vector<std::pair<std::string, E>>& choices) {
    std::string names;
    for (const auto& [name, value] : choices) {
        if (name == text) return value;
        names += (names.empty() ? "" : ", ") + name;
    }
    throw tissue::InputError(flag, "", "must be one of " + names + ", got '" + text + "'");
}

// Frame (0..1, scan converted) as an image file of the requested format.
void write_frame(const cv::Mat& image, const std::string& path, int bits) {
    std::vector<float> pixels(image.begin<float>(), image.end<float>());
    const float full_scale = bits == 8 ? 255.0f : bits == 16 ? 65535.0f : 1.0f;
    for (float& v : pixels) v = bits == 32 ? v : std::round(v * full_scale);  // stored as integers
    tissue::write_gray_image(path, image.cols, image.rows, pixels, bits);
}

}  // namespace

CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& o) {
    CLI::App* cmd = app.add_subcommand(
        "simulate",
        "Simulate a B-mode frame: beams from a transducer model are traced through the tissue "
        "map, their echoes become RF lines (pulse, speckle), envelope, TGC, log compression and "
        "a scan-converted image with a JSON sidecar. Without arguments: the Colin27 head, convex "
        "probe on the cortex through a craniotomy, written to out/bmode.png.");
    add_parameter(*cmd, kViewDoc, o.view);
    add_volume_options(*cmd, o.volume);
    add_parameter(*cmd, kProbeDoc, o.probe);
    for (const auto& doc : probe::transducer_parameter_docs()) {
        const std::string flag = std::string("--") + doc.key;
        std::string help = std::string(doc.description) + " (default: the preset's)";
        if (doc.unit[0] != '\0') help += std::string(" [") + doc.unit + "]";
        const std::string key = doc.key;
        if (key == "type")
            cmd->add_option(flag, o.type, help);
        else if (key == "elements")
            cmd->add_option(flag, o.elements, help);
        else if (key == "lines")
            cmd->add_option(flag, o.lines, help);
        else if (key == "pitch")
            cmd->add_option(flag, o.pitch, help);
        else if (key == "radius")
            cmd->add_option(flag, o.radius, help);
        else if (key == "fov")
            cmd->add_option(flag, o.fov, help);
        else if (key == "frequency")
            cmd->add_option(flag, o.frequency, help);
        else if (key == "bandwidth")
            cmd->add_option(flag, o.bandwidth, help);
        else if (key == "focus")
            cmd->add_option(flag, o.focus, help);
        else if (key == "f-number")
            cmd->add_option(flag, o.f_number, help);
        else if (key == "elevation-focus")
            cmd->add_option(flag, o.elevation_focus, help);
        else if (key == "slice-thickness")
            cmd->add_option(flag, o.slice_thickness, help);
        else if (key == "depth")
            cmd->add_option(flag, o.depth, help);
        else if (key == "face-reflectivity")
            cmd->add_option(flag, o.face_reflectivity, help);
    }
    add_parameter(*cmd, kQualityDoc, o.quality);
    add_parameter(*cmd, kReceiveDoc, o.receive);
    add_parameter(*cmd, kGainDoc, o.gain_db);
    add_parameter(*cmd, kRangeDoc, o.dynamic_range_db);
    add_parameter(*cmd, kTgcDoc, o.tgc);
    add_parameter(*cmd, kPixelDoc, o.pixel_mm);
    add_parameter(*cmd, kStepDoc, o.step_texels);
    add_parameter(*cmd, kSeedDoc, o.seed);
    add_parameter(*cmd, kFormatsDoc, o.formats);
    cmd->add_flag("--rf", o.write_rf, "also write the RF lines (NAME_rf.exr: lines x samples)");
    cmd->add_flag("--envelope", o.write_envelope,
                  "also write the envelope (NAME_envelope.exr: lines x samples)");
    cmd->add_flag(
        "--labels", o.write_labels,
        "also write the ground-truth tissue labels in the frame's pixels (NAME_labels.png, "
        "values = tissue index listed in the sidecar) and a colour preview");
    cmd->add_flag("--energy", o.write_energy,
                  "also write the energy deposition map (NAME_energy.png)");
    add_parameter(*cmd, kOutDoc, o.out_dir);
    add_parameter(*cmd, kNameDoc, o.name);
    add_parameter(*cmd, kJsonDoc, o.json_path);
    add_parameter(*cmd, kThreadsDoc, o.threads)->check(CLI::Range(0, 1024));
    cmd->add_flag("-q,--quiet", o.quiet, "no progress on stderr");
    return cmd;
}

int run_simulate_command(const SimulateOptions& o) {
    StageTimer timer(o.quiet);
    const auto thread_limit = limit_threads(o.threads);

    // ---- validate everything before loading ----
    if (o.view != "craniotomy" && o.view != "temporal")
        throw tissue::InputError("--view", "",
                                 "must be craniotomy or temporal, got '" + o.view + "'");
    const std::string preset =
        !o.probe.empty() ? o.probe : (o.view == "temporal" ? "phased" : "convex");
    imaging::SimulationSettings settings;
    settings.transducer = make_transducer(o, preset);
    settings.quality = parse_enum<imaging::Quality>(o.quality, "--quality",
                                                    {{"interactive", imaging::Quality::interactive},
                                                     {"standard", imaging::Quality::standard},
                                                     {"high", imaging::Quality::high}});
    settings.receive =
        parse_enum<imaging::ReceiveModel>(o.receive, "--receive",
                                          {{"monostatic", imaging::ReceiveModel::monostatic},
                                           {"capture", imaging::ReceiveModel::capture}});
    settings.seed = o.seed;
    settings.trace.step_texels = o.step_texels;
    settings.imaging.gain_db = o.gain_db;
    settings.imaging.dynamic_range_db = o.dynamic_range_db;
    settings.imaging.pixel_mm = o.pixel_mm;
    settings.imaging.tgc = parse_tgc(o.tgc, settings.transducer);
    settings.validate("simulate options");
    std::vector<std::pair<std::string, int>> formats;  // file suffix, bits
    {
        std::istringstream list(o.formats);
        for (std::string f; std::getline(list, f, ',');) {
            if (f == "png8")
                formats.emplace_back(".png", 8);
            else if (f == "png16")
                formats.emplace_back("_16.png", 16);
            else if (f == "exr")
                formats.emplace_back(".exr", 32);
            else
                throw tissue::InputError("--formats", f, "unknown format (png8, png16, exr)");
        }
        if (formats.empty()) throw tissue::InputError("--formats", "", "is empty");
    }
    if (o.name.empty() || o.name.find('/') != std::string::npos)
        throw tissue::InputError("--name", "", "must be a plain file stem");
    std::optional<probe::Pose> pose;
    if (o.volume.pose != "default") pose = probe::parse_pose(o.volume.pose, "--pose");

    // ---- load and place the probe ----
    const VolumeSource source = load_volume_source(o.volume, timer);
    {
        const glm::dvec3 voxel = source.loaded.volume.geometry().spacing;
        settings.trace.interface_reach_mm = 3.0 * std::max({voxel.x, voxel.y, voxel.z});
    }
    imaging::ScenePlacement scene;
    timer.begin("placing the probe (" + o.view + ")");
    if (pose) {
        scene.pose = *pose;
        scene.description = "probe at --pose";
    } else if (source.is_default) {
        scene = o.view == "temporal" ? imaging::temporal_scene(source.loaded.volume, *source.tf)
                                     : imaging::craniotomy_scene(source.loaded.volume, *source.tf);
    } else {
        scene.pose = top_centre_pose(source.loaded.volume.geometry());
        scene.description = "probe on the top face of the volume";
    }
    timer.end();

    // ---- the plane under the probe ----
    const imaging::QualityLevel level = imaging::quality_level(settings.quality);
    const imaging::PlaneGrid grid =
        imaging::plane_grid(settings.transducer, scene.pose, level.map_pixel_mm);
    timer.begin("acoustic map " + std::to_string(grid.geometry.dims.x) + "x" +
                std::to_string(grid.geometry.dims.y));
    const tissue::Volume plane_values = source.resample(grid.geometry);
    tissue::PropertyMaps maps = tissue::classify(plane_values, *source.tf);
    std::optional<tissue::Volume> labels;
    if (o.write_labels) labels = tissue::tissue_labels(plane_values, *source.tf);
    imaging::prepare_plane(maps, grid, scene, 5.0, labels ? &*labels : nullptr);
    const auto map = tissue::AcousticMap<2>::build(maps);
    timer.end();

    // ---- trace and form the frame ----
    const std::size_t particles =
        std::size_t(settings.transducer.lines) * std::size_t(level.particles_per_line);
    ProgressBar bar("simulating " + std::to_string(particles) + " particles", o.quiet);
    const imaging::Frame frame = imaging::simulate_frame(
        map, grid, scene.pose, settings,
        [&bar](std::size_t done, std::size_t total) { bar.update(done, total); });
    bar.finish();

    // ---- outputs, staged and committed together ----
    timer.begin("writing");
    tissue::OutputTransaction transaction;
    const std::filesystem::path out(o.out_dir);
    std::vector<std::string> written;
    for (const auto& [suffix, bits] : formats) {
        const std::string path = (out / (o.name + suffix)).string();
        write_frame(frame.image.image, transaction.stage(path), bits);
        written.push_back(path);
    }
    auto write_lines = [&](const imaging::LineData& d, const std::string& suffix) {
        const std::string path = (out / (o.name + suffix)).string();
        tissue::write_gray_image(transaction.stage(path), d.samples, d.lines, d.values, 32);
        written.push_back(path);
    };
    if (o.write_rf) write_lines(frame.rf, "_rf.exr");
    if (o.write_envelope) write_lines(frame.envelope, "_envelope.exr");
    json label_record;
    if (labels) {
        const cv::Mat label_image = imaging::scan_convert_labels(*labels, grid, frame.image);
        const std::string path = (out / (o.name + "_labels.png")).string();
        const std::vector<float> values(label_image.begin<uint8_t>(), label_image.end<uint8_t>());
        tissue::write_gray_image(transaction.stage(path), label_image.cols, label_image.rows,
                                 values, 8);
        const std::string preview = (out / (o.name + "_labels_preview.png")).string();
        imaging::write_png(imaging::label_picture(label_image), transaction.stage(preview));
        written.push_back(path);
        written.push_back(preview);
        json legend = {{"0", "outside the scanned region"}};
        for (std::size_t i = 0; i < tissue::tissue_table().size(); ++i)
            legend[std::to_string(i + 1)] = tissue::tissue_label_name(int(i) + 1);
        label_record = {
            {"file", path},
            {"legend", legend},
            {"geometry", "same pixels as the frame; true (not echo-delayed) positions"}};
    }
    if (o.write_energy) {
        imaging::FieldStyle style{"absorbed energy (sedimentation)",
                                  "energy",
                                  imaging::Colormap::inferno,
                                  std::nullopt,
                                  true,
                                  level.map_pixel_mm};
        const std::string path = (out / (o.name + "_energy.png")).string();
        imaging::write_png(imaging::render_field(frame.absorbed, style), transaction.stage(path));
        written.push_back(path);
    }
    timer.end();

    json record = {
        {"command", "simulate"},
        {"version", SONOTRACE_VERSION},
        {"seed", o.seed},
        {"view", o.view},
        {"scene", scene.description},
        {"source", volume_source_json(source, o.volume)},
        {"probe", transducer_json(settings.transducer)},
        {"pose", pose_json(scene.pose)},
        {"quality",
         {{"name", imaging::to_string(settings.quality)},
          {"map_pixel_mm", level.map_pixel_mm},
          {"particles_per_line", level.particles_per_line}}},
        {"receive", imaging::to_string(settings.receive)},
        {"craniotomy",
         {{"radius_mm", scene.craniotomy_radius_mm}, {"depth_mm", scene.craniotomy_depth_mm}}},
        {"image",
         {{"width", frame.image.image.cols},
          {"height", frame.image.image.rows},
          {"pixel_spacing_mm", {o.pixel_mm, o.pixel_mm}},
          {"origin_mm", {frame.image.origin.x, frame.image.origin.y}},
          {"axes", "x = lateral, y = depth from the probe face apex (mm); row 0 at origin.y"},
          {"gain_db", o.gain_db},
          {"dynamic_range_db", o.dynamic_range_db},
          {"tgc", o.tgc}}},
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
        {"labels", label_record},
        {"timings_s", frame.timings},
        {"stage_timings_s", timer.timings()},
        {"outputs", written},
    };
    const std::string sidecar = (out / (o.name + ".json")).string();
    write_json(record, transaction.stage(sidecar));
    if (!o.json_path.empty() && o.json_path != "-")
        write_json(record, transaction.stage(o.json_path));
    transaction.commit();
    if (o.json_path == "-") write_json(record, "-");
    if (!o.quiet) std::cerr << "sonotrace: wrote " << written.front() << " and " << sidecar << "\n";
    return 0;
}

}  // namespace sonotrace::ui
