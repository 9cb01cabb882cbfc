// Particle-based volume rendering against closed forms: the transmittance of a homogeneous
// slab, convergence to the ray-cast reference, eq. 13's radius adaptation, thread
// independence, overlays and bad input. Particle counts and positions:
// test_pbvr_sampling.cpp.
#include <gtest/gtest.h>

#include <tbb/global_control.h>
#include <atomic>

#include <bit>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "imaging/pbvr/overlay.h"
#include "imaging/pbvr/pbvr.h"
#include "tests/imaging/pbvr_test_volumes.h"
#include "tests/test_util.h"
#include "tissue/base/error.h"

namespace sonotrace::imaging::pbvr {
namespace {

using test::chi_square;
using test::chi_square_critical_001;

// A slab 5 mm thick (y) of constant scalar, seen along +y through a narrow field of
// view: each pixel's expected value is 1 - exp(-sigma l) for the ray's path l in it.
struct SlabScene {
    tissue::Volume data = make_volume({41, 6, 41}, 1.0, [](int, int, int) { return 1.0f; });
    ColourTransferFunction tf{
        "white", "test", {{0.0, glm::vec3(1.0f), 0.3}, {1.0, glm::vec3(1.0f), 0.3}}, 1.0, 0.0, 1.0};
    OrbitCamera camera;
    RenderSettings settings;
    SlabScene() {
        tf.bind(data);
        camera.target = {20.0, 2.5, 20.0};
        camera.distance_mm = 300.0;
        camera.fov_deg = 4.0;  // 21 mm across at the slab: inside its 40 mm
        camera.width = camera.height = 24;
        settings.shading.model = Shading::Model::none;
        // one sample per pixel and repetition: the statistics below assume it
        settings.subpixel_level = 1;
        settings.radius_scale = 1.0;
    }
    double expected(int x, int y) const {
        const double f = camera.focal_px();
        const glm::dvec3 dir =
            glm::normalize(camera.forward() + (x + 0.5 - 12.0) / f * camera.right() -
                           (y + 0.5 - 12.0) / f * camera.up());
        const double path = 5.0 / dir.y;  // between the faces y = 0 and y = 5
        const double sigma = -std::log(1.0 - 0.3);
        return 1.0 - std::exp(-sigma * path);
    }
};

TEST(Pbvr, HomogeneousSlabConvergesToTheAnalyticTransmittance) {
    const SlabScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    PbvrRenderer renderer(volume, scene.tf, scene.camera, scene.settings);
    auto errors = [&] {
        const RgbImage image = renderer.image();
        double mean_error = 0.0, squared = 0.0;
        for (int y = 0; y < 24; ++y)
            for (int x = 0; x < 24; ++x) {
                const double d = image.at(x, y).x - scene.expected(x, y);
                mean_error += d, squared += d * d;
            }
        return std::pair{mean_error / 576.0, std::sqrt(squared / 576.0)};
    };
    for (int r = 0; r < 16; ++r) renderer.add_repetition();
    const auto [bias16, rmse16] = errors();
    for (int r = 16; r < 256; ++r) renderer.add_repetition();
    const auto [bias256, rmse256] = errors();
    // Each pixel sample is white with probability p = 1 - exp(-sigma l) ~ 0.83, else black:
    // the standard error of the image mean over 576 pixels x 256 repetitions is
    // sqrt(p (1 - p) / 147456) = 1e-3; 4 sigma.
    const double p = scene.expected(12, 12);
    EXPECT_NEAR(bias256, 0.0, 4.0 * std::sqrt(p * (1 - p) / (576.0 * 256.0)));
    // RMSE falls as 1/sqrt(N): 4x from 16 to 256 repetitions (3x allows for noise).
    EXPECT_LT(rmse256, rmse16 / 3.0);
    EXPECT_NEAR(rmse256, std::sqrt(p * (1 - p) / 256.0), 0.3 * std::sqrt(p * (1 - p) / 256.0));
    ::testing::Test::RecordProperty("bias_rmse_16_256",
                                    std::to_string(bias16) + " " + std::to_string(rmse16) + " " +
                                        std::to_string(bias256) + " " + std::to_string(rmse256));
}

// A cube 160 mm wide of constant extinction sigma (2 mm voxels), white, unshaded, seen
// along +y.
struct CubeScene {
    static constexpr double kSigma = 0.01;  // 1/mm
    tissue::Volume data = make_volume({81, 81, 81}, 2.0, [](int, int, int) { return 1.0f; });
    ColourTransferFunction tf{"white",
                              "test",
                              {{0.0, glm::vec3(1.0f), 1.0 - std::exp(-kSigma)},
                               {1.0, glm::vec3(1.0f), 1.0 - std::exp(-kSigma)}},
                              1.0,
                              0.0,
                              1.0};
    OrbitCamera camera;
    RenderSettings settings;
    CubeScene() {
        tf.bind(data);
        camera.target = {80.0, 80.0, 80.0};
        camera.width = camera.height = 64;
        settings.shading.model = Shading::Model::none;
        settings.occlusion_culling = false;
    }
};

// Each particle's radius is the sub-pixel footprint at its depth (times radius_scale /
// sqrt pi), so a repetition's particle count follows the image: per mm of depth inside
// the view, rho A(z) = sigma / (pi k^2 z^2) * A_subpixels z^2 / f^2 = sigma A / s^2
// (k = s / (f sqrt pi), s = radius_scale), whatever the camera's distance. Through the
// cube's 160 mm: sigma 160 A / s^2, A the sub-pixel area where a disc of radius
// s / sqrt(pi) reaches a sub-pixel centre. With one radius for all, set at the target,
// the count grew as the camera came nearer (x1.15 here, 1/distance^2 for far cells).
TEST(Pbvr, ParticleCountFollowsTheImageNotTheCameraDistance) {
    CubeScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    const int L = scene.settings.subpixel_level;
    const double s = scene.settings.radius_scale, disc = s / std::sqrt(std::numbers::pi);
    // A disc reaches the image's edge row of centres from outside by sqrt(disc^2 - t^2),
    // t uniform over the half spacing 0..0.5 between centres: the mean, by midpoints.
    double reach = 0.0;
    for (int i = 0; i < 1000; ++i) {
        const double t = 0.5 * (i + 0.5) / 1000.0;
        reach += std::sqrt(disc * disc - t * t) / 1000.0;
    }
    const double side = double(scene.camera.width * L) - 1.0 + 2.0 * reach;
    const double expected = CubeScene::kSigma * 160.0 * side * side / (s * s);
    // The view stays inside the cube: at the far face (distance + 80 mm) the half-width is
    // (distance + 80) tan 15 deg <= 80 mm for distances up to 218 mm.
    constexpr int kRepetitions = 8;
    std::vector<double> counts;
    for (const double distance : {100.0, 200.0}) {
        scene.camera.distance_mm = distance;
        PbvrRenderer renderer(volume, scene.tf, scene.camera, scene.settings);
        for (int r = 0; r < kRepetitions; ++r) renderer.add_repetition();
        counts.push_back(double(renderer.particles_drawn()) / kRepetitions);
        // Poisson: the standard error of 8 repetitions' mean is 0.43 % of ~6.7k; 2 % allows
        // for the discs' depth within a cell (+-5 % near the face at 20 mm, at the rim only).
        EXPECT_NEAR(counts.back(), expected, 0.02 * expected) << "distance " << distance;
    }
    EXPECT_NEAR(counts[1] / counts[0], 1.0, 0.02);
}

// The eye inside the medium: cells around and behind it are culled as off the image
// (the projected disc cannot tell there), those in front kept with the radius of their
// depth, and each pixel converges to 1 - exp(-sigma l), l the ray's path to the far face.
TEST(Pbvr, AnEyeInsideTheVolumeSeesTheAnalyticFog) {
    CubeScene scene;
    scene.settings.subpixel_level = 1;  // one Bernoulli sample per pixel and repetition
    scene.settings.radius_scale = 1.0;
    scene.settings.occlusion_culling = true;
    scene.camera.target = {80.0, 120.0, 80.0};
    scene.camera.distance_mm = 40.0;  // the eye at the cube's centre, looking along +y
    scene.camera.width = scene.camera.height = 24;
    const RenderVolume volume(scene.data, scene.tf);
    PbvrRenderer renderer(volume, scene.tf, scene.camera, scene.settings);
    EXPECT_GT(renderer.culled_cells(), std::size_t(80 * 80 * 40))  // at least those behind
        << "kept " << renderer.occupied_cells();
    constexpr int kRepetitions = 256;
    for (int r = 0; r < kRepetitions; ++r) renderer.add_repetition();
    const RgbImage image = renderer.image();
    const double f = scene.camera.focal_px();
    double mean_error = 0.0, variance = 0.0;
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) {
            const glm::dvec3 dir = glm::normalize(scene.camera.forward() +
                                                  (x + 0.5 - 12.0) / f * scene.camera.right() -
                                                  (y + 0.5 - 12.0) / f * scene.camera.up());
            const double p = 1.0 - std::exp(-CubeScene::kSigma * 80.0 / dir.y);
            mean_error += (image.at(x, y).x - p) / 576.0;
            variance += p * (1.0 - p) / (576.0 * 576.0 * kRepetitions);
        }
    // The image mean's standard error for independent repetitions (stratified ones are
    // closer): 4 sigma.
    EXPECT_NEAR(mean_error, 0.0, 4.0 * std::sqrt(variance));
}

// A smooth blob with shading, the scene of the reference and eq. 13 tests.
struct BlobScene {
    tissue::Volume data = make_volume({48, 48, 48}, 1.0, [](int i, int j, int k) {
        const double r = glm::length(glm::dvec3(i, j, k) - 23.5) / 20.0;
        return float(
            std::clamp(1.0 - r * r + 0.1 * std::sin(i * 0.4) * std::cos(k * 0.3), 0.0, 1.0));
    });
    ColourTransferFunction tf{"blob",
                              "test",
                              {{0.0, {0.2f, 0.3f, 0.8f}, 0.0},
                               {0.4, {0.9f, 0.5f, 0.2f}, 0.08},
                               {1.0, {1.0f, 1.0f, 0.9f}, 0.3}},
                              1.0,
                              0.0,
                              1.0};
    OrbitCamera camera;
    RenderSettings settings;
    BlobScene() {
        tf.bind(data);
        camera.target = {23.5, 23.5, 23.5};
        camera.distance_mm = 160.0;
        camera.azimuth_deg = 30.0;
        camera.elevation_deg = 20.0;
        camera.width = camera.height = 96;
        settings.subpixel_level = 1;  // the PSNR figures in the comments are for these
        settings.radius_scale = 1.0;
    }
};

// A raised cancel flag (render's Ctrl-C) is seen inside a repetition: it returns false and
// leaves the ensemble as it was; lowered again, rendering goes on as if nothing happened.
TEST(Pbvr, ACancelledRepetitionLeavesTheEnsembleUnchanged) {
    const BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    PbvrRenderer renderer(volume, scene.tf, scene.camera, scene.settings);
    PbvrRenderer uncancelled(volume, scene.tf, scene.camera, scene.settings);
    ASSERT_TRUE(renderer.add_repetition());
    ASSERT_TRUE(uncancelled.add_repetition());
    const RgbImage before = renderer.image();
    std::atomic<bool> cancel{true};
    renderer.set_cancel(&cancel);
    EXPECT_FALSE(renderer.add_repetition());
    EXPECT_EQ(renderer.repetitions_done(), 1);
    EXPECT_EQ(renderer.image().pixels, before.pixels);
    cancel = false;
    EXPECT_TRUE(renderer.add_repetition());
    EXPECT_TRUE(uncancelled.add_repetition());
    EXPECT_EQ(renderer.image().pixels, uncancelled.image().pixels);
}

TEST(Pbvr, PsnrAgainstTheRayCasterRisesWithRepetitions) {
    const BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    const RgbImage reference = raycast(volume, scene.tf, scene.camera, scene.settings, 0.05);
    PbvrRenderer renderer(volume, scene.tf, scene.camera, scene.settings);
    std::vector<double> db;
    for (int r = 1; r <= 128; ++r) {
        renderer.add_repetition();
        if (r == 8 || r == 32 || r == 128) db.push_back(psnr(renderer.image(), reference));
    }
    // Noise power falls as 1/N: +6 dB per 4x repetitions while the bias (finite particle
    // radius against the ray caster's fine steps) stays below it. Each step must gain at
    // least 4.5 dB.
    EXPECT_GT(db[1], db[0] + 4.5) << db[0] << " " << db[1];
    EXPECT_GT(db[2], db[1] + 4.5) << db[1] << " " << db[2];
    EXPECT_GT(db[2], 35.0);
    ::testing::Test::RecordProperty(
        "psnr_8_32_128",
        std::to_string(db[0]) + " " + std::to_string(db[1]) + " " + std::to_string(db[2]));
}

// The repetitions of one seed are stratified across each other (CellSequence), so a short
// run's image is not an average of independent samples; it must still be an unbiased
// estimate of the converged image. 64 seeds of 2 repetitions each (short runs, drawn
// independently of each other) are averaged and compared, pixel by pixel and channel by
// channel, with one seed's 1024 repetitions: sum over samples of (mean of the short runs
// - long run)^2 / (its variance) must be chi-square with one degree of freedom per
// sample. The variance is that of the short runs' mean (their sample variance / 64)
// plus the long run's, bounded by 2 x that sample variance / 1024 as if its repetitions
// were independent (stratified ones vary less). Neighbouring pixels share particles, so
// the statistic's spread is wider than chi-square's (0.98-1.11 over four sets of short-run
// seeds); its mean is the test: within 25 % of 1 (a bias of one standard error per
// sample doubles it). The same statistic against
// the long run lifted by 0.01 must exceed 2: the test can fail.
TEST(Pbvr, ShortStratifiedRunsAverageToTheConvergedImage) {
    BlobScene scene;
    scene.camera.width = scene.camera.height = 48;
    const RenderVolume volume(scene.data, scene.tf);
    constexpr int kShortRuns = 64, kShortRepetitions = 2, kLongRepetitions = 1024;
    ImageEnsemble short_runs;
    for (int run = 0; run < kShortRuns; ++run) {
        RenderSettings settings = scene.settings;
        settings.seed = uint64_t(1000 + run);
        PbvrRenderer renderer(volume, scene.tf, scene.camera, settings);
        for (int r = 0; r < kShortRepetitions; ++r) renderer.add_repetition();
        short_runs.add(renderer.image());
    }
    PbvrRenderer long_run(volume, scene.tf, scene.camera, scene.settings);
    for (int r = 0; r < kLongRepetitions; ++r) long_run.add_repetition();
    const RgbImage converged = long_run.image();
    // The long run's variance, as if its repetitions were independent (background: every
    // short run the same).
    constexpr double kExtra = double(kShortRepetitions) / kLongRepetitions;
    const auto statistic = short_runs.against(converged, 0.0, kExtra, 1e-12);
    const double lifted = short_runs.against(converged, 0.01, kExtra, 1e-12).per_sample;
    EXPECT_GT(statistic.degrees, 1000) << "too few samples vary";
    std::printf("chi-square per sample: %.3f (lifted by 0.01: %.2f)\n", statistic.per_sample,
                lifted);
    EXPECT_NEAR(statistic.per_sample, 1.0, 0.25);
    EXPECT_GT(lifted, 2.0);
}

TEST(Pbvr, RadiusAdaptationMatchesRegenerationAfterAnOpacityEdit) {
    // Eq. 13: particles generated from the original opacity, drawn with radii adapted to
    // the edited one (extinction doubled), against particles regenerated from the edit.
    // Both estimate the same image: PSNR between them above 43 dB at 128 repetitions
    // (their noise alone, two independent 128-sample means, allows ~44.5 dB: 3 dB below
    // each one's ~47 dB against the reference), and each within 1 dB of the other
    // against the ray-cast reference of the edit. (Over seeds 1-5 the adapted image was
    // 0.06-0.52 dB below the regenerated one, mean 0.22, sd 0.18: its particles are
    // larger where the opacity rose, with more finite-radius bias; 1 dB is the mean
    // plus 4 sd.)
    const BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    const ColourTransferFunction edited = scene.tf.with_extinction_scaled(2.0);
    PbvrRenderer regenerated(volume, edited, scene.camera, scene.settings);
    PbvrRenderer adapted(volume, edited, scene.camera, scene.settings, &scene.tf);
    PbvrRenderer unadapted(volume, scene.tf, scene.camera, scene.settings);
    for (int r = 0; r < 128; ++r) {
        regenerated.add_repetition();
        adapted.add_repetition();
        if (r < 32) unadapted.add_repetition();
    }
    const RgbImage reference = raycast(volume, edited, scene.camera, scene.settings, 0.05);
    const double regenerated_db = psnr(regenerated.image(), reference);
    const double adapted_db = psnr(adapted.image(), reference);
    EXPECT_GT(psnr(adapted.image(), regenerated.image()), 43.0);
    EXPECT_NEAR(adapted_db, regenerated_db, 1.0);
    // The edit is visible: without adaptation the image is far from the edited reference.
    const double unadapted_db = psnr(unadapted.image(), reference);
    EXPECT_LT(unadapted_db, regenerated_db - 8.0);
    ::testing::Test::RecordProperty("psnr_regenerated_adapted_unadapted_between",
                                    std::to_string(regenerated_db) + " " +
                                        std::to_string(adapted_db) + " " +
                                        std::to_string(unadapted_db) + " " +
                                        std::to_string(psnr(adapted.image(), regenerated.image())));
    // Fewer particles were generated for the adapted image (the original density).
    EXPECT_LT(adapted.particles_drawn(), regenerated.particles_drawn());
}

TEST(Pbvr, ImagesAreByteIdenticalOnOneAndTwoThreads) {
    const BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    for (const Sampling sampling : {Sampling::uniform, Sampling::metropolis}) {
        RenderSettings settings = scene.settings;
        settings.sampling = sampling;
        settings.subpixel_level = 2;
        auto run = [&](int threads) {
            tbb::global_control c(tbb::global_control::max_allowed_parallelism,
                                  std::size_t(threads));
            PbvrRenderer renderer(volume, scene.tf, scene.camera, settings);
            for (int r = 0; r < 4; ++r) renderer.add_repetition();
            return renderer.image();
        };
        const RgbImage a = run(1), b = run(2);
        ASSERT_EQ(a.pixels.size(), b.pixels.size());
        EXPECT_EQ(
            std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(glm::vec3)), 0);
    }
}

// Brick culling is a bound: a brick is skipped only if each of its cells would be
// (transparent or hidden), so the cells drawn and the image stay the same, from cameras
// far, near (cells close to the eye), looking past the volume's edge (cells off the
// image), from above, and from inside the volume (cells behind the eye).
TEST(Pbvr, BrickCullingKeepsExactlyTheCellsThatCellCullingKeeps) {
    BlobScene scene;
    scene.tf = scene.tf.with_extinction_scaled(8.0);  // a dense blob hides its interior
    const RenderVolume volume(scene.data, scene.tf);
    struct View {
        double distance_mm, azimuth_deg, elevation_deg;
        glm::dvec3 target;
    };
    const View views[] = {{160.0, 30.0, 20.0, {23.5, 23.5, 23.5}},
                          {45.0, 120.0, 10.0, {23.5, 23.5, 23.5}},
                          {90.0, 200.0, -30.0, {45.0, 5.0, 23.5}},
                          {120.0, 300.0, 80.0, {23.5, 23.5, 23.5}},
                          {10.0, 60.0, 15.0, {23.5, 23.5, 23.5}}};  // the eye inside
    std::size_t skipped = 0;
    for (const View& view : views) {
        OrbitCamera camera = scene.camera;
        camera.distance_mm = view.distance_mm;
        camera.azimuth_deg = view.azimuth_deg;
        camera.elevation_deg = view.elevation_deg;
        camera.target = view.target;
        auto render = [&](bool bricks) {
            RenderSettings settings = scene.settings;
            settings.early_culling = bricks;
            PbvrRenderer renderer(volume, scene.tf, camera, settings);
            for (int r = 0; r < 2; ++r) renderer.add_repetition();
            return std::tuple{renderer.occupied_cells(), renderer.image(),
                              renderer.skipped_bricks()};
        };
        const auto [cells_with, image_with, bricks_with] = render(true);
        const auto [cells_without, image_without, bricks_without] = render(false);
        EXPECT_EQ(cells_with, cells_without) << "distance " << view.distance_mm;
        ASSERT_EQ(image_with.pixels.size(), image_without.pixels.size());
        EXPECT_EQ(std::memcmp(image_with.pixels.data(), image_without.pixels.data(),
                              image_with.pixels.size() * sizeof(glm::vec3)),
                  0)
            << "distance " << view.distance_mm;
        EXPECT_EQ(bricks_without, 0u);
        skipped += bricks_with;
    }
    EXPECT_GT(skipped, 0u);  // the bound is not vacuous here
}

// Cells that the cut-away or the clip plane removes whole are not kept (their particles
// were generated and dropped one by one): the same image to the bit, with and without,
// from a view that looks into the cut (a box over a corner of the blob) past a clip plane
// through it.
TEST(Pbvr, CellsRemovedWholeAreNotGeneratedAndTheImageStaysTheSame) {
    BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    OrbitCamera camera = scene.camera;
    camera.distance_mm = 90.0, camera.azimuth_deg = 30.0, camera.elevation_deg = 20.0;
    camera.target = {23.5, 23.5, 23.5};
    auto render = [&](bool early) {
        RenderSettings settings = scene.settings;
        settings.early_culling = early;
        settings.cut_away = CutAway{{20.0f, 20.0f, 20.0f}, {60.0f, 60.0f, 60.0f}};
        settings.clip_plane = glm::vec4(1.0f, 0.0f, 0.0f, -38.3f);  // x > 38.3 mm removed
        PbvrRenderer renderer(volume, scene.tf, camera, settings);
        for (int r = 0; r < 3; ++r) renderer.add_repetition();
        return std::tuple{renderer.occupied_cells(), renderer.removed_cells(), renderer.image(),
                          renderer.particles_drawn()};
    };
    const auto [cells_with, removed_with, image_with, drawn_with] = render(true);
    const auto [cells_without, removed_without, image_without, drawn_without] = render(false);
    EXPECT_GT(removed_with, 0u);
    EXPECT_EQ(removed_without, 0u);
    // Fewer cells kept; the removed ones include some that the occlusion map would have
    // culled as hidden.
    EXPECT_LT(cells_with, cells_without);
    EXPECT_GE(cells_with + removed_with, cells_without);
    EXPECT_EQ(drawn_with, drawn_without);
    ASSERT_EQ(image_with.pixels.size(), image_without.pixels.size());
    EXPECT_EQ(std::memcmp(image_with.pixels.data(), image_without.pixels.data(),
                          image_with.pixels.size() * sizeof(glm::vec3)),
              0);
}

TEST(Pbvr, SpecularPowerIsThePower) {
    for (const float shininess :
         {0.0f, 1.0f, 2.0f, 7.0f, 24.0f, 63.0f, 64.0f, 100.0f, 2.5f, 30.7f}) {
        for (const float facing : {1e-3f, 0.1f, 0.5f, 0.9f, 0.99f, 0.999f, 1.0f}) {
            const double expected = std::pow(double(facing), double(shininess));
            // Squaring: relative error below (n - 1) 2^-24 = 3.8e-6 for n <= 64; exp2/log2:
            // about |shininess log2 facing| ln 2 2^-24 (4e-6 at 0.1^30.7). 1e-5 covers both.
            EXPECT_NEAR(specular_power(facing, shininess), expected, 1e-5 * expected + 1e-30)
                << facing << "^" << shininess;
        }
    }
}

TEST(Pbvr, MetropolisConvergesToTheSameImage) {
    const BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    RenderSettings settings = scene.settings;
    settings.sampling = Sampling::metropolis;
    PbvrRenderer renderer(volume, scene.tf, scene.camera, settings);
    for (int r = 0; r < 64; ++r) renderer.add_repetition();
    // The Gauss-rule count is exact for densities cubic per axis; this one is smooth:
    // within 1.5 dB of thinning at 64 repetitions (43.4 dB: between its 40.5 dB at 32 and
    // 46.6 dB at 128 in the test above).
    const RgbImage reference = raycast(volume, scene.tf, scene.camera, scene.settings, 0.05);
    const double db = psnr(renderer.image(), reference);
    EXPECT_GT(db, 42.0);
    ::testing::Test::RecordProperty("psnr_metropolis_64", std::to_string(db));
}

// A linear probe's frame (uniform grey 200) in the plane y = 20 of a 41^3 volume, its
// face at z = 35 looking down -z; the camera looks along +y at the plane.
struct OverlayScene {
    tissue::Volume data = make_volume({41, 41, 41}, 1.0, [](int, int j, int) {
        return j < 10 ? 1.0f : 0.0f;  // an opaque slab in front of the plane (y < 10)
    });
    FrameOverlay overlay;
    OrbitCamera camera;
    OverlayScene() {
        overlay.transducer = probe::find_transducer("linear", "test");
        overlay.transducer.depth_mm = 20.0;
        overlay.frame = cv::Mat(100, 200, CV_8UC1, cv::Scalar(200));
        overlay.origin_mm = {-20.0, 0.0};
        overlay.pixel_mm = {0.2, 0.2};
        overlay.position = {20.0, 20.0, 35.0};
        overlay.axial = {0.0, 0.0, -1.0};
        overlay.lateral = {1.0, 0.0, 0.0};
        overlay.elevation = {0.0, 1.0, 0.0};
        camera.target = {20.0, 20.0, 25.0};
        camera.distance_mm = 200.0;
        camera.fov_deg = 20.0;
        camera.width = camera.height = 64;
    }
};

TEST(PbvrOverlay, TheFrameSitsOnItsPlaneAndIsDepthTestedAgainstParticles) {
    const OverlayScene scene;
    const std::vector<uint64_t> layer = overlay_layer(scene.overlay, scene.camera, 1);
    // The image centre looks at (20, 20, 25): 10 mm deep in the sector, on the plane.
    const uint64_t centre = layer[32 * 64 + 32];
    ASSERT_NE(centre, kEmptyEntry);
    EXPECT_NEAR(entry_colour(centre).x, 200.0f / 255.0f, 1e-6f);
    const float depth = std::bit_cast<float>(uint32_t(centre >> 32));
    // Camera depth (along the view axis) of a plane facing the camera: the eye is at
    // y = 20 - 200, the plane at y = 20.
    EXPECT_NEAR(depth, 200.0f, 1e-3f);
    // Beyond the sector's depth (z < 15) nothing is drawn: the image's bottom rows.
    EXPECT_EQ(layer[62 * 64 + 32], kEmptyEntry);

    // Transparent medium: the picture is the overlay. Opaque slab in front: hidden.
    RenderSettings settings;
    settings.subpixel_level = 1;
    for (const bool opaque : {false, true}) {
        ColourTransferFunction tf("slab", "test",
                                  {{0.0, glm::vec3(0.0f, 0.0f, 1.0f), 0.0},
                                   {1.0, glm::vec3(0.0f, 0.0f, 1.0f), opaque ? 0.99 : 0.0}},
                                  1.0, 0.0, 1.0);
        tf.bind(scene.data);
        const RenderVolume volume(scene.data, tf);
        PbvrRenderer renderer(volume, tf, scene.camera, settings);
        renderer.set_overlay(overlay_layer(scene.overlay, scene.camera, 1));
        for (int r = 0; r < 4; ++r) renderer.add_repetition();
        const glm::vec3 pixel = renderer.image().at(32, 32);
        if (opaque)
            EXPECT_GT(pixel.z, 0.9f) << "the slab in front hides the frame";
        else
            EXPECT_NEAR(pixel.x, 200.0f / 255.0f, 1e-6f);
    }
}

TEST(PbvrOverlay, ARadialProbeIsACylinderAboutItsElevationAxis) {
    // The radial preset (a ring of radius R = 6 mm; the pose is on its face, the ring's
    // centre R behind it), its elevation axis towards the camera: the tip's silhouette is
    // a disc of radius R around the ring's centre, lit head-on (its end cap), and the frame lies
    // around it, with no outline where the last line meets the first.
    OverlayScene scene;
    scene.overlay.transducer = probe::find_transducer("radial", "test");
    scene.overlay.transducer.depth_mm = 15.0;
    scene.overlay.position = {20.0, 20.0, 25.0};
    scene.overlay.frame = cv::Mat(200, 200, CV_8UC1, cv::Scalar(200));
    scene.overlay.origin_mm = {-20.0, -20.0};
    scene.overlay.pixel_mm = {0.2, 0.2};
    scene.camera.target = {20.0, 20.0, 25.0};
    const std::vector<uint64_t> layer = overlay_layer(scene.overlay, scene.camera, 1);
    const double radius = scene.overlay.transducer.radius_mm;
    // Pixels per mm on the plane: 64 pixels span 2 d tan(fov / 2) mm at distance d.
    const double mm_per_pixel = 2.0 * 200.0 * std::tan(glm::radians(10.0)) / 64.0;
    // The ring's centre on the plane: R along -axial (world +z) from the camera's target.
    auto at = [&](double x_mm, double z_mm) {  // offsets from the ring's centre
        const int col = int(std::lround(32 + x_mm / mm_per_pixel - 0.5));
        const int row = int(std::lround(32 - (z_mm + radius) / mm_per_pixel - 0.5));
        return layer[std::size_t(row) * 64 + std::size_t(col)];
    };
    const glm::vec3 body_colour(0.30f, 0.42f, 0.62f);
    for (const double angle : {0.0, 45.0, 90.0, 135.0, 200.0, 300.0}) {
        const double c = std::cos(glm::radians(angle)), s = std::sin(glm::radians(angle));
        const glm::vec3 inside = entry_colour(at(0.7 * radius * c, 0.7 * radius * s));
        // Colours are stored with 8 bits (zbuffer_entry).
        EXPECT_NEAR(inside.x, body_colour.x, 1.0 / 255.0) << "lit head-on, " << angle;
        EXPECT_NEAR(inside.z, body_colour.z, 1.0 / 255.0) << angle;
        const glm::vec3 outside = entry_colour(at(1.4 * radius * c, 1.4 * radius * s));
        EXPECT_NEAR(outside.x, 200.0f / 255.0f, 1e-6f) << "the frame around the tip, " << angle;
    }
}

TEST(PbvrOverlay, TheClipPlaneRemovesTheCameraSide) {
    const OverlayScene scene;
    const glm::vec4 plane =
        camera_side_of_plane(scene.overlay, scene.data.geometry(), scene.camera);
    RenderSettings settings;
    settings.clip_plane = plane;
    EXPECT_TRUE(settings.removed({20.0f, 5.0f, 20.0f}));    // between the camera and the plane
    EXPECT_FALSE(settings.removed({20.0f, 30.0f, 20.0f}));  // behind the plane
}

TEST(PbvrErrors, BadTransferFunctionsCamerasAndSettingsAreNamed) {
    using test::expect_input_error;
    const auto j = [](const char* text) { return nlohmann::json::parse(text); };
    expect_input_error(
        [&] {
            parse_colour_tf(j(R"({"points": [{"value": 0, "colour": [0,0,0], "opacity": 0}]})"),
                            "tf.json");
        },
        "tf.json", "points");
    expect_input_error(
        [&] {
            parse_colour_tf(
                j(R"({"points": [{"value": 0.5, "colour": [0,0,0], "opacity": 0}, {"value": 0.2, "colour": [0,0,0], "opacity": 0}]})"),
                "tf.json");
        },
        "tf.json", "points[1].value");
    expect_input_error(
        [&] {
            parse_colour_tf(
                j(R"({"points": [{"value": 0, "colour": [0,0,0], "opacity": 1.5}, {"value": 1, "colour": [0,0,0], "opacity": 0}]})"),
                "tf.json");
        },
        "tf.json", "points[0].opacity");
    expect_input_error(
        [&] {
            parse_colour_tf(
                j(R"({"points": [{"value": 0, "colour": [0,2,0], "opacity": 0}, {"value": 1, "colour": [0,0,0], "opacity": 0}]})"),
                "tf.json");
        },
        "tf.json", "points[0].colour");
    expect_input_error([&] { parse_colour_tf(j(R"({"pionts": []})"), "tf.json"); }, "tf.json",
                       "pionts");
    expect_input_error([] { load_colour_tf("/nonexistent/tf.json"); }, "/nonexistent/tf.json", "",
                       "presets: head, ramp");
    OrbitCamera camera;
    camera.fov_deg = 0.0;
    expect_input_error([&] { camera.validate(); }, "camera", "fov");
    camera.fov_deg = 190.0;
    expect_input_error([&] { camera.validate(); }, "camera", "fov");
    camera = OrbitCamera{};
    camera.distance_mm = 0.0;
    expect_input_error([&] { camera.validate(); }, "camera", "distance");
    camera = OrbitCamera{};
    camera.elevation_deg = 90.0;
    expect_input_error([&] { camera.validate(); }, "camera", "elevation");
    RenderSettings settings;
    settings.repetitions = 0;
    expect_input_error([&] { settings.validate(); }, "render settings", "repetitions");
}

TEST(Pbvr, StoredGradientsMatchCentralDifferences) {
    // Three 8-bit mantissas and a shared exponent: each component within 1/127 of the
    // largest one (half a unit of the last place, twice for the exponent's rounding).
    const BlobScene scene;
    const RenderVolume volume(scene.data, scene.tf);
    double worst = 0.0;
    for (int k = 0; k < 48; k += 3)
        for (int j = 0; j < 48; j += 2)
            for (int i = 0; i < 48; ++i) {
                const glm::vec3 exact = volume.gradient(i, j, k),
                                stored = volume.stored_gradient(i, j, k);
                const float largest =
                    std::max({std::abs(exact.x), std::abs(exact.y), std::abs(exact.z)});
                if (largest == 0.0f) {
                    EXPECT_EQ(stored, glm::vec3(0.0f));
                    continue;
                }
                for (int a = 0; a < 3; ++a)
                    worst = std::max(worst, double(std::abs(stored[a] - exact[a]) / largest));
            }
    EXPECT_LT(worst, 1.0 / 127.0);
}

TEST(Pbvr, ATransparentVolumeRendersTheBackground) {
    const BlobScene scene;
    const ColourTransferFunction clear(
        "clear", "test", {{0.0, glm::vec3(1.0f), 0.0}, {1.0, glm::vec3(1.0f), 0.0}}, 1.0, 0.0, 1.0);
    const RenderVolume volume(scene.data, clear);
    RenderSettings settings = scene.settings;
    settings.background = {0.1f, 0.2f, 0.3f};
    PbvrRenderer renderer(volume, clear, scene.camera, settings);
    EXPECT_EQ(renderer.occupied_cells(), 0u);
    renderer.add_repetition();
    for (const glm::vec3& p : renderer.image().pixels) EXPECT_EQ(p, settings.background);
}

}  // namespace
}  // namespace sonotrace::imaging::pbvr
