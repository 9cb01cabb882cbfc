#include "ui/cli/render_command.h"

#include <unistd.h>
#include <atomic>
#include <chrono>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "imaging/pbvr/overlay.h"
#include "imaging/pbvr/pbvr.h"
#include "imaging/picture.h"
#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/memory.h"
#include "tissue/volume_io.h"
#ifdef SONOTRACE_HAVE_GL_PBVR
#include "ui/gl/gl_pbvr.h"
#include "ui/gl/headless_gl.h"
#endif

namespace sonotrace::ui {

namespace {

using nlohmann::json;
namespace pbvr = imaging::pbvr;

constexpr ParameterDoc kVolumeDoc = {
    "--volume", "",
    "a volume (repeat for several, fused in one image): 'default' (Colin27 T1 head), a NIfTI "
    "file or raw sidecar (the first regular volume is rendered by particles, later ones are "
    "split into tetrahedra), or a VTK legacy unstructured grid (.vtk: tetrahedra, "
    "hexahedra)"};
constexpr ParameterDoc kTfDoc = {
    "--tf", "",
    "colour/opacity transfer function per --volume, in the same order: a preset (head, ramp, "
    "bmode) or a JSON file with \"points\": [{\"value\": 0..1, \"colour\": [r,g,b], "
    "\"opacity\": 0..1 per unit_length_mm}]"};
constexpr ParameterDoc kDepthDoc = {
    "--depth-sampling", "",
    "where a tetrahedron fragment's particle sits: cdf (drawn from the opacity CDF, exact), "
    "entry, middle, exit or random (the paper's comparison modes)"};
constexpr ParameterDoc kSectorDoc = {
    "--sector", "",
    "with --frame: also render the frame's sector (lines x depth x slice thickness) as a "
    "tetrahedral volume carrying the B-mode values, fused with the head"};
constexpr ParameterDoc kSectorTfDoc = {"--sector-tf", "",
                                       "transfer function of the --sector mesh (0..255 grey)"};
constexpr ParameterDoc kAzimuthDoc = {"--azimuth", "degrees",
                                      "camera turn about the up axis (+z); 0 looks along +y"};
constexpr ParameterDoc kElevationDoc = {"--elevation", "degrees", "camera height angle"};
constexpr ParameterDoc kDistanceDoc = {
    "--distance", "mm", "camera distance from the volume centre; 0 = fit the volume"};
constexpr ParameterDoc kFovDoc = {"--fov", "degrees", "vertical field of view"};
constexpr ParameterDoc kWidthDoc = {"--width", "pixels", "image width"};
constexpr ParameterDoc kHeightDoc = {"--height", "pixels", "image height"};
constexpr ParameterDoc kRepetitionsDoc = {"--repetitions", "", pbvr::doc::kRepetitions};
constexpr ParameterDoc kSubpixelDoc = {"--subpixel", "", pbvr::doc::kSubpixel};
constexpr ParameterDoc kRadiusDoc = {"--radius-scale", "", pbvr::doc::kRadiusScale};
constexpr ParameterDoc kSamplingDoc = {"--sampling", "", pbvr::doc::kSampling};
constexpr ParameterDoc kShadingDoc = {"--shading", "",
                                      "none, lambert or blinn-phong (headlight, gradient normals)"};
constexpr ParameterDoc kBackgroundDoc = {"--background", "0..1", "background colour r,g,b"};
constexpr ParameterDoc kCutDoc = {
    "--cut-away", "",
    "box not drawn, opening the volume: 'auto' (the octant facing the camera with the head "
    "preset, else none), 'none', 'octant', or x0,y0,z0,x1,y1,z1 in mm of the volume's index "
    "frame (spacing * index)"};
constexpr ParameterDoc kTimeLimitDoc = {
    "--time-limit", "s",
    "stop adding repetitions after this time; 0 = no limit (Ctrl-C also "
    "stops and keeps the image so far)"};
constexpr ParameterDoc kSeedDoc = {
    "--seed", "", "random seed; the same seed gives identical images on any thread count"};
constexpr ParameterDoc kFrameDoc = {
    "--frame", "",
    "the JSON sidecar of a `sonotrace simulate` frame (same volume): draws the probe, its scan "
    "sector and the B-mode frame on it, depth-tested against the particles; with --cut-away "
    "auto the half of the volume on the camera's side of the scan plane is removed"};
constexpr ParameterDoc kReferenceDoc = {
    "--reference", "",
    "also render the emission-absorption ray-cast reference to this PNG and report the PSNR"};
constexpr ParameterDoc kReferenceStepDoc = {"--reference-step", "mm",
                                            "sample spacing of the reference ray caster"};
constexpr ParameterDoc kRendererDoc = {
    "--renderer", "",
    "where the particles are projected: cpu (the reference) or gpu (OpenGL 3.3 through EGL, "
    "no display needed: the GPU where there is one, else Mesa's software rasteriser; the same "
    "particles and mesh fragments, so the same image within rounding)"};
constexpr ParameterDoc kOutDoc = {"--out", "", "output PNG"};

// The first Ctrl-C stops the rendering within the repetition in flight (the renderer polls
// the flag) and the image of the repetitions done is written; a second one exits at once.
std::atomic<bool> g_interrupted{false};
extern "C" void on_interrupt(int) {
    if (g_interrupted.exchange(true)) _exit(130);  // async-signal-safe: nothing is staged yet
}

}  // namespace

CLI::App* add_render_command(CLI::App& app, RenderOptions& options) {
    CLI::App* cmd = app.add_subcommand(
        "render",
        "Particle-based volume rendering (Sakamoto & Koyamada) of the 3D tissue context: "
        "opaque particles generated from the transfer function's opacity, projected with a "
        "Z-buffer and averaged over repetitions. Writes a PNG (and with --reference the "
        "ray-cast reference and the PSNR).");
    add_parameter(*cmd, kVolumeDoc, options.volumes);
    add_parameter(*cmd, kTfDoc, options.tfs);
    add_parameter(*cmd, kDepthDoc, options.depth_sampling);
    add_parameter(*cmd, kAzimuthDoc, options.azimuth_deg);
    add_parameter(*cmd, kElevationDoc, options.elevation_deg);
    add_parameter(*cmd, kDistanceDoc, options.distance_mm);
    add_parameter(*cmd, kFovDoc, options.fov_deg);
    add_parameter(*cmd, kWidthDoc, options.width);
    add_parameter(*cmd, kHeightDoc, options.height);
    add_parameter(*cmd, kRepetitionsDoc, options.repetitions);
    add_parameter(*cmd, kSubpixelDoc, options.subpixel);
    add_parameter(*cmd, kRadiusDoc, options.radius_scale);
    add_parameter(*cmd, kSamplingDoc, options.sampling);
    add_parameter(*cmd, kShadingDoc, options.shading);
    add_parameter(*cmd, kBackgroundDoc, options.background);
    add_parameter(*cmd, kCutDoc, options.cut_away);
    add_parameter(*cmd, kTimeLimitDoc, options.time_limit_s);
    add_parameter(*cmd, kSeedDoc, options.seed);
    add_parameter(*cmd, kFrameDoc, options.frame);
    cmd->add_flag(kSectorDoc.flag, options.sector, kSectorDoc.description);
    add_parameter(*cmd, kSectorTfDoc, options.sector_tf);
    add_parameter(*cmd, kReferenceDoc, options.reference);
    add_parameter(*cmd, kReferenceStepDoc, options.reference_step_mm);
    add_parameter(*cmd, kRendererDoc, options.renderer);
    add_parameter(*cmd, kOutDoc, options.out);
    add_run_options(*cmd, options.json_path, options.threads, options.quiet);
    return cmd;
}

int run_render_command(const RenderOptions& options) {
    StageTimer timer(options.quiet);
    const auto thread_limit = limit_threads(options.threads);

    // ---- parameters, validated before any heavy work ----
    pbvr::RenderSettings settings;
    settings.repetitions = options.repetitions;
    settings.subpixel_level = options.subpixel;
    settings.radius_scale = options.radius_scale;
    settings.seed = options.seed;
    if (options.sampling == "uniform")
        settings.sampling = pbvr::Sampling::uniform;
    else if (options.sampling == "metropolis")
        settings.sampling = pbvr::Sampling::metropolis;
    else
        throw base::InputError("--sampling", "", "must be 'uniform' or 'metropolis'");
    if (options.shading == "none")
        settings.shading.model = pbvr::Shading::Model::none;
    else if (options.shading == "lambert")
        settings.shading.model = pbvr::Shading::Model::lambert;
    else if (options.shading == "blinn-phong")
        settings.shading.model = pbvr::Shading::Model::blinn_phong;
    else
        throw base::InputError("--shading", "", "must be 'none', 'lambert' or 'blinn-phong'");
    const auto bg = parse_numbers(options.background, "--background", 3);
    settings.background = glm::vec3(bg[0], bg[1], bg[2]);
    base::require_in_range("--time-limit", "", options.time_limit_s, 0.0, 1e6, "s");
    settings.validate();
    if (options.renderer != "cpu" && options.renderer != "gpu")
        throw base::InputError("--renderer", "", "must be 'cpu' or 'gpu'");
#ifndef SONOTRACE_HAVE_GL_PBVR
    if (options.renderer == "gpu")
        throw base::InputError("--renderer", "",
                               "gpu: this build has no OpenGL renderer (install libgl-dev and "
                               "libegl-dev, or run scripts/setup.sh, and rebuild)");
#endif
    const std::filesystem::path out_path(options.out);
    if (out_path.extension() != ".png")
        throw base::InputError("--out", "", "must name a .png file, got '" + options.out + "'");

    pbvr::DepthSampling depth_sampling = pbvr::DepthSampling::cdf;
    {
        bool known = false;
        for (const auto d :
             {pbvr::DepthSampling::cdf, pbvr::DepthSampling::entry, pbvr::DepthSampling::middle,
              pbvr::DepthSampling::exit, pbvr::DepthSampling::random})
            if (options.depth_sampling == pbvr::to_string(d)) depth_sampling = d, known = true;
        if (!known)
            throw base::InputError("--depth-sampling", "",
                                   "must be cdf, entry, middle, exit or random");
    }
    {  // the camera's own parameters, before anything is loaded (the distance may be "fit")
        pbvr::OrbitCamera check;
        check.azimuth_deg = options.azimuth_deg, check.elevation_deg = options.elevation_deg;
        check.fov_deg = options.fov_deg, check.width = options.width, check.height = options.height;
        check.distance_mm = options.distance_mm > 0.0 ? options.distance_mm : 1.0;
        base::require_in_range("--distance", "", options.distance_mm, 0.0, 1e6, "mm");
        check.validate();
        // Each option may be in range while their product is not: the sub-pixel grid holds a
        // depth entry, an overlay entry and a reference sample per sub-pixel (8 bytes each).
        const double subpixels = double(options.width) * double(options.height) *
                                 double(options.subpixel) * double(options.subpixel);
        base::check_allocation(subpixels * 24.0, "--width x --height x --subpixel^2", "");
    }
    // The GPU path draws the particles and mesh fragments the CPU renderer generates
    // (PbvrRenderer::splats). Its context is opened before anything is loaded: a machine
    // without OpenGL fails at once.
#ifdef SONOTRACE_HAVE_GL_PBVR
    std::unique_ptr<gl::HeadlessGl> gl;
    std::unique_ptr<gl::GlPbvr> gpu;
    if (options.renderer == "gpu") {
        timer.begin("opening an OpenGL context (EGL)");
        try {
            gl = std::make_unique<gl::HeadlessGl>();
            gpu = std::make_unique<gl::GlPbvr>(options.width, options.height,
                                               settings.subpixel_level, settings.background);
        } catch (const std::runtime_error& e) {
            throw base::InputError("--renderer", "",
                                   std::string("gpu: ") + e.what() + "; --renderer cpu needs none");
        }
        timer.end();
        if (!options.quiet)
            std::fprintf(stderr, "sonotrace: OpenGL renderer: %s\n", gl->renderer().c_str());
    }
#endif
    if (options.sector && options.frame.empty())
        throw base::InputError("--sector", "", "needs --frame (the frame whose sector to mesh)");
    if (options.volumes.empty()) throw base::InputError("--volume", "", "needs a volume");
    if (options.tfs.size() != options.volumes.size())
        throw base::InputError("--tf", "",
                               "give one transfer function per --volume (" +
                                   std::to_string(options.volumes.size()) + " volumes, " +
                                   std::to_string(options.tfs.size()) + " transfer functions)");

    // ---- the inputs: one regular volume for particles, meshes for the rest ----
    std::optional<tissue::LoadedVolume> loaded;
    std::optional<pbvr::ColourTransferFunction> tf;
    std::string tf_name;
    std::vector<std::unique_ptr<pbvr::TetMesh>> meshes;
    std::vector<std::unique_ptr<pbvr::ColourTransferFunction>> mesh_tfs;
    json inputs = json::array();
    for (std::size_t v = 0; v < options.volumes.size(); ++v) {
        const std::string& spec = options.volumes[v];
        timer.begin("loading " + spec);
        auto volume_tf = pbvr::load_colour_tf(options.tfs[v]);
        const bool is_mesh = std::filesystem::path(spec).extension() == ".vtk";
        if (!is_mesh && !loaded) {
            loaded = tissue::load_volume({spec, std::nullopt});
            loaded->volume.require_finite(loaded->path);
            volume_tf.bind(loaded->volume);
            tf = volume_tf;
            tf_name = options.tfs[v];
            inputs.push_back({{"volume", loaded->path},
                              {"rendered_as", "particles (O-PBVR)"},
                              {"transfer_function", volume_tf.describe()}});
        } else {
            auto mesh = std::make_unique<pbvr::TetMesh>();
            if (is_mesh) {
                *mesh = pbvr::read_vtk_unstructured(spec);
            } else {
                const auto other = tissue::load_volume({spec, std::nullopt});
                other.volume.require_finite(other.path);
                *mesh = pbvr::tetrahedralize(other.volume);
            }
            volume_tf.bind(mesh->values_as_volume());
            inputs.push_back({{"volume", spec},
                              {"rendered_as", "tetrahedra (I-PBVR)"},
                              {"tetrahedra", mesh->tets.size()},
                              {"transfer_function", volume_tf.describe()}});
            meshes.push_back(std::move(mesh));
            mesh_tfs.push_back(std::make_unique<pbvr::ColourTransferFunction>(volume_tf));
        }
        timer.end();
    }
    // The view fits the regular volume, else the meshes' bounding box.
    tissue::VolumeGeometry g;
    if (loaded) {
        g = loaded->volume.geometry();
    } else {
        glm::dvec3 low(1e300), high(-1e300);
        for (const auto& m : meshes)
            for (const auto& p : m->points) low = glm::min(low, p), high = glm::max(high, p);
        g.dims = {11, 11, 11};
        g.origin = low;
        g.spacing = glm::max((high - low) / 10.0, glm::dvec3(1e-6));
    }
    pbvr::OrbitCamera camera = pbvr::fit_camera(g, options.azimuth_deg, options.elevation_deg,
                                                options.fov_deg, options.width, options.height);
    if (options.distance_mm > 0.0) camera.distance_mm = options.distance_mm;
    camera.validate();

    std::optional<pbvr::FrameOverlay> overlay;
    if (!options.frame.empty()) {
        timer.begin("loading frame " + options.frame);
        overlay = pbvr::load_frame_overlay(options.frame);
        timer.end();
    }
    if (overlay && options.sector) {
        overlay->draw_frame = false;  // the sector mesh shows the frame's values
        timer.begin("meshing the frame's sector");
        auto mesh = std::make_unique<pbvr::TetMesh>(pbvr::sector_mesh(*overlay));
        auto sector_tf = pbvr::load_colour_tf(options.sector_tf);
        sector_tf.bind(mesh->values_as_volume());
        inputs.push_back({{"volume", options.frame + " (sector)"},
                          {"rendered_as", "tetrahedra (I-PBVR)"},
                          {"tetrahedra", mesh->tets.size()},
                          {"transfer_function", sector_tf.describe()}});
        meshes.push_back(std::move(mesh));
        mesh_tfs.push_back(std::make_unique<pbvr::ColourTransferFunction>(sector_tf));
        timer.end();
    }
    if (overlay && options.cut_away == "auto") {
        settings.clip_plane = pbvr::camera_side_of_plane(*overlay, g, camera);
    } else if (options.cut_away == "octant" || (options.cut_away == "auto" && tf_name == "head")) {
        settings.cut_away = pbvr::facing_octant(g, camera);
    } else if (options.cut_away != "auto" && options.cut_away != "none") {
        const auto v = parse_numbers(options.cut_away, "--cut-away", 6);
        settings.cut_away = pbvr::CutAway{glm::vec3(v[0], v[1], v[2]), glm::vec3(v[3], v[4], v[5])};
    }

    std::optional<pbvr::RenderVolume> volume;
    if (loaded) {
        timer.begin("preparing volume (normalized values)");
        volume.emplace(loaded->volume, *tf);
        timer.end();
    }
    timer.begin("finding occupied cells");
    auto renderer = volume ? std::make_unique<pbvr::PbvrRenderer>(*volume, *tf, camera, settings)
                           : std::make_unique<pbvr::PbvrRenderer>(camera, settings);
    for (std::size_t m = 0; m < meshes.size(); ++m)
        renderer->add_mesh(*meshes[m], *mesh_tfs[m], depth_sampling);
    if (overlay) {
        std::vector<uint64_t> layer =
            pbvr::overlay_layer(*overlay, camera, settings.subpixel_level);
#ifdef SONOTRACE_HAVE_GL_PBVR
        if (gpu) gpu->set_overlay(layer);  // the GPU draws the same surfaces
#endif
        renderer->set_overlay(std::move(layer));
    }
    timer.end();
    int repetitions_done = 0;
    uint64_t particles = 0;
    // One repetition on the chosen renderer; false if interrupted within it.
    auto add_repetition = [&]() -> bool {
#ifdef SONOTRACE_HAVE_GL_PBVR
        if (gpu) {
            // splats() stops early on a Ctrl-C (the renderer's cancel flag): such a list
            // is not a repetition.
            const std::vector<pbvr::Splat> splats = renderer->splats(uint32_t(repetitions_done));
            if (g_interrupted) return false;
            gpu->add_repetition(splats);
            particles += splats.size();
            ++repetitions_done;
            return true;
        }
#endif
        if (!renderer->add_repetition()) return false;
        particles = renderer->particles_drawn();
        repetitions_done = renderer->repetitions_done();
        return true;
    };
    auto ensemble_image = [&]() -> pbvr::RgbImage {
#ifdef SONOTRACE_HAVE_GL_PBVR
        if (gpu) return gpu->image();
#endif
        return renderer->image();
    };
    json warnings = json::array();
    if (volume && renderer->occupied_cells() == 0) {
        const std::string warning =
            "the transfer function makes every voxel transparent: the image is the background";
        warnings.push_back(warning);
        if (!options.quiet) std::cerr << "sonotrace: warning: " << warning << "\n";
    }

    // ---- progressive refinement ----
    g_interrupted = false;
    const auto previous_handler = std::signal(SIGINT, on_interrupt);
    // Said once the handler is in place: from here on, Ctrl-C keeps the work done.
    if (!options.quiet)
        std::fprintf(stderr,
                     "sonotrace: rendering up to %d repetitions; Ctrl-C stops and writes the "
                     "image of the repetitions done\n",
                     settings.repetitions);
    const auto start = std::chrono::steady_clock::now();
    ProgressBar bar("rendering", options.quiet);
    std::vector<double> repetition_ms;
    std::string stopped_by = "repetitions";
    renderer->set_cancel(&g_interrupted);
    for (int r = 0; r < settings.repetitions; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        if (!add_repetition()) {
            stopped_by = "interrupt";
            break;
        }
        const auto t1 = std::chrono::steady_clock::now();
        repetition_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        bar.update(std::size_t(r + 1), std::size_t(settings.repetitions));
        if (g_interrupted) {
            stopped_by = "interrupt";
            break;
        }
        if (options.time_limit_s > 0.0 &&
            std::chrono::duration<double>(t1 - start).count() >= options.time_limit_s) {
            stopped_by = "time limit";
            break;
        }
    }
    bar.finish();
    std::signal(SIGINT, previous_handler);
    if (repetitions_done == 0) {
        // An interrupt, not bad input: the status says so (130, as every command's).
        if (!options.quiet)
            std::cerr << "sonotrace: interrupted before a repetition finished: nothing written\n";
        return 130;
    }
    const double render_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const pbvr::RgbImage image = ensemble_image();
#ifdef SONOTRACE_HAVE_GL_PBVR
    if (gpu && gpu->clipped() > 0) {
        const std::string warning =
            std::to_string(gpu->clipped()) +
            " particles' discs reached beyond the GPU framebuffer's margin and were partly lost";
        warnings.push_back(warning);
        if (!options.quiet) std::cerr << "sonotrace: warning: " << warning << "\n";
    }
#endif

    json record = {
        {"version", SONOTRACE_VERSION},
        {"inputs", inputs},
        {"depth_sampling", options.depth_sampling},
        {"camera",
         {{"target_mm", {camera.target.x, camera.target.y, camera.target.z}},
          {"distance_mm", camera.distance_mm},
          {"azimuth_deg", camera.azimuth_deg},
          {"elevation_deg", camera.elevation_deg},
          {"fov_deg", camera.fov_deg},
          {"width", camera.width},
          {"height", camera.height}}},
        {"seed", settings.seed},
        {"sampling", options.sampling},
        {"shading", options.shading},
        {"subpixel_level", settings.subpixel_level},
        {"particle_radius_mm", renderer->particle_radius_mm()},
        {"occupied_cells", renderer->occupied_cells()},
        {"renderer", options.renderer},
        {"repetitions", repetitions_done},
        {"stopped_by", stopped_by},
        {"particles_per_repetition", double(particles) / repetitions_done},
        {"render_s", render_s},
        {"warnings", warnings},
    };
    if (settings.cut_away)
        record["cut_away_mm"] = {settings.cut_away->low.x,  settings.cut_away->low.y,
                                 settings.cut_away->low.z,  settings.cut_away->high.x,
                                 settings.cut_away->high.y, settings.cut_away->high.z};
    if (overlay) record["frame"] = options.frame;
#ifdef SONOTRACE_HAVE_GL_PBVR
    if (gl) record["gl_renderer"] = gl->renderer() + ", OpenGL " + gl->version();
#endif
    if (!repetition_ms.empty()) {
        std::vector<double> sorted = repetition_ms;
        std::sort(sorted.begin(), sorted.end());
        record["ms_per_repetition_median"] = sorted[sorted.size() / 2];
    }

    base::OutputTransaction transaction;
    imaging::write_png(pbvr::to_picture(image), transaction.stage(options.out));
    if (!options.reference.empty()) {
        timer.begin("ray-casting the reference");
        std::vector<std::pair<const pbvr::TetMesh*, const pbvr::ColourTransferFunction*>> fused;
        for (std::size_t m = 0; m < meshes.size(); ++m)
            fused.push_back({meshes[m].get(), mesh_tfs[m].get()});
        const pbvr::RgbImage reference =
            pbvr::raycast_fused(volume ? &*volume : nullptr, volume ? &*tf : nullptr, fused, camera,
                                settings, options.reference_step_mm);
        timer.end();
        const double db = pbvr::psnr(image, reference);
        record["reference"] = {
            {"file", options.reference}, {"step_mm", options.reference_step_mm}, {"psnr_db", db}};
        if (!options.quiet) std::cerr << "sonotrace: PSNR against the reference: " << db << " dB\n";
        imaging::write_png(pbvr::to_picture(reference), transaction.stage(options.reference));
    }
    record["timings_s"] = timer.timings();
    if (!options.json_path.empty() && options.json_path != "-")
        write_json(record, transaction.stage(options.json_path));
    transaction.commit();
    if (options.json_path == "-") write_json(record, "-");
    if (!options.quiet) std::cerr << "sonotrace: wrote " << options.out << "\n";
    return 0;
}

}  // namespace sonotrace::ui
