// A mesh images like the shape it stands for: an icosphere the test writes, of a tissue
// 6 dB less echogenic than the liver around it, against the analytic sphere of the same
// radius and tissue, the same frames otherwise. Levels measured on the envelope.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "phantoms/scene/scene.h"
#include "probe/transducer.h"
#include "tests/phantoms/meshes_for_tests.h"
#include "tests/test_util.h"

namespace sonotrace {
namespace {

// Mean intensity (envelope^2) over the lines within [x0, x1] mm of the probe's centre and
// the samples within [z0, z1] mm of depth.
struct Region {
    double x0, x1, z0, z1;
};
double mean_intensity(const imaging::LineData& data, const probe::Transducer& t, const Region& r) {
    const probe::ScanGeometry g(t);
    double sum = 0.0;
    int n = 0;
    for (int l = 0; l < data.lines; ++l) {
        const double x = g.point(l, 0.0).x;
        if (x < r.x0 || x > r.x1) continue;
        for (int i = 0; i < data.samples; ++i) {
            const double z = data.depth_mm(i);
            if (z < r.z0 || z > r.z1) continue;
            sum += double(data.at(l, i)) * data.at(l, i);
            ++n;
        }
    }
    return n > 0 ? sum / n : 0.0;
}

TEST(MeshFrames, AnIcosphereImagesAsItsAnalyticSphere) {
    test::ScratchDir dir;
    // The probe on top at x = 20: the sphere's centre 20 mm deep, on the central line.
    const glm::dvec3 c(20.0, 20.0, 5.0);
    const double R = 6.0;
    test::write_obj(test::icosphere(4, R, c), dir / "ball.obj");
    auto phantom = [&](bool mesh) {
        nlohmann::json ball = {{"tissue", "liver"}, {"backscatter", 0.25}};
        if (mesh)
            ball.update({{"type", "mesh"}, {"file", "ball.obj"}});
        else
            ball.update({{"type", "sphere"}, {"centre", {c.x, c.y, c.z}}, {"radius", R}});
        const nlohmann::json j = {{"name", "ball"},
                                  {"size", {40, 40, 10}},
                                  {"background", {{"tissue", "liver"}}},
                                  {"shapes", {ball}},
                                  {"probe", {{"preset", "linear"}}}};
        return phantoms::parse_phantom(j, dir / "ball.json");  // the mesh beside it
    };
    const probe::Transducer t = probe::find_transducer("linear", "test");
    // Inside: a square within R - 1 of the centre; outside: a band 3 mm beside the ball.
    const Region inside{-3.5, 3.5, c.y - 3.5, c.y + 3.5},
        beside{-13.0, -10.0, c.y - 3.5, c.y + 3.5};
    // The ball's contrast, inside against beside (dB), per seed.
    constexpr int kSeeds = 6;
    std::vector<double> contrast[2];  // [sphere, mesh]
    for (const bool mesh : {false, true}) {
        const auto scene = scene::phantom_scene(phantom(mesh));
        for (int seed = 1; seed <= kSeeds; ++seed) {
            imaging::SimulationSettings settings;
            settings.transducer = t;
            settings.quality = imaging::Quality::interactive;
            settings.seed = uint64_t(seed);
            scene->apply_to(settings);
            const imaging::LineData env =
                imaging::simulate_plane(scene->mapper, scene->start, settings, false)
                    .frame.envelope;
            contrast[mesh].push_back(
                10.0 * std::log10(mean_intensity(env, t, inside) / mean_intensity(env, t, beside)));
        }
    }
    // Within speckle statistics: the two means differ by less than 4 standard errors of
    // their difference, the spread measured over the seeds (each seed a new speckle).
    auto mean = [](const std::vector<double>& v) {
        double sum = 0.0;
        for (double x : v) sum += x;
        return sum / double(v.size());
    };
    auto variance = [&](const std::vector<double>& v) {
        const double m = mean(v);
        double sum = 0.0;
        for (double x : v) sum += (x - m) * (x - m);
        return sum / double(v.size() - 1);
    };
    const double error =
        std::sqrt((variance(contrast[0]) + variance(contrast[1])) / double(kSeeds));
    std::printf("inside against beside: sphere %.2f dB, mesh %.2f dB (standard error %.2f dB)\n",
                mean(contrast[0]), mean(contrast[1]), error);
    EXPECT_NEAR(mean(contrast[1]), mean(contrast[0]), 4.0 * error);
    // And the ball shows: backscatter 0.25 is -6 dB of the liver's.
    EXPECT_NEAR(mean(contrast[0]), -6.0, 1.5);
}

// Instances: a sphere mesh (shape 1) holding a smaller sphere (shape 2), an analytic box
// (shape 3) beside them. Each pixel's instance is the innermost shape whose surface holds
// its centre: worked out here from the geometry (the probe plane is z = 5, the probe's
// centre at x = 20 on top, depth along y), exact away from the surfaces (0.5 mm: the
// interactive quality's map texel, which the nearest texel may miss by half its diagonal).
TEST(MeshFrames, InstancesNameTheShapeEachPixelLiesIn) {
    test::ScratchDir dir;
    const glm::dvec3 c(16.0, 18.0, 5.0);
    test::write_obj(test::icosphere(4, 7.0, c), dir / "outer.obj");
    test::write_obj(test::icosphere(3, 3.0, c), dir / "inner.obj");
    const nlohmann::json j = {
        {"name", "nested"},
        {"size", {40, 40, 10}},
        {"background", {{"tissue", "liver"}}},
        {"shapes",
         {{{"type", "mesh"}, {"file", "outer.obj"}, {"tissue", "kidney"}},
          {{"type", "mesh"}, {"file", "inner.obj"}, {"tissue", "blood"}},
          {{"type", "box"}, {"min", {28, 10, 0}}, {"max", {34, 16, 10}}, {"tissue", "fat"}}}},
        {"probe", {{"preset", "linear"}}}};
    const auto scene = scene::phantom_scene(phantoms::parse_phantom(j, dir / "nested.json"));
    imaging::SimulationSettings settings;
    settings.transducer = probe::find_transducer("linear", "test");
    settings.quality = imaging::Quality::interactive;
    scene->apply_to(settings);
    const imaging::SimulatedFrame frame =
        imaging::simulate_plane(scene->mapper, scene->start, settings, true);
    const cv::Mat instances = scene::instance_map(*scene, frame);
    ASSERT_EQ(instances.type(), CV_16U);
    const imaging::ScanConverted& image = frame.frame.image;
    int counted[4] = {};
    for (int r = 0; r < instances.rows; ++r)
        for (int col = 0; col < instances.cols; ++col) {
            if (!image.inside.at<uint8_t>(r, col)) continue;
            // The pixel in the phantom's frame: lateral about x = 20, depth along y.
            const glm::dvec2 p = image.origin + glm::dvec2(col, r) * image.pixel_mm;
            const glm::dvec3 at(20.0 + p.x, p.y, 5.0);
            const double to_centre = glm::length(at - c);
            const bool in_box = at.x > 28 && at.x < 34 && at.y > 10 && at.y < 16;
            const double margin =
                std::min({std::abs(to_centre - 7.0), std::abs(to_centre - 3.0),
                          in_box || (at.x > 27.5 && at.x < 34.5 && at.y > 9.5 && at.y < 16.5)
                              ? std::min({std::abs(at.x - 28), std::abs(at.x - 34),
                                          std::abs(at.y - 10), std::abs(at.y - 16)})
                              : 1.0});
            if (margin < 0.5 || at.y < 0.5) continue;
            const int expected = to_centre < 3.0 ? 2 : to_centre < 7.0 ? 1 : in_box ? 3 : 0;
            ASSERT_EQ(instances.at<uint16_t>(r, col), expected) << at.x << " " << at.y;
            ++counted[expected];
        }
    for (int k = 0; k < 4; ++k) EXPECT_GT(counted[k], 50) << k;
}

}  // namespace
}  // namespace sonotrace
