// Volume: index <-> world transforms, interpolation, quantiles, geometry validation,
// and the atomic output transaction.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>
#include <iterator>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

#include "tests/test_util.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/memory.h"
#include "tissue/volume.h"

namespace sonotrace::tissue {
namespace {

VolumeGeometry oblique_geometry() {
    VolumeGeometry g;
    g.dims = {6, 5, 4};
    g.spacing = {0.8, 1.1, 2.5};
    g.origin = {12.0, -7.0, 3.0};
    // A rotation about (1,1,1) by 40 degrees, built by hand (Rodrigues).
    const glm::dvec3 k = glm::normalize(glm::dvec3(1, 1, 1));
    const double a = glm::radians(40.0), c = std::cos(a), s = std::sin(a);
    glm::dmat3 K(0.0);
    K[1][0] = k.z, K[2][0] = -k.y, K[0][1] = -k.z, K[2][1] = k.x, K[0][2] = k.y, K[1][2] = -k.x;
    g.direction = glm::dmat3(1.0) + s * K + (1 - c) * K * K;
    return g;
}

TEST(Volume, IndexWorldRoundTripAndSpacing) {
    const VolumeGeometry g = oblique_geometry();
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-3, 8);
    for (int n = 0; n < 100; ++n) {
        const glm::dvec3 p(u(rng), u(rng), u(rng));
        const glm::dvec3 back = g.world_to_index(g.index_to_world(p));
        EXPECT_NEAR(glm::length(back - p), 0.0, 1e-12);
    }
    // One step along index axis a moves spacing[a] mm in the world (rotation preserves length).
    for (int a = 0; a < 3; ++a) {
        glm::dvec3 step(0.0);
        step[a] = 1.0;
        EXPECT_NEAR(glm::length(g.index_to_world(step) - g.origin), g.spacing[a], 1e-12);
    }
    // The 4x4 matrix form agrees with the function form.
    const glm::dvec4 w = g.index_to_world_matrix() * glm::dvec4(1.5, 2, 3, 1);
    EXPECT_NEAR(glm::length(glm::dvec3(w) - g.index_to_world({1.5, 2, 3})), 0.0, 1e-12);
}

TEST(Volume, TrilinearIsExactOnLinearFields) {
    // Trilinear interpolation reproduces any affine function exactly.
    Volume v(oblique_geometry());
    auto f = [](glm::dvec3 p) { return 2.0 * p.x - 3.0 * p.y + 0.5 * p.z + 4.0; };
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 5; ++j)
            for (int i = 0; i < 6; ++i) v.at(i, j, k) = float(f({double(i), double(j), double(k)}));
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> ux(0, 5), uy(0, 4), uz(0, 3);
    for (int n = 0; n < 200; ++n) {
        const glm::dvec3 p(ux(rng), uy(rng), uz(rng));
        EXPECT_NEAR(v.sample_trilinear(p, -1e9f), f(p), 1e-4);
    }
    // Beyond half a voxel from the outer centres: the outside value.
    EXPECT_EQ(v.sample_trilinear({-0.6, 1, 1}, -7.0f), -7.0f);
    EXPECT_EQ(v.sample_trilinear({1, 4.51, 1}, -7.0f), -7.0f);
    // Within half a voxel: clamped to the edge.
    EXPECT_NEAR(v.sample_trilinear({-0.4, 1, 1}, -7.0f), f({0, 1, 1}), 1e-5);
    EXPECT_EQ(v.sample_nearest({2.4, 1.6, 0.2}, 0.0f), v.at(2, 2, 0));
}

TEST(Volume, QuantileOfUniformRamp) {
    VolumeGeometry g;
    g.dims = {1000, 1, 1};
    Volume v(g);
    for (int i = 0; i < 1000; ++i) v.at(i, 0) = float(i);  // uniform on 0..999
    EXPECT_NEAR(v.quantile(0.25), 250.0, 1.0);
    EXPECT_NEAR(v.quantile(0.9), 900.0, 1.0);
    EXPECT_EQ(v.quantile(0.0), 0.0f);
    EXPECT_EQ(v.value_range(), std::make_pair(0.0f, 999.0f));
}

TEST(Volume, ValidateNamesTheBadField) {
    VolumeGeometry g;
    g.spacing = {1, 0, 1};
    test::expect_input_error([&] { g.validate("vol.json"); }, "vol.json", "spacing[j]", "positive");
    g.spacing = {1, 1, -2};
    test::expect_input_error([&] { g.validate("vol.json"); }, "vol.json", "spacing[k]", "positive");
    g = VolumeGeometry{};
    g.dims = {0, 4, 4};
    test::expect_input_error([&] { g.validate("vol.json"); }, "vol.json", "dims[i]");
    g = VolumeGeometry{};
    g.direction[2] = g.direction[0];
    test::expect_input_error([&] { g.validate("vol.json"); }, "vol.json", "direction",
                             "degenerate");
    g = VolumeGeometry{};
    g.dims = {100000, 100000, 100000};
    test::expect_input_error([&] { g.validate("vol.json"); }, "vol.json", "dims", "memory");
}

TEST(Volume, RequireFiniteNamesVoxel) {
    VolumeGeometry g;
    g.dims = {3, 3, 2};
    Volume v(g, 1.0f);
    EXPECT_NO_THROW(v.require_finite("x"));
    v.at(2, 1, 1) = std::nanf("");
    test::expect_input_error([&] { v.require_finite("x.raw"); }, "x.raw", "data", "(2, 1, 1)");
}

// Storage is zeroed without a write of ours (base::ZeroedAllocator): fresh maps read zero, small
// and large, with malloc's defaults (large blocks: fresh mappings) and as our programs set
// it (base::keep_freed_memory: reused heap), after earlier volumes of the same size were written
// and freed (their memory must not come back with old values); a fill reaches every voxel.
TEST(Volume, FreshVolumesReadZeroAndFillsReachEveryVoxel) {
    for (const bool keep : {false, true}) {
        if (keep) base::keep_freed_memory();
        for (const glm::ivec3 dims : {glm::ivec3(7, 5, 3), glm::ivec3(130, 120, 70)}) {
            VolumeGeometry g;
            g.dims = dims;
            for (int round = 0; round < 3; ++round) {
                Volume filled(g, 2.5f);
                ASSERT_EQ(filled.size(), g.voxel_count());
                for (float v : filled.voxels()) ASSERT_EQ(v, 2.5f);
                std::fill(filled.voxels().begin(), filled.voxels().end(), -1.0f);
                filled = Volume();  // freed before the next allocation
                const Volume fresh(g);
                ASSERT_EQ(fresh.size(), g.voxel_count());
                for (float v : fresh.voxels()) ASSERT_EQ(v, 0.0f);
                const Volume copy = fresh;
                for (float v : copy.voxels()) ASSERT_EQ(v, 0.0f);
            }
        }
    }
}

// gaussian_smoothed_coarse against the Gaussian itself: each expected voxel is the
// direct sum over the whole volume of exp(-|d|^2 / 2 sigma^2) (normalised, edges
// replicated out to 4 sigma), in double, independent of either smoothing's code. Tissue
// as it comes: regions of constant value with steps of 1, a disc, a stripe thinner than
// sigma (a sulcus), a disc that meets an edge. In a plane (m = 4 at sigma = 12 voxels)
// and in a slab (m = 2, 2, 1). Within 1 % of a step of 1 everywhere, edges included
// (measured: 0.74 % at the disc's centre, where the interpolation's error is largest).
TEST(Volume, GaussianOnACoarseGridIsTheGaussian) {
    struct Case {
        glm::ivec3 dims;
        glm::dvec3 spacing;
        double sigma_mm;
    };
    for (const Case& c :
         {Case{{150, 130, 1}, {0.25, 0.25, 1.0}, 3.0}, Case{{60, 50, 7}, {0.5, 0.5, 1.0}, 3.0}}) {
        VolumeGeometry g;
        g.dims = c.dims;
        g.spacing = c.spacing;
        Volume v(g);
        for (int k = 0; k < g.dims.z; ++k)
            for (int j = 0; j < g.dims.y; ++j)
                for (int i = 0; i < g.dims.x; ++i) {
                    const glm::dvec3 x = glm::dvec3(i, j, k) * g.spacing;
                    float value = x.x + 0.3 * x.y < 20.0 ? 0.0f : 1.0f;  // a tilted interface
                    if (glm::length(glm::dvec2(x.x - 12.0, x.y - 20.0)) < 5.0) value = 2.0f;
                    if (std::abs(x.y - 8.0) < 0.5) value = 1.0f;  // 1 mm stripe
                    v.at(i, j, k) = value;
                }
        const Volume coarse = gaussian_smoothed_coarse(v, c.sigma_mm);
        // The direct Gaussian: separable, so one axis at a time in double.
        std::vector<double> field(v.voxels().begin(), v.voxels().end());
        for (int axis = 0; axis < 3; ++axis) {
            const int n = g.dims[axis];
            if (n < 2) continue;
            const double s = c.sigma_mm / g.spacing[axis];
            const int reach = int(std::ceil(4.0 * s));
            std::vector<double> w(std::size_t(2 * reach + 1));
            double total = 0.0;
            for (int o = -reach; o <= reach; ++o)
                total += w[std::size_t(o + reach)] = std::exp(-0.5 * o * o / (s * s));
            const std::vector<double> in = field;
            for (int k = 0; k < g.dims.z; ++k)
                for (int j = 0; j < g.dims.y; ++j)
                    for (int i = 0; i < g.dims.x; ++i) {
                        double sum = 0.0;
                        for (int o = -reach; o <= reach; ++o) {
                            glm::ivec3 at(i, j, k);
                            at[axis] = std::clamp(at[axis] + o, 0, n - 1);
                            sum += w[std::size_t(o + reach)] * in[v.linear_index(at.x, at.y, at.z)];
                        }
                        field[v.linear_index(i, j, k)] = sum / total;
                    }
        }
        double worst = 0.0;
        for (std::size_t q = 0; q < field.size(); ++q)
            worst = std::max(worst, std::abs(double(coarse.voxels()[q]) - field[q]));
        std::printf("dims %d x %d x %d: largest difference %.4f of a step of 1\n", c.dims.x,
                    c.dims.y, c.dims.z, worst);
        EXPECT_LT(worst, 0.01);
    }
}

// gaussian_smoothed sums blocks of samples in registers (an optimisation that claims to
// change nothing): it must equal, bit for bit, the plain separable sum it replaced: along
// x, then y, then z, each output 0 + w_0 v_-r + w_1 v_-r+1 + ... in tap order, edges
// clamped. Sizes not multiples of the block (32), and a spacing per axis.
TEST(Volume, GaussianSmoothingIsThePlainTapByTapSum) {
    VolumeGeometry g;
    g.dims = {75, 41, 9};
    g.spacing = {0.25, 0.4, 1.0};
    Volume v(g);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(0.0f, 2.0f);
    for (float& x : v.voxels()) x = u(rng);
    const double sigma_mm = 1.3;
    const Volume fast = gaussian_smoothed(v, sigma_mm);
    Volume plain = v;
    for (int axis = 0; axis < 3; ++axis) {
        const double sigma = sigma_mm / g.spacing[axis];
        const int radius = std::max(1, int(std::ceil(3.0 * sigma)));
        std::vector<float> kernel;
        double total = 0.0;
        for (int o = -radius; o <= radius; ++o) total += std::exp(-0.5 * o * o / (sigma * sigma));
        for (int o = -radius; o <= radius; ++o)
            kernel.push_back(float(std::exp(-0.5 * o * o / (sigma * sigma)) / total));
        const Volume in = plain;
        for (int k = 0; k < g.dims.z; ++k)
            for (int j = 0; j < g.dims.y; ++j)
                for (int i = 0; i < g.dims.x; ++i) {
                    float sum = 0.0f;
                    for (int o = -radius; o <= radius; ++o) {
                        glm::ivec3 at(i, j, k);
                        at[axis] = std::clamp(at[axis] + o, 0, g.dims[axis] - 1);
                        sum += kernel[std::size_t(o + radius)] * in.at(at.x, at.y, at.z);
                    }
                    plain.at(i, j, k) = sum;
                }
    }
    ASSERT_EQ(fast.size(), plain.size());
    EXPECT_EQ(std::memcmp(fast.voxels().data(), plain.voxels().data(), fast.size() * 4), 0);
}

TEST(OutputTransaction, UncommittedFilesVanishCommittedOnesAppear) {
    test::ScratchDir dir;
    const std::string a = dir / "sub/a.txt", b = dir / "b.txt";
    {
        base::OutputTransaction t;
        std::ofstream(t.stage(a)) << "a";
        std::ofstream(t.stage(b)) << "b";
        EXPECT_FALSE(std::filesystem::exists(a));
    }  // destroyed without commit
    EXPECT_FALSE(std::filesystem::exists(a));
    EXPECT_FALSE(std::filesystem::exists(b));
    EXPECT_TRUE(std::filesystem::is_empty(dir / "sub"));
    {
        base::OutputTransaction t;
        std::ofstream(t.stage(a)) << "a";
        t.commit();
    }
    std::ifstream in(a);
    std::string text;
    in >> text;
    EXPECT_EQ(text, "a");
    EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir / "sub"), {}), 1);
}

std::string contents(const std::string& path) {
    std::ifstream in(path);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

// A rename that fails part-way (the third output's name is taken by a directory) leaves
// the directory as it was: the first output is not there, the second's older file is
// restored, and no temporary or backup remains.
TEST(OutputTransaction, ACommitIsAllOrNothing) {
    test::ScratchDir dir;
    std::ofstream(dir / "b.txt") << "old";
    std::filesystem::create_directories(dir / "c.txt");
    {
        base::OutputTransaction t;
        std::ofstream(t.stage(dir / "a.txt")) << "new a";
        std::ofstream(t.stage(dir / "b.txt")) << "new b";
        std::ofstream(t.stage(dir / "c.txt")) << "new c";
        test::expect_input_error([&] { t.commit(); }, "c.txt", "", "cannot move output");
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "a.txt"));
    EXPECT_EQ(contents(dir / "b.txt"), "old");
    EXPECT_TRUE(std::filesystem::is_directory(dir / "c.txt"));
    EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()), {}), 2)
        << "only b.txt and the directory c.txt";
    // Without the obstacle the same outputs replace the old file.
    std::filesystem::remove(dir / "c.txt");
    base::OutputTransaction t;
    std::ofstream(t.stage(dir / "a.txt")) << "new a";
    std::ofstream(t.stage(dir / "b.txt")) << "new b";
    t.commit();
    EXPECT_EQ(contents(dir / "a.txt"), "new a");
    EXPECT_EQ(contents(dir / "b.txt"), "new b");
    EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()), {}), 2);
}

TEST(OutputTransaction, TwoOutputsOfOneNameAreRefused) {
    test::ScratchDir dir;
    base::OutputTransaction t;
    t.stage(dir / "out/trace.json");
    test::expect_input_error([&] { t.stage(dir / "out/../out/trace.json"); }, "trace.json", "",
                             "two outputs");
}

// Temporaries of runs that no longer exist (killed) are removed by the next run into the
// directory; those of live processes, and those of another host (its process ids mean
// nothing here: a directory shared over NFS), are left alone.
TEST(OutputTransaction, TheNextRunRemovesStaleTemporaries) {
    test::ScratchDir dir;
    const pid_t dead = [] {  // a child that has exited and been reaped
        const pid_t child = fork();
        if (child == 0) _exit(0);
        int status = 0;
        waitpid(child, &status, 0);
        return child;
    }();
    const std::string stale = dir / (".partial-" + base::temporary_owner(dead) + "-0-bmode.png");
    const std::string live =
        dir / (".partial-" + base::temporary_owner(getppid()) + "-0-bmode.png");
    const std::string other_host =
        dir / (".partial-" + std::to_string(dead) + ".0123456789abcdef-0-bmode.png");
    const std::string no_host = dir / (".partial-" + std::to_string(dead) + "-0-labels.png");
    for (const std::string& file : {stale, live, other_host, no_host}) std::ofstream(file) << "x";
    base::OutputTransaction t;
    std::ofstream(t.stage(dir / "bmode.png")) << "frame";
    EXPECT_FALSE(std::filesystem::exists(stale));
    EXPECT_TRUE(std::filesystem::exists(live));
    EXPECT_TRUE(std::filesystem::exists(other_host));
    EXPECT_TRUE(std::filesystem::exists(no_host));
    EXPECT_EQ(base::output_name(t.stage(dir / "labels.png")), dir / "labels.png");
}

}  // namespace
}  // namespace sonotrace::tissue
