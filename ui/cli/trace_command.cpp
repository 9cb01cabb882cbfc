#include "ui/cli/trace_command.h"
#include "tissue/base/data_dir.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <numbers>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "imaging/picture.h"
#include "imaging/simulation.h"
#include "imaging/trace_pictures.h"
#include "phantoms/trace_setup.h"
#include "simulator/trace_setups.h"
#include "simulator/tracer.h"
#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"

namespace sonotrace::ui {

namespace {

using nlohmann::json;
using simulator::TraceSetup;

constexpr ParameterDoc kConfigDoc = {
    "--config", "",
    "built-in configuration reproducing a figure of Reis & Bertram: fig2 (two interfaces, fan: "
    "refraction and total reflection), fig4a / fig4b (bent fibre, parallel / fan injection), "
    "fig5 (Colin27 slice, parallel injection from the upper right), fig6 (45-degree beam on a "
    "reflector over inhomogeneous matter, with the intensity profile over a semicircle). "
    "Figures 2, 4 and 6 are the catalogue phantoms phantoms/paper_fig*.json. "
    "Empty: trace a volume slice (the --volume options)"};
constexpr ParameterDoc kPhantomDoc = {
    "--phantom", "",
    "JSON phantom with a \"source\" entry (phantoms/paper_fig*.json, or any phantom with one): "
    "its medium on the z = size/2 plane, its particles and its \"trace\" physics"};
constexpr ParameterDoc kModeDoc = {"--mode", "", simulator::doc::kMode};
constexpr ParameterDoc kParticlesDoc = {
    "--particles", "", "particles in total; 0 = the configuration's default (volume: 4000)"};
constexpr ParameterDoc kLinesDoc = {"--lines", "",
                                    "scan lines the particles are split into (volume slices)"};
constexpr ParameterDoc kInjectionDoc = {
    "--injection", "",
    "volume slices: 'fan' from the probe centre or 'parallel' across --beam-width"};
constexpr ParameterDoc kBeamAngleDoc = {"--beam-angle", "degrees", "half opening angle of a fan"};
constexpr ParameterDoc kBeamWidthDoc = {"--beam-width", "mm", "width of a parallel beam"};
constexpr ParameterDoc kContrastDoc = {
    "--contrast", "",
    "paper mode on a volume: density d = 1 + contrast * (value - min) / (max - min)"};
constexpr ParameterDoc kFaceDoc = {
    "--face-reflectivity", "0..1",
    "intensity fraction the probe face reflects back into the tissue (volume slices)"};
constexpr ParameterDoc kLobeExponentDoc = {"--lobe-exponent", "", simulator::doc::kLobeExponent};
constexpr ParameterDoc kLobeWeightDoc = {"--lobe-weight", "", simulator::doc::kLobeWeight};
constexpr ParameterDoc kLobeScaleDoc = {
    "--lobe-scale", "", "factor on c for the paper's lobe interpretations; < 0 = default"};
constexpr ParameterDoc kStepDoc = {"--step", "texels", simulator::doc::kStep};
constexpr ParameterDoc kFrequencyDoc = {"--frequency", "MHz", simulator::doc::kFrequency};
constexpr ParameterDoc kSeedDoc = {"--seed", "", simulator::doc::kSeed};
constexpr ParameterDoc kMaxBouncesDoc = {"--max-bounces", "", simulator::doc::kMaxBounces};
constexpr ParameterDoc kPathsDoc = {
    "--paths", "", "particle paths drawn per line; -1 = the configuration's default"};
constexpr ParameterDoc kEchoesDoc = {"--echoes", "",
                                     "also write every echo event as CSV to this file"};
constexpr ParameterDoc kOutDoc = {"--out", "", "output directory"};

// The --disable switches: simulate's names (simulator::kPhysicsSwitches), but for the
// image's speckle, which a trace does not make.
void apply_disable(const std::string& disable, simulator::TraceSettings& s) {
    const imaging::PhysicsSwitches off = imaging::disabled_physics(disable, "--disable", "");
    if (!off.on(simulator::Physics::speckle))
        throw base::InputError(
            "--disable", "speckle",
            "is the B-mode image's; a trace makes no image (sonotrace simulate)");
    imaging::switch_off(off, s);
}

// Options that apply to built-in configurations and volume slices alike.
void apply_integration_options(const TraceOptions& o, simulator::TraceSettings& s) {
    s.seed = o.seed;
    s.step_texels = o.step_texels;
    s.frequency_mhz = o.frequency_mhz;
    if (o.lobe_scale >= 0.0) s.lobe_scale = o.lobe_scale;
}

// Physics switches and enums from their option text.
void apply_physics_options(const TraceOptions& o, simulator::TraceSettings& s) {
    if (o.mode == "paper")
        s.mode = simulator::PhysicsMode::paper;
    else if (o.mode == "acoustic")
        s.mode = simulator::PhysicsMode::acoustic;
    else
        throw base::InputError("--mode", "", "must be 'acoustic' or 'paper', got '" + o.mode + "'");
    if (o.lobe_exponent == "roughness")
        s.lobe_exponent = simulator::LobeExponent::roughness;
    else if (o.lobe_exponent == "reflecting-density")
        s.lobe_exponent = simulator::LobeExponent::reflecting_density;
    else if (o.lobe_exponent == "density-ratio")
        s.lobe_exponent = simulator::LobeExponent::density_ratio;
    else if (!o.lobe_exponent.empty()) {
        throw base::InputError("--lobe-exponent", "",
                               "must be roughness, reflecting-density or density-ratio");
    }
    if (o.lobe_weight == "probability")
        s.lobe_weight = simulator::LobeWeight::probability;
    else if (o.lobe_weight == "energy")
        s.lobe_weight = simulator::LobeWeight::energy;
    else if (!o.lobe_weight.empty())
        throw base::InputError("--lobe-weight", "", "must be probability or energy");
    apply_integration_options(o, s);
    s.max_bounces = o.max_bounces;
    apply_disable(o.disable, s);  // after --max-bounces: `bounces` off wins
}

// A volume slice as a trace set-up: the probe at the top centre, fan or parallel injection.
TraceSetup volume_setup(const TraceOptions& o, const Slice& slice) {
    TraceSetup setup;
    setup.name = "volume";
    setup.description = "volume slice of " + slice.source.loaded.path;
    const int particles = o.particles > 0 ? o.particles : 4000;
    if (o.mode == "paper") {
        if (!(std::isfinite(o.contrast) && o.contrast > 0.0 && o.contrast < 100.0)) {
            throw base::InputError("--contrast", "", "must be in (0, 100)");
        }
        tissue::Volume density = slice.values;
        const double lo = slice.source.value_min,
                     span =
                         std::max(1e-12, double(slice.source.value_max - slice.source.value_min));
        for (float& v : density.voxels())
            v = float(1.0 + o.contrast * std::clamp((v - lo) / span, 0.0, 1.0));
        setup.map = tissue::AcousticMap<2>::build_paper(density);
        setup.medium = std::move(density);
        setup.medium_label = "density d";
    } else {
        setup.map = tissue::AcousticMap<2>::build(slice.maps);
        setup.medium = slice.maps.impedance();
        setup.medium_label = "impedance Z";
        setup.medium_unit = "MRayl";
    }
    const glm::vec2 extent = setup.map.extent_mm();
    const glm::vec2 face_centre(0.5f * extent.x, 0.01f);
    if (o.lines < 1 || o.lines > 100000)
        throw base::InputError("--lines", "", "must be between 1 and 100000");
    for (int p = 0; p < particles; ++p) {
        const float u = (float(p) + 0.5f) / float(particles) * 2.0f - 1.0f;  // -1..1
        const auto line = uint32_t(std::int64_t(p) * o.lines / particles);
        if (o.injection == "fan") {
            const float a = glm::radians(float(o.beam_angle_deg)) * u;
            setup.sources.push_back({face_centre, {std::sin(a), std::cos(a)}, 1.0f, line});
        } else if (o.injection == "parallel") {
            setup.sources.push_back(
                {face_centre + glm::vec2(0.5f * float(o.beam_width_mm) * u, 0.0f),
                 {0.0f, 1.0f},
                 1.0f,
                 line});
        } else {
            throw base::InputError("--injection", "", "must be 'fan' or 'parallel'");
        }
    }
    simulator::ProbeFace<2> face;
    face.centre = {face_centre.x, 0.0f};
    face.normal = {0.0f, 1.0f};
    face.half_width_mm = o.injection == "fan" ? 5.0f : 0.5f * float(o.beam_width_mm);
    face.reflectivity = float(o.face_reflectivity);
    setup.settings.probe_face_2d = face;
    if (o.mode == "paper") {
        setup.settings.mode = simulator::PhysicsMode::paper;
        setup.settings.lobe_exponent = simulator::LobeExponent::reflecting_density;
    }
    setup.settings.record_paths = 10;
    return setup;
}

void write_echoes_csv(const std::vector<simulator::EchoEvent<2>>& echoes, const std::string& path) {
    std::ostringstream out;
    out << "line,particle,time_s,energy,weight,x_mm,y_mm,bounces,kind,cos_incidence,lobe_"
           "exponent\n";
    out.precision(9);
    for (const auto& e : echoes) {
        out << e.line << ',' << e.particle << ',' << e.time_s << ',' << e.energy << ',' << e.weight
            << ',' << e.position.x << ',' << e.position.y << ',' << e.bounces << ','
            << simulator::to_string(e.kind) << ',' << e.cos_incidence << ',' << e.lobe_exponent
            << '\n';
    }
    const std::string text = out.str();
    base::write_file(path, text.data(), text.size());
}

}  // namespace

CLI::App* add_trace_command(CLI::App& app, TraceOptions& options) {
    CLI::App* cmd = app.add_subcommand(
        "trace",
        "Trace energy particles through a medium (Reis & Bertram): draws the paths over the medium "
        "and "
        "writes the intensity (fluence) and absorbed-energy maps as PNGs with colour scales, plus "
        "trace.json with the energy ledger. Built-in configurations reproduce the paper's "
        "figures.");
    add_parameter(*cmd, kConfigDoc, options.config);
    add_parameter(*cmd, kPhantomDoc, options.phantom);
    add_slice_options(*cmd, options.slice, false);
    add_parameter(*cmd, kModeDoc, options.mode);
    add_parameter(*cmd, kParticlesDoc, options.particles)->check(CLI::Range(0, 10000000));
    add_parameter(*cmd, kLinesDoc, options.lines);
    add_parameter(*cmd, kInjectionDoc, options.injection);
    add_parameter(*cmd, kBeamAngleDoc, options.beam_angle_deg)->check(CLI::Range(0.0, 89.0));
    add_parameter(*cmd, kBeamWidthDoc, options.beam_width_mm)->check(CLI::Range(0.01, 1000.0));
    add_parameter(*cmd, kContrastDoc, options.contrast);
    add_parameter(*cmd, kFaceDoc, options.face_reflectivity);
    cmd->add_option("--disable", options.disable,
                    "comma list of physics to switch off (simulate's names; speckle is the "
                    "image's): " +
                        imaging::physics_switch_help() + ".");
    add_parameter(*cmd, kLobeExponentDoc, options.lobe_exponent);
    add_parameter(*cmd, kLobeWeightDoc, options.lobe_weight);
    add_parameter(*cmd, kLobeScaleDoc, options.lobe_scale);
    add_parameter(*cmd, kStepDoc, options.step_texels);
    add_parameter(*cmd, kFrequencyDoc, options.frequency_mhz);
    add_parameter(*cmd, kSeedDoc, options.seed);
    add_parameter(*cmd, kMaxBouncesDoc, options.max_bounces);
    add_parameter(*cmd, kPathsDoc, options.paths);
    add_parameter(*cmd, kEchoesDoc, options.echoes_csv);
    add_parameter(*cmd, kOutDoc, options.out_dir);
    add_run_options(*cmd, options.json_path, options.threads, options.quiet);
    return cmd;
}

int run_trace_command(const TraceOptions& options) {
    StageTimer timer(options.quiet);
    const auto thread_limit = limit_threads(options.threads);

    // ---- the set-up (everything validated before tracing) ----
    {
        simulator::TraceSettings checked;  // the switch names, before any volume loads
        apply_disable(options.disable, checked);
    }
    TraceSetup setup;
    json source_record;
    if (!options.config.empty() || !options.phantom.empty()) {
        if (!options.config.empty() && !options.phantom.empty())
            throw base::InputError("--phantom", "", "cannot be combined with --config");
        // The paper's figures 2, 4 and 6 are catalogue phantoms; figure 5 is an MRI slice.
        std::string file = options.phantom;
        for (const auto& [config, name] : phantoms::kPaperFigurePhantoms)
            if (options.config == config)
                file = base::phantom_catalogue_dir() + "/" + name + ".json";
        timer.begin("building configuration " + (file.empty() ? options.config : file));
        if (!file.empty()) {
            setup = phantoms::trace_setup(phantoms::load_phantom(file), options.particles);
            if (!options.config.empty()) setup.name = options.config;
        } else {
            setup = simulator::make_paper_setup(options.config,
                                                options.particles > 0 ? options.particles : 4000);
        }
        timer.end();
        source_record = {{"config", setup.name}, {"description", setup.description}};
        if (!file.empty()) source_record["phantom"] = file;
        // Only explicitly given options override the configuration's physics.
        simulator::TraceSettings& s = setup.settings;
        apply_disable(options.disable, s);
        apply_integration_options(options, s);
    } else {
        const Slice slice = make_slice(options.slice, timer);
        setup = volume_setup(options, slice);
        apply_physics_options(options, setup.settings);
        source_record = slice_json(slice, options.slice);
    }
    if (options.paths >= 0) setup.settings.record_paths = options.paths;
    setup.settings.validate("trace options");

    // ---- trace ----
    ProgressBar bar("tracing " + std::to_string(setup.sources.size()) + " particles",
                    options.quiet);
    const auto start = std::chrono::steady_clock::now();
    const auto result =
        simulator::trace(setup.map, setup.sources, setup.settings,
                         [&bar](std::size_t done, std::size_t total) { bar.update(done, total); });
    bar.finish();
    const double trace_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

    // ---- pictures ----
    timer.begin("writing pictures");
    const double px = setup.map.spacing().x;
    base::OutputTransaction transaction;
    const std::filesystem::path out(options.out_dir);
    struct Picture {
        std::string name;
        cv::Mat image;
    };
    // Fluence on a linear scale up to its 99.5th percentile (a log scale is swamped by
    // the uniform beam outside the tissue); absorption only where there is some.
    const double fluence_top = std::max(1e-12, double(result.fluence.quantile(0.995)));
    const bool absorbing = result.ledger.absorbed > 0.0;
    std::vector<Picture> pictures(absorbing ? 4 : 3);
    // Maps at the paths' scale, so that the overview sets them side by side texel for texel.
    const int scale = imaging::PathStyle{}.scale;
    tbb::parallel_for(0, int(pictures.size()), [&](int n) {
        switch (n) {
            case 0: {
                cv::Mat paths = imaging::draw_paths(setup.medium, result.paths, {});
                cv::putText(paths, "paths: blue = full energy ... red = 0.1 %", {10, 24},
                            cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(255, 255, 255), 1,
                            cv::LINE_AA);
                pictures[0] = {"paths", paths};
                break;
            }
            case 1:
                pictures[1] = {"medium", imaging::render_field(
                                             setup.medium, {setup.medium_label, setup.medium_unit,
                                                            imaging::Colormap::gray, std::nullopt,
                                                            false, px, scale})};
                break;
            case 2:
                pictures[2] = {
                    "fluence",
                    imaging::render_field(
                        result.fluence,
                        {"intensity (fluence)", "energy/mm", imaging::Colormap::inferno,
                         std::pair<double, double>(0.0, fluence_top), false, px, scale})};
                break;
            case 3:
                pictures[3] = {"absorbed", imaging::render_field(result.absorbed,
                                                                 {"absorbed energy", "energy/texel",
                                                                  imaging::Colormap::magma,
                                                                  std::nullopt, true, px, scale})};
                break;
        }
    });
    json outputs = json::array();
    std::vector<double> angles;
    if (!result.ring_profile.empty()) {
        const auto& ring = *setup.settings.ring;
        for (int b = 0; b < ring.bins; ++b) angles.push_back((b + 0.5) * 180.0 / ring.bins);
        pictures.push_back(
            {"profile", imaging::plot_profile(angles, result.ring_profile,
                                              "intensity leaving the semicircle (r = " +
                                                  std::to_string(int(ring.radius_mm)) + " mm)",
                                              "angle from the interface [degrees] (specular: 45)",
                                              "energy", {45.0})});
        std::ostringstream csv;
        csv << "angle_deg,energy\n";
        for (std::size_t b = 0; b < angles.size(); ++b)
            csv << angles[b] << ',' << result.ring_profile[b] << '\n';
        const std::string text = csv.str();
        base::write_file(transaction.stage((out / "profile.csv").string()), text.data(),
                         text.size());
        outputs.push_back({{"name", "profile"}, {"csv", (out / "profile.csv").string()}});
    }
    std::vector<cv::Mat> panels;
    for (const Picture& p : pictures) {
        const std::string path = (out / (p.name + ".png")).string();
        imaging::write_png(p.image, transaction.stage(path));
        outputs.push_back({{"name", p.name}, {"png", path}});
        if (p.name != "medium") panels.push_back(p.image);
    }
    imaging::write_png(imaging::montage(panels, 2),
                       transaction.stage((out / "overview.png").string()));
    if (!options.echoes_csv.empty())
        write_echoes_csv(result.echoes, transaction.stage(options.echoes_csv));
    timer.end();

    // ---- record ----
    const auto& l = result.ledger;
    const auto& st = result.stats;
    json echo_counts = json::object();
    for (const auto& e : result.echoes)
        echo_counts[simulator::to_string(e.kind)] =
            echo_counts.value(simulator::to_string(e.kind), 0) + 1;
    const simulator::TraceSettings& s = setup.settings;
    json record = {
        {"command", "trace"},
        {"software", {{"name", "sonotrace"}, {"version", SONOTRACE_VERSION}}},
        {"source", source_record},
        {"settings",
         {{"mode", simulator::to_string(s.mode)},
          {"step_texels", s.step_texels},
          {"frequency_mhz", s.frequency_mhz},
          {"seed", s.seed},
          {"physics",
           [&] {
               json on = json::object();
               for (const auto& sw : simulator::kPhysicsSwitches)
                   if (!sw.image_only) on[std::string(sw.record_key)] = s.physics.on(sw.id);
               return on;
           }()},
          {"max_bounces", s.max_bounces},
          {"lobe_exponent", simulator::to_string(s.lobe_exponent)},
          {"lobe_weight", simulator::to_string(s.lobe_weight)},
          {"lobe_scale", s.lobe_scale},
          {"interface_threshold", s.interface_threshold},
          {"roulette_energy", s.roulette_energy}}},
        {"particles", setup.sources.size()},
        {"ledger",
         {{"injected", l.injected},
          {"absorbed", l.absorbed},
          {"escaped", l.escaped},
          {"recorded", l.recorded},
          {"remaining", l.remaining},
          {"roulette_killed", l.roulette_killed},
          {"roulette_added", l.roulette_added},
          {"relative_error", l.relative_error()}}},
        {"stats",
         {{"steps", st.steps},
          {"interface_events", st.interface_events},
          {"reflections", st.reflections},
          {"total_reflections", st.total_reflections},
          {"scatter_events", st.scatter_events},
          {"captured", st.captured},
          {"steps_per_second", trace_seconds > 0 ? double(st.steps) / trace_seconds : 0.0}}},
        {"echoes", echo_counts},
        {"outputs", outputs},
        {"timings_s", timer.timings()},
    };
    record["timings_s"]["tracing"] = trace_seconds;
    write_json(record, transaction.stage((out / "trace.json").string()));
    if (!options.json_path.empty() && options.json_path != "-")
        write_json(record, transaction.stage(options.json_path));
    transaction.commit();
    if (options.json_path == "-") write_json(record, "-");
    if (!options.quiet) {
        std::fprintf(stderr,
                     "sonotrace: %llu steps in %.2f s (%.1f M steps/s); energy ledger error %.1e; "
                     "wrote %s\n",
                     (unsigned long long)st.steps, trace_seconds,
                     st.steps / std::max(trace_seconds, 1e-9) / 1e6, l.relative_error(),
                     (out / "overview.png").c_str());
    }
    return 0;
}

}  // namespace sonotrace::ui
