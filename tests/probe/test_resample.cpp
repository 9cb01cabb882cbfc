// Slicing and sub-volumes: exact on linear fields (where trilinear interpolation is
// exact) for arbitrary rotated poses, correct grid geometry, labels stay labels, and
// results do not depend on the thread count.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <random>
#include <set>

#include "probe/pose.h"
#include "tests/test_util.h"
#include "tissue/resample.h"

namespace sonotrace::tissue {
namespace {

// f(world) = a . world + b: affine in world, hence affine in index space for any
// geometry, so trilinear interpolation reproduces it exactly.
const glm::dvec3 kA(0.7, -1.3, 2.1);
constexpr double kB = 5.0;
double linear_field(const glm::dvec3& w) {
    return glm::dot(kA, w) + kB;
}

Volume linear_volume() {
    VolumeGeometry g;
    g.dims = {40, 36, 30};
    g.spacing = {1.0, 1.2, 1.5};
    g.origin = {-20, -21, -22};
    const double t = glm::radians(20.0);  // the volume itself is rotated about x
    g.direction = glm::dmat3(glm::dvec3(1, 0, 0), glm::dvec3(0, std::cos(t), std::sin(t)),
                             glm::dvec3(0, -std::sin(t), std::cos(t)));
    Volume v(g);
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i)
                v.at(i, j, k) =
                    float(linear_field(g.index_to_world({double(i), double(j), double(k)})));
    return v;
}

bool inside(const Volume& v, const glm::dvec3& world) {
    const glm::dvec3 p = v.geometry().world_to_index(world);
    for (int a = 0; a < 3; ++a) {
        if (p[a] < 0 || p[a] > v.dims()[a] - 1) return false;
    }
    return true;
}

TEST(Resample, ObliqueSlicesOfLinearFieldAreExact) {
    const Volume v = linear_volume();
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1, 1);
    int checked = 0;
    for (int pose_n = 0; pose_n < 12; ++pose_n) {
        const glm::dvec3 at(5 * u(rng), 5 * u(rng), 5 * u(rng));
        const probe::Pose pose =
            probe::Pose::looking(at, {u(rng), u(rng), u(rng)}, {u(rng), u(rng), u(rng)})
                .rotated(37 * pose_n);
        const GridExtent extent{24.0, 18.0, 0.0, 0.7};
        const VolumeGeometry grid = probe_grid(pose.frame(), extent, "test");
        const Volume slice = resample(v, grid, Interpolation::trilinear, -999.0f);
        for (int j = 0; j < grid.dims.y; ++j) {
            for (int i = 0; i < grid.dims.x; ++i) {
                // Expected position from the pose alone: pixels centred on the beam axis
                // (the width rounds to whole pixels), depth from the face.
                const double lateral = (i - 0.5 * (grid.dims.x - 1)) * extent.pixel_mm;
                const double depth = (j + 0.5) * extent.pixel_mm;
                const glm::dvec3 w =
                    pose.position + pose.lateral() * lateral + pose.axial() * depth;
                if (inside(v, w)) {
                    ASSERT_NEAR(slice.at(i, j), linear_field(w),
                                2e-4 * (1 + std::abs(linear_field(w))));
                    ++checked;
                }
            }
        }
    }
    EXPECT_GT(checked, 3000);
}

TEST(Resample, SubVolumeHasElevationAxisAndExactValues) {
    const Volume v = linear_volume();
    const probe::Pose pose = probe::Pose::looking({0, 0, -5}, {0, 0.3, 1}, {1, 0, 0});
    const GridExtent extent{10.0, 12.0, 6.0, 1.0};
    const VolumeGeometry grid = probe_grid(pose.frame(), extent, "test");
    ASSERT_EQ(grid.dims, glm::ivec3(10, 12, 6));
    const Volume sub = resample(v, grid, Interpolation::trilinear, 0.0f);
    for (int k = 0; k < 6; ++k) {
        const glm::dvec3 w = pose.position + pose.lateral() * (-4.5) + pose.axial() * 3.5 +
                             pose.elevation() * (-2.5 + k);
        EXPECT_NEAR(sub.at(0, 3, k), linear_field(w), 1e-3);
    }
    // (lateral, axial, elevation) is right-handed.
    EXPECT_GT(glm::determinant(grid.direction), 0.999);
}

TEST(Resample, OutsideTheVolumeGivesTheOutsideValue) {
    const Volume v = linear_volume();
    const probe::Pose far = probe::Pose::looking({500, 500, 500}, {1, 0, 0}, {0, 1, 0});
    const Volume s =
        resample(v, probe_grid(far.frame(), {10, 10, 0, 1}, "t"), Interpolation::trilinear, -3.0f);
    for (float x : s.voxels()) ASSERT_EQ(x, -3.0f);
}

TEST(Resample, NearestKeepsLabels) {
    VolumeGeometry g;
    g.dims = {8, 8, 8};
    Volume labels(g);
    for (int k = 0; k < 8; ++k)
        for (int j = 0; j < 8; ++j)
            for (int i = 0; i < 8; ++i) labels.at(i, j, k) = float((i / 3 + j / 3 + k / 3) % 3 * 5);
    const probe::Pose pose =
        probe::Pose::looking({3.3, -0.2, 3.1}, {0.1, 1, 0.2}, {1, 0, 0}).rotated(21);
    const Volume s = resample(labels, probe_grid(pose.frame(), {6, 7, 0, 0.13}, "t"),
                              Interpolation::nearest, 0.0f);
    const std::set<float> values(s.voxels().begin(), s.voxels().end());
    for (float x : values) EXPECT_TRUE(x == 0.0f || x == 5.0f || x == 10.0f) << x;
    EXPECT_GE(values.size(), 2u);
}

TEST(Resample, IdenticalOnOneAndTwoThreads) {
    const Volume v = linear_volume();
    const probe::Pose pose = probe::Pose::looking({1, 2, -3}, {0.2, 0.1, 1}, {1, 0, 0});
    const VolumeGeometry grid = probe_grid(pose.frame(), {30, 30, 4, 0.2}, "t");
    Voxels one, two;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        one = resample(v, grid, Interpolation::trilinear, 0.0f).voxels();
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
        two = resample(v, grid, Interpolation::trilinear, 0.0f).voxels();
    }
    EXPECT_EQ(one, two);
}

TEST(ResampleErrors, BadExtentNamesTheParameter) {
    const ProbeFrame frame;
    test::expect_input_error(
        [&] {
            probe_grid(frame, {0, 10, 0, 1}, "--width");
        },
        "--width", "width", "positive");
    test::expect_input_error(
        [&] {
            probe_grid(frame, {10, 10, 0, -1}, "--resolution");
        },
        "--resolution", "resolution");
    test::expect_input_error([&] { probe_grid(frame, {10, 10, -2, 1}, "x"); }, "x", "elevation");
    test::expect_input_error(
        [&] {
            probe_grid(frame, {1e6, 1e6, 1e6, 0.01}, "x");
        },
        "x", "dims", "memory");
    ProbeFrame skew;
    skew.axial = glm::normalize(glm::dvec3(1, 1, 0));
    test::expect_input_error(
        [&] {
            probe_grid(skew, {10, 10, 0, 1}, "--pose");
        },
        "--pose", "pose", "orthonormal");
}

}  // namespace
}  // namespace sonotrace::tissue
