// Particle-based volume rendering of the Colin27 head preset at 512 x 512: milliseconds
// per repetition, time to reach 30 and 35 dB PSNR against the ray-cast reference, peak
// memory. Prints one JSON record per configuration (a bench command, not Google
// Benchmark: the quantity is a time-to-quality, measured once per configuration).
//
//   build/bench/bench_pbvr [max_repetitions]
//   build/bench/bench_pbvr tetra      # image-space PBVR of tetrahedra: tetrahedra per second
//   build/bench/bench_pbvr fusion out/bmode.json [max_repetitions]   # head + sector
//   build/bench/bench_pbvr repetitions [count]   # the default settings: ms per repetition
//                                                # only (no reference; for A/B of changes)
//   build/bench/bench_pbvr noise [seeds]   # one repetition's error split into noise and
//                                          # bias, and how concentrated the noise is
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "imaging/pbvr/overlay.h"
#include "imaging/pbvr/pbvr.h"
#include "tissue/base/memory.h"
#include "tissue/volume_io.h"

namespace {

using namespace sonotrace;
using namespace sonotrace::imaging::pbvr;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

double peak_rss_mb() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return double(usage.ru_maxrss) / 1024.0;
}

}  // namespace

// Image-space PBVR throughput: a Colin27 brick split into tetrahedra, at 512 x 512.
void bench_tetrahedra(const tissue::Volume& head, int side) {
    const glm::ivec3 low = head.dims() / 2 - side / 2;
    const TetMesh mesh = tetrahedralize(head, low, low + side);
    ColourTransferFunction tf = load_colour_tf("head");
    tf.bind(head);
    tissue::VolumeGeometry box = head.geometry();
    box.origin = head.geometry().index_to_world(glm::dvec3(low));
    box.dims = glm::ivec3(side + 1);
    const OrbitCamera camera = fit_camera(box, kHeadAzimuthDeg, kHeadElevationDeg, 30.0, 512, 512);
    // The ray integral the CDF depth converges to, at a tenth of a voxel.
    const RgbImage reference =
        raycast_meshes({{&mesh, &tf}}, camera, RenderSettings{}, 0.1 * head.geometry().spacing.x);
    for (const DepthSampling depth : {DepthSampling::cdf, DepthSampling::middle}) {
        RenderSettings settings;
        PbvrRenderer renderer(camera, settings);
        renderer.add_mesh(mesh, tf, depth);
        std::vector<double> ms;
        // Repetitions until 35 dB against the ray integral (the CDF depth; at most 64).
        int to_30 = 0, to_35 = 0;
        for (int r = 1; r <= 64; ++r) {
            const auto t = Clock::now();
            renderer.add_repetition();
            ms.push_back(1e3 * seconds_since(t));
            if (depth != DepthSampling::cdf) {
                if (r == 5) break;
                continue;
            }
            const double db = psnr(renderer.image(), reference);  // not timed
            if (db >= 30.0 && to_30 == 0) to_30 = r;
            if (db >= 35.0) {
                to_35 = r;
                break;
            }
        }
        std::sort(ms.begin(), ms.end());
        const double median = ms[ms.size() / 2];
        nlohmann::json line{{"tetrahedra", mesh.tets.size()},
                            {"brick_voxels", side},
                            {"image", "512x512, 2x2 sub-pixels"},
                            {"depth_sampling", to_string(depth)},
                            {"ms_per_repetition_median", median},
                            {"tetrahedra_per_s", double(mesh.tets.size()) / (1e-3 * median)},
                            {"peak_rss_mb", peak_rss_mb()}};
        if (depth == DepthSampling::cdf)
            line["repetitions_to_30_35_db"] = {to_30, to_35};  // 0: not within 64
        std::cout << line.dump() << std::endl;
    }
}

// The product's fusion: the head's particles and the sector of a simulated frame as
// tetrahedra, at 512 x 512, against the fused reference.
void bench_fusion(const std::string& sidecar, int max_repetitions) {
    const tissue::Volume head =
        tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt}).volume;
    ColourTransferFunction tf = load_colour_tf("head");
    tf.bind(head);
    const RenderVolume volume(head, tf);
    FrameOverlay overlay = load_frame_overlay(sidecar);
    overlay.draw_frame = false;
    const TetMesh sector = sector_mesh(overlay);
    ColourTransferFunction sector_tf = load_colour_tf("bmode");
    sector_tf.bind(sector.values_as_volume());
    const OrbitCamera camera = fit_camera(head.geometry(), 200.0, 15.0, 30.0, 512, 512);
    RenderSettings settings;
    settings.clip_plane = camera_side_of_plane(overlay, head.geometry(), camera);
    auto t = Clock::now();
    const RgbImage reference =
        raycast_fused(&volume, &tf, {{&sector, &sector_tf}}, camera, settings, 0.25);
    const double reference_s = seconds_since(t);
    t = Clock::now();
    PbvrRenderer renderer(volume, tf, camera, settings);
    renderer.add_mesh(sector, sector_tf, DepthSampling::cdf);
    double rendering_s = seconds_since(t), to_30 = -1.0, to_35 = -1.0, db = 0.0;
    std::vector<double> ms;
    for (int r = 1; r <= max_repetitions && to_35 < 0.0; ++r) {
        t = Clock::now();
        renderer.add_repetition();
        ms.push_back(1e3 * seconds_since(t));
        rendering_s += ms.back() * 1e-3;
        db = psnr(renderer.image(), reference);
        if (to_30 < 0.0 && db >= 30.0) to_30 = rendering_s;
        if (to_35 < 0.0 && db >= 35.0) to_35 = rendering_s;
    }
    std::sort(ms.begin(), ms.end());
    std::cout << nlohmann::json{{"fusion", "head particles + sector tetrahedra"},
                                {"sector_tetrahedra", sector.tets.size()},
                                {"image", "512x512, 2x2 sub-pixels"},
                                {"ms_per_repetition_median", ms[ms.size() / 2]},
                                {"repetitions", ms.size()},
                                {"s_to_30_db", to_30},
                                {"s_to_35_db", to_35},
                                {"final_psnr_db", db},
                                {"reference_s", reference_s},
                                {"peak_rss_mb", peak_rss_mb()}}
                     .dump()
              << std::endl;
}

// Where one repetition's error lies, from `seeds` independent one-repetition images of
// the head preset (different seeds) against the ray-cast reference: the per-pixel
// variance (the noise the ensemble averages away: MSE after N repetitions ~ noise / N +
// bias^2 for independent repetitions) and the bias of the ensemble's limit. Also what
// adaptive sampling could gain: with n_t repetitions in image tile t at a cost
// proportional to its pixels, the optimal split costs (sum_t sqrt(V_t P_t))^2 / (P V)
// of uniform repetitions for the same MSE (V_t: tile t's summed variance, P_t: its pixels
// with non-zero variance; P, V: the totals).
void bench_noise(const RenderVolume& volume, const ColourTransferFunction& tf,
                 const OrbitCamera& camera, const RenderSettings& defaults, int seeds) {
    RenderSettings settings = defaults;
    const RgbImage reference = raycast(volume, tf, camera, settings, 0.25);
    const std::size_t pixels = reference.pixels.size();
    std::vector<glm::dvec3> sum(pixels, glm::dvec3(0.0));
    std::vector<double> sum_squares(pixels, 0.0);
    for (int k = 0; k < seeds; ++k) {
        settings.seed = 1000 + uint64_t(k);
        PbvrRenderer renderer(volume, tf, camera, settings);
        renderer.add_repetition();
        const RgbImage image = renderer.image();
        for (std::size_t p = 0; p < pixels; ++p) {
            const glm::dvec3 v = glm::clamp(glm::dvec3(image.pixels[p]), 0.0, 1.0);  // as psnr()
            sum[p] += v;
            sum_squares[p] += glm::dot(v, v);
        }
    }
    // per pixel, mean over the three channels
    std::vector<double> variance(pixels);
    double noise = 0.0, squared_error_of_mean = 0.0;
    std::size_t noisy_pixels = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const glm::dvec3 mean = sum[p] / double(seeds);
        variance[p] = std::max(
            0.0, (sum_squares[p] - double(seeds) * glm::dot(mean, mean)) / double(seeds - 1) / 3.0);
        const glm::dvec3 d = mean - glm::clamp(glm::dvec3(reference.pixels[p]), 0.0, 1.0);
        squared_error_of_mean += glm::dot(d, d) / 3.0;
        noise += variance[p];
        noisy_pixels += variance[p] > 0.0;
    }
    noise /= double(pixels);
    // E[(mean - reference)^2] = bias^2 + noise / seeds
    const double bias_squared = squared_error_of_mean / double(pixels) - noise / double(seeds);
    std::vector<double> sorted = variance;
    std::sort(sorted.begin(), sorted.end(), std::greater<>());
    nlohmann::json shares = nlohmann::json::object();
    for (const double share : {0.5, 0.8, 0.9}) {
        double running = 0.0;
        std::size_t n = 0;
        while (n < sorted.size() && running < share * noise * double(pixels))
            running += sorted[n++];
        shares[std::to_string(int(share * 100)) + "%"] = double(n) / double(noisy_pixels);
    }
    nlohmann::json adaptive = nlohmann::json::object();
    for (const int tile : {1, 8, 32}) {
        const int tiles_x = (camera.width + tile - 1) / tile,
                  tiles_y = (camera.height + tile - 1) / tile;
        std::vector<double> tile_variance(std::size_t(tiles_x) * std::size_t(tiles_y), 0.0);
        std::vector<double> tile_pixels(tile_variance.size(), 0.0);
        for (int y = 0; y < camera.height; ++y)
            for (int x = 0; x < camera.width; ++x) {
                const std::size_t p = std::size_t(y) * std::size_t(camera.width) + std::size_t(x);
                const std::size_t t =
                    std::size_t(y / tile) * std::size_t(tiles_x) + std::size_t(x / tile);
                tile_variance[t] += variance[p];
                tile_pixels[t] += variance[p] > 0.0 ? 1.0 : 0.0;
            }
        double root_sum = 0.0;
        for (std::size_t t = 0; t < tile_variance.size(); ++t)
            root_sum += std::sqrt(tile_variance[t] * tile_pixels[t]);
        adaptive[std::to_string(tile) + "px"] =
            root_sum * root_sum / (double(noisy_pixels) * noise * double(pixels));
    }
    const double target_mse = std::pow(10.0, -3.5);  // 35 dB, peak 1
    std::cout
        << nlohmann::json{{"image", "512x512"},
                          {"seeds", seeds},
                          {"noise_per_repetition", noise},
                          {"psnr_one_repetition_db", -10.0 * std::log10(noise + bias_squared)},
                          {"bias_squared", bias_squared},
                          {"bias_psnr_db", -10.0 * std::log10(std::max(bias_squared, 1e-12))},
                          {"independent_repetitions_for_35_db",
                           bias_squared < target_mse ? noise / (target_mse - bias_squared) : -1.0},
                          {"pixels_with_noise", noisy_pixels},
                          {"share_of_noisy_pixels_holding", shares},
                          {"adaptive_cost_ratio_by_tile", adaptive}}
               .dump()
        << std::endl;
}

int main(int argc, char** argv) {
    base::keep_freed_memory();  // as the sonotrace program does
    if (argc > 2 && std::string(argv[1]) == "fusion") {
        bench_fusion(argv[2], argc > 3 ? std::atoi(argv[3]) : 64);
        return 0;
    }
    if (argc > 1 && std::string(argv[1]) == "tetra") {
        const tissue::Volume head =
            tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt}).volume;
        for (int side : {24, 48}) bench_tetrahedra(head, side);
        return 0;
    }
    const bool repetitions_only = argc > 1 && std::string(argv[1]) == "repetitions";
    const int max_repetitions = repetitions_only ? (argc > 2 ? std::atoi(argv[2]) : 16)
                                : argc > 1       ? std::atoi(argv[1])
                                                 : 48;
    auto t = Clock::now();
    const tissue::Volume head =
        tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt}).volume;
    ColourTransferFunction tf = load_colour_tf("head");
    tf.bind(head);
    const RenderVolume volume(head, tf);
    const double prepare_s = seconds_since(t);

    // The head preset's view, as `sonotrace render` sets it up.
    const OrbitCamera camera =
        fit_camera(head.geometry(), kHeadAzimuthDeg, kHeadElevationDeg, 30.0, 512, 512);
    const CutAway cut = facing_octant(head.geometry(), camera);

    struct Config {
        int subpixel;
        double radius_scale;
    };
    if (argc > 1 && std::string(argv[1]) == "noise") {
        RenderSettings settings;
        settings.cut_away = cut;
        bench_noise(volume, tf, camera, settings, argc > 2 ? std::max(2, std::atoi(argv[2])) : 16);
        return 0;
    }
    if (repetitions_only) {
        RenderSettings settings;
        settings.cut_away = cut;
        t = Clock::now();
        PbvrRenderer renderer(volume, tf, camera, settings);
        const double setup_s = seconds_since(t);
        std::vector<double> ms;
        for (int r = 0; r < max_repetitions; ++r) {
            t = Clock::now();
            renderer.add_repetition();
            ms.push_back(1e3 * seconds_since(t));
        }
        std::sort(ms.begin(), ms.end());
        std::cout << nlohmann::json{{"image", "512x512"},
                                    {"repetitions", max_repetitions},
                                    {"setup_s", setup_s},
                                    {"ms_per_repetition_median", ms[ms.size() / 2]},
                                    {"particles_per_repetition",
                                     double(renderer.particles_drawn()) / double(ms.size())}}
                         .dump()
                  << std::endl;
        return 0;
    }
    for (const Config config : {Config{2, 2.0}, Config{1, 1.0}, Config{2, 3.0}}) {
        RenderSettings settings;
        settings.subpixel_level = config.subpixel;
        settings.radius_scale = config.radius_scale;
        settings.cut_away = cut;
        t = Clock::now();
        const RgbImage reference = raycast(volume, tf, camera, settings, 0.25);
        const double reference_s = seconds_since(t);

        t = Clock::now();
        PbvrRenderer renderer(volume, tf, camera, settings);
        const double setup_s = seconds_since(t);
        double rendering_s = setup_s, to_30 = -1.0, to_35 = -1.0, db = 0.0;
        std::vector<double> ms;
        nlohmann::json curve = nlohmann::json::array();
        for (int r = 1; r <= max_repetitions && to_35 < 0.0; ++r) {
            t = Clock::now();
            renderer.add_repetition();
            const double s = seconds_since(t);
            ms.push_back(1e3 * s);
            rendering_s += s;
            db = psnr(renderer.image(), reference);  // not timed
            curve.push_back({{"repetitions", r}, {"s", rendering_s}, {"psnr_db", db}});
            if (to_30 < 0.0 && db >= 30.0) to_30 = rendering_s;
            if (to_35 < 0.0 && db >= 35.0) to_35 = rendering_s;
        }
        std::sort(ms.begin(), ms.end());
        const nlohmann::json record = {
            {"image", "512x512"},
            {"subpixel_level", config.subpixel},
            {"radius_scale", config.radius_scale},
            {"particle_radius_mm", renderer.particle_radius_mm()},
            {"cells_drawn", renderer.occupied_cells()},
            {"cells_culled", renderer.culled_cells()},
            {"bricks_skipped", renderer.skipped_bricks()},
            {"particles_per_repetition", double(renderer.particles_drawn()) / double(ms.size())},
            {"volume_prepare_s", prepare_s},
            {"renderer_setup_s", setup_s},
            {"ms_per_repetition_median", ms[ms.size() / 2]},
            {"s_to_30_db", to_30},
            {"s_to_35_db", to_35},
            {"final_psnr_db", db},
            {"reference_raycast_s", reference_s},
            {"peak_rss_mb", peak_rss_mb()},
            {"curve", curve},
        };
        std::cout << record.dump() << std::endl;
    }
    return 0;
}
