// AcousticMap: gradients (Sobel-weighted central differences) against analytic gradients of smooth
// fields (2D and 3D) within the truncation-error bound, exact bi/trilinear sampling of
// linear fields, domain test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "tissue/acoustic_map.h"

namespace sonotrace::tissue {
namespace {

// c(x, y, z) = 1540 + 50 sin(x/L) cos(y/L) cos(z/L) m/s, positions in mm.
constexpr double kL = 5.0, kAmp = 50.0, kRho = 1000.0;
double speed_at(glm::dvec3 p) {
    return 1540.0 + kAmp * std::sin(p.x / kL) * std::cos(p.y / kL) * std::cos(p.z / kL);
}
glm::dvec3 speed_gradient(glm::dvec3 p) {
    const double a = kAmp / kL;
    return {a * std::cos(p.x / kL) * std::cos(p.y / kL) * std::cos(p.z / kL),
            -a * std::sin(p.x / kL) * std::sin(p.y / kL) * std::cos(p.z / kL),
            -a * std::sin(p.x / kL) * std::cos(p.y / kL) * std::sin(p.z / kL)};
}

PropertyMaps smooth_maps(glm::ivec3 dims, double h) {
    VolumeGeometry g;
    g.dims = dims;
    g.spacing = glm::dvec3(h);
    PropertyMaps maps;
    for (Volume& f : maps.fields) f = Volume(g, 0.0f);
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) {
                const glm::dvec3 p = glm::dvec3(i, j, k) * h;
                maps[Property::speed_of_sound].at(i, j, k) = float(speed_at(p));
                maps[Property::density].at(i, j, k) = float(kRho);
                maps[Property::attenuation].at(i, j, k) =
                    float(0.5 + 0.01 * p.x - 0.02 * p.y + 0.03 * p.z);
                maps[Property::roughness].at(i, j, k) =
                    float(0.2 - 0.01 * p.x + 0.02 * p.y + 0.01 * p.z);
            }
    return maps;
}

// Error bound per gradient component, with every third derivative of c bounded by
// amp/L^3: the central difference errs by h^2/6 |f_xxx|; the Sobel average over each
// other axis (weights 1/4, 1/2, 1/4: variance h^2/2) adds h^2/4 |f_xyy| per axis; the
// bilinear interpolation of the texel gradients adds h^2/8 |g''| per axis. 10 % covers
// the O(h^4) remainder; 1e-4 the float rounding.
double gradient_tolerance(double h, int dims) {
    const double third = kAmp / (kL * kL * kL);
    return 1.1 * h * h * third * (1.0 / 6.0 + (dims - 1) / 4.0 + dims / 8.0) + 1e-4;
}

template <int Dim>
void check_gradients(const AcousticMap<Dim>& map, double h, int samples) {
    std::mt19937 rng(5);
    const auto extent = map.extent_mm();
    double worst_z = 0.0, worst_n = 0.0;
    for (int s = 0; s < samples; ++s) {
        glm::vec<Dim, float> p;
        glm::dvec3 w(0.0);
        for (int a = 0; a < Dim; ++a) {
            // Keep one texel away from the border, where differences are one-sided.
            p[a] = std::uniform_real_distribution<float>(float(h), extent[a] - float(h))(rng);
            w[a] = p[a];
        }
        const AcousticTexel<Dim> t = map.sample(p);
        const glm::dvec3 gc = speed_gradient(w);
        const double c = speed_at(w);
        for (int a = 0; a < Dim; ++a) {
            // Z = rho c: dZ = rho dc (MRayl); n = c0/c: dn = -c0 dc / c^2.
            worst_z = std::max(worst_z,
                               std::abs(t.grad_impedance[a] - kRho * gc[a] * 1e-6) / (kRho * 1e-6));
            worst_n = std::max(
                worst_n, std::abs(t.grad_refractive_index[a] + kReferenceSpeed * gc[a] / (c * c)) /
                             (kReferenceSpeed / (c * c)));
        }
    }
    // Both are expressed as errors in dc/dx (m/s per mm).
    EXPECT_LT(worst_z, gradient_tolerance(h, Dim));
    EXPECT_LT(worst_n, gradient_tolerance(h, Dim) + 0.005);  // n is a float near 1: ~4e-4 rounding
    ::testing::Test::RecordProperty("worst_dc_error_from_Z", std::to_string(worst_z));
}

TEST(AcousticMap, GradientsMatchAnalytic2D) {
    const double h = 0.25;
    const auto map = AcousticMap<2>::build(smooth_maps({160, 120, 1}, h));
    check_gradients(map, h, 2000);
}

TEST(AcousticMap, GradientsMatchAnalytic3D) {
    const double h = 0.5;
    const auto map = AcousticMap<3>::build(smooth_maps({48, 40, 36}, h));
    check_gradients(map, h, 2000);
}

TEST(AcousticMap, TexelGradientIsTheSobelWeightedCentralDifference) {
    // d/dx at (7, 9): central differences of rows 8, 9, 10 weighted 1/4, 1/2, 1/4.
    const double h = 0.25;
    const auto maps = smooth_maps({20, 20, 1}, h);
    const auto map = AcousticMap<2>::build(maps);
    auto z = [&](int i, int j) { return maps[Property::speed_of_sound].at(i, j) * kRho * 1e-6; };
    auto cd = [&](int i, int j) { return (z(i + 1, j) - z(i - 1, j)) / (2 * h); };
    EXPECT_NEAR(map.texel({7, 9}).grad_impedance[0],
                0.25 * cd(7, 8) + 0.5 * cd(7, 9) + 0.25 * cd(7, 10), 1e-6);
    // One-sided along the axis at the border, averaged over the existing neighbours.
    auto one_sided = [&](int j) { return (z(1, j) - z(0, j)) / h; };
    EXPECT_NEAR(map.texel({0, 9}).grad_impedance[0],
                0.25 * one_sided(8) + 0.5 * one_sided(9) + 0.25 * one_sided(10), 1e-6);
    // At a corner the missing neighbour drops out of the weights (2/3, 1/3).
    auto cd_y = [&](int i) { return (z(i, 1) - z(i, 0)) / h; };
    EXPECT_NEAR(map.texel({0, 0}).grad_impedance[1], (2.0 * cd_y(0) + cd_y(1)) / 3.0, 1e-6);
}

// The 3D interior's direct-indexing path (a speed-up) must give the float the generic
// Sobel difference gives: per neighbour the float of (f+ - f-) / 2h, summed in double with
// weights 1, 2, 4 in the order u, v = -1..1 over the next two axes, divided by 16. Written
// out here on an anisotropic grid with random speeds, compared bit for bit.
TEST(AcousticMap, InteriorGradients3DAreTheSobelDifferenceBitForBit) {
    PropertyMaps maps = smooth_maps({9, 8, 7}, 0.25);
    VolumeGeometry g = maps.geometry();
    g.spacing = {0.25, 0.3, 0.5};
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> speed(1450.0f, 1650.0f);
    for (auto& field : maps.fields) {
        Volume v(g);
        for (float& x : v.voxels()) x = field.voxels()[&x - v.voxels().data()];
        field = std::move(v);
    }
    for (float& c : maps[Property::speed_of_sound].voxels()) c = speed(rng);
    const Volume impedance = maps.impedance();
    const auto map = AcousticMap<3>::build(maps);
    auto sobel = [&](const glm::ivec3& i, int axis) {
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
        double sum = 0.0;
        for (int u = -1; u <= 1; ++u) {
            for (int v = -1; v <= 1; ++v) {
                glm::ivec3 j = i, lo, hi;
                j[a1] += u, j[a2] += v;
                lo = hi = j;
                lo[axis] -= 1, hi[axis] += 1;
                const double h = g.spacing[axis] * 2.0;
                const float d = float(
                    (double(impedance.at(hi.x, hi.y, hi.z)) - impedance.at(lo.x, lo.y, lo.z)) / h);
                sum += (u == 0 ? 2.0 : 1.0) * (v == 0 ? 2.0 : 1.0) * double(d);
            }
        }
        return float(sum / 16.0);
    };
    int compared = 0;
    for (int k = 1; k + 1 < g.dims.z; ++k)
        for (int j = 1; j + 1 < g.dims.y; ++j)
            for (int i = 1; i + 1 < g.dims.x; ++i)
                for (int a = 0; a < 3; ++a) {
                    EXPECT_EQ(map.texel({i, j, k}).grad_impedance[a], sobel({i, j, k}, a))
                        << i << "," << j << "," << k << " axis " << a;
                    ++compared;
                }
    EXPECT_EQ(compared, 7 * 6 * 5 * 3);
}

TEST(AcousticMap, SamplingIsExactForLinearFields) {
    const auto map = AcousticMap<3>::build(smooth_maps({12, 10, 8}, 0.5));
    std::mt19937 rng(9);
    for (int s = 0; s < 500; ++s) {
        const glm::vec3 p(std::uniform_real_distribution<float>(0, 5.5f)(rng),
                          std::uniform_real_distribution<float>(0, 4.5f)(rng),
                          std::uniform_real_distribution<float>(0, 3.5f)(rng));
        EXPECT_NEAR(map.sample(p).attenuation, 0.5 + 0.01 * p.x - 0.02 * p.y + 0.03 * p.z, 1e-5);
        // Roughness, a map beside the records, interpolates the same way.
        EXPECT_NEAR(map.sample_roughness(p), 0.2 - 0.01 * p.x + 0.02 * p.y + 0.01 * p.z, 1e-5);
    }
}

// The single-field lookups give exactly what the whole-record sample() gives: the tracer
// mixes them (the index at a particle's birth, the record at its steps).
template <int Dim>
void check_single_fields_match_sample(glm::ivec3 dims) {
    const auto map = AcousticMap<Dim>::build(smooth_maps(dims, 0.5));
    std::mt19937 rng(11);
    const auto extent = map.extent_mm();
    for (int s = 0; s < 500; ++s) {
        glm::vec<Dim, float> p;
        for (int a = 0; a < Dim; ++a)
            p[a] = std::uniform_real_distribution<float>(0.0f, extent[a])(rng);
        ASSERT_EQ(map.sample_refractive_index(p), map.sample(p).refractive_index);
    }
}
TEST(AcousticMap, RefractiveIndexLookupIsSamplesValue) {
    check_single_fields_match_sample<2>({16, 12, 1});
    check_single_fields_match_sample<3>({12, 10, 8});
}

TEST(AcousticMap, DomainIsTheTexelCentreBox) {
    const auto map = AcousticMap<2>::build(smooth_maps({11, 21, 1}, 0.5));
    EXPECT_TRUE(map.inside({0.0f, 0.0f}));
    EXPECT_TRUE(map.inside({5.0f, 10.0f}));
    EXPECT_FALSE(map.inside({5.01f, 1.0f}));
    EXPECT_FALSE(map.inside({1.0f, -0.01f}));
    // Outside samples clamp to the edge texel.
    EXPECT_EQ(map.sample({-3.0f, 0.0f}).impedance, map.texel({0, 0}).impedance);
}

// A step in speed of sound at x = 20.5 texels (between texels 20 and 21), 2D and 3D:
// a block is uniform exactly when its texel range, widened by one texel on each side
// (the far corners of its cells), stays on one side.
template <int Dim>
void check_uniform_blocks() {
    const glm::ivec3 dims = Dim == 2 ? glm::ivec3(50, 30, 1) : glm::ivec3(50, 30, 20);
    PropertyMaps maps = smooth_maps(dims, 0.5);
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) {
                maps[Property::speed_of_sound].at(i, j, k) = i <= 20 ? 1540.0f : 1580.0f;
                maps[Property::attenuation].at(i, j, k) = 0.5f;
            }
    const auto map = AcousticMap<Dim>::build(maps);
    constexpr int B = AcousticMap<Dim>::kBlock;
    std::mt19937 rng(3);
    int uniform = 0, varying = 0;
    for (int s = 0; s < 4000; ++s) {
        glm::vec<Dim, float> p;
        for (int a = 0; a < Dim; ++a)
            p[a] = std::uniform_real_distribution<float>(0.0f, map.extent_mm()[a])(rng);
        const int block_x = int(p[0] / 0.5f) / B;
        // Texels block_x*B - 1 .. (block_x+1)*B must lie on one side of 20 | 21; the
        // gradient is non-zero at texels 20 and 21 themselves.
        const int lo = block_x * B - 1, hi = (block_x + 1) * B;
        const bool expect_uniform = hi < 20 || lo > 21;
        const AcousticTexel<Dim>* record = map.uniform_block(p);
        ASSERT_EQ(record != nullptr, expect_uniform) << "x = " << p[0];
        if (!record) {
            ++varying;
            continue;
        }
        ++uniform;
        // Anywhere in a uniform block, interpolation returns the record (to rounding).
        const AcousticTexel<Dim> t = map.sample(p);
        EXPECT_NEAR(t.refractive_index, record->refractive_index, 1e-6f);
        EXPECT_NEAR(t.impedance, record->impedance, 1e-6f);
        EXPECT_NEAR(t.attenuation, record->attenuation, 1e-6f);
        EXPECT_EQ(record->grad_impedance[0], 0.0f);
    }
    EXPECT_GT(uniform, 1000);
    EXPECT_GT(varying, 100);
    // Two distinct records (either side): the fraction of uniform blocks is
    // (blocks of x clear of texels 19..22) / (blocks of x) over all other axes.
    const int blocks_x = (dims.x + B - 1) / B;
    int clear = 0;
    for (int b = 0; b < blocks_x; ++b) clear += ((b + 1) * B < 20 || b * B - 1 > 21);
    EXPECT_DOUBLE_EQ(map.uniform_block_fraction(), double(clear) / blocks_x);
}

TEST(AcousticMap, UniformBlocksAreExactlyTheBlocksClearOfAnInterface2D) {
    check_uniform_blocks<2>();
}
TEST(AcousticMap, UniformBlocksAreExactlyTheBlocksClearOfAnInterface3D) {
    check_uniform_blocks<3>();
}

}  // namespace
}  // namespace sonotrace::tissue

namespace sonotrace::tissue {
namespace {

// Arrays of 2 MiB or more start on a 2 MiB boundary (so that whole huge pages back
// them); smaller ones come from operator new. Under ASan a mismatched free fails here.
TEST(HugePageAllocator, LargeArraysStartOnHugePageBoundaries) {
    constexpr std::size_t kHuge = std::size_t(2) << 20;
    for (const std::size_t bytes : {std::size_t(64), kHuge - 1, kHuge, 3 * kHuge + 5}) {
        std::vector<char, base::HugePageAllocator<char>> v(bytes, 'x');
        if (bytes >= kHuge) {
            EXPECT_EQ(reinterpret_cast<std::uintptr_t>(v.data()) % kHuge, 0u);
        }
        EXPECT_EQ(v.front(), 'x');
        EXPECT_EQ(v.back(), 'x');
    }
    std::vector<double, base::HugePageAllocator<double>> grown;
    for (int i = 0; i < 1 << 20; ++i) grown.push_back(i);  // crosses the 2 MiB threshold
    EXPECT_EQ(grown[123456], 123456.0);
}

// A speed map along x only (ny rows alike): speed(x in mm).
template <class Speed>
Volume speed_profile(int nx, int ny, double h, Speed speed) {
    VolumeGeometry g;
    g.dims = {nx, ny, 1};
    g.spacing = glm::dvec3(h);
    Volume v(g);
    for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) v.at(i, j) = float(speed(i * h));
    return v;
}

TEST(SoftTissueSmoothedIndex, ASheetThinnerThanSigmaKeepsTheGaussianBlurOfItsContrast) {
    // A CSF sheet (1500 m/s) of width w in brain (1560 m/s): the smoothed index at its
    // centre is n_brain + (n_csf - n_brain) erf(w / (2 sqrt(2) sigma)), the Gaussian
    // integral over the sheet; far from it, brain's own index.
    const double h = 0.05, w = 1.0, sigma = 2.0, centre = 15.0;
    const Volume speed = speed_profile(
        601, 3, h, [&](double x) { return std::abs(x - centre) < 0.5 * w ? 1500.0 : 1560.0; });
    const Volume n = soft_tissue_smoothed_index(speed, sigma);
    const double n_brain = kReferenceSpeed / 1560.0, n_csf = kReferenceSpeed / 1500.0;
    // The sheet's width on the grid: its texels times h.
    int texels = 0;
    for (int i = 0; i < 601; ++i) texels += speed.at(i, 1) == 1500.0f;
    const double expected =
        n_brain + (n_csf - n_brain) * std::erf(texels * h / (2.0 * std::sqrt(2.0) * sigma));
    EXPECT_NEAR(n.at(300, 1), expected, 2e-4);  // the Gaussian's sampling at h = sigma / 40
    EXPECT_LT(n.at(300, 1) - n_brain, 0.25 * (n_csf - n_brain));  // a quarter of the jump
    EXPECT_NEAR(n.at(0, 1), n_brain, 1e-6);                       // 7.5 sigma away
}

TEST(SoftTissueSmoothedIndex, BoneAndAirKeepTheirIndexAndDoNotPullTheirNeighbours) {
    // Brain, then bone (3000 m/s) from 10 mm, then air (343 m/s) from 20 mm: outside the
    // soft band both keep c0 / c exactly, and the brain next to the bone keeps brain's
    // index (the normalised convolution leaves the bone out of its average).
    const double h = 0.25;
    const Volume speed = speed_profile(121, 3, h, [](double x) {
        return x < 10.0 ? 1560.0 : x < 20.0 ? 3000.0 : 343.0;
    });
    const Volume n = soft_tissue_smoothed_index(speed, 3.0);
    for (int i = 0; i < 121; ++i) {
        const double expected = kReferenceSpeed / speed.at(i, 1);
        EXPECT_NEAR(n.at(i, 1), expected, 1e-6 * expected) << "x = " << i * h << " mm";
    }
}

TEST(SoftTissueSmoothedIndex, ZeroSigmaOrAUniformMediumChangesNothing) {
    const Volume speed = speed_profile(64, 32, 0.25, [](double x) { return 1540.0 + x; });
    const Volume kept = soft_tissue_smoothed_index(speed, 0.0);
    for (std::size_t v = 0; v < speed.size(); ++v)
        ASSERT_EQ(kept.voxels()[v], float(kReferenceSpeed / speed.voxels()[v]));
    const Volume uniform = speed_profile(64, 32, 0.25, [](double) { return 1560.0; });
    const Volume smoothed = soft_tissue_smoothed_index(uniform, 2.0);
    for (float v : smoothed.voxels()) ASSERT_NEAR(v, kReferenceSpeed / 1560.0, 1e-6);
}

// Brain with bone where `bone(x, y)` (mm) says, on a 2D grid of h = 0.25 mm, as a map of
// the Fresnel-zone normals at sigma (AcousticMap::build's refraction smoothing).
template <class Bone>
AcousticMap<2> bone_in_brain(int nx, int ny, Bone bone, double sigma_mm) {
    VolumeGeometry g;
    g.dims = {nx, ny, 1};
    g.spacing = glm::dvec3(0.25);
    PropertyMaps maps;
    for (Volume& f : maps.fields) f = Volume(g, 0.0f);
    for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
            const bool in_bone = bone(i * 0.25, j * 0.25);
            maps[Property::speed_of_sound].at(i, j) = in_bone ? 3500.0f : 1560.0f;
            maps[Property::density].at(i, j) = in_bone ? 1900.0f : 1040.0f;
        }
    return AcousticMap<2>::build(maps, sigma_mm);
}

glm::vec2 local_normal(const AcousticMap<2>& map, glm::vec2 p) {
    const auto t = map.sample(p);
    return glm::normalize(glm::vec2(t.grad_impedance[0], t.grad_impedance[1]));
}

double degrees_between(glm::vec2 a, glm::vec2 b) {
    return glm::degrees(std::acos(std::clamp(double(glm::dot(a, b)), -1.0, 1.0)));
}

// A bone surface tilted by 12 or 45 degrees as an MRI gives it, in steps of its 1 mm
// voxels: the texels' own normals point along the steps (up to 30-45 degrees off the
// surface's); the zone normal is the surface's, (-sin t, cos t), within 2 degrees (the
// steps' residue over a zone of sigma = 3 mm), with the local normal's sign.
TEST(ZoneNormal, AVoxelStaircaseTurnsToItsPlane) {
    for (const double degrees : {12.0, 45.0}) {
        const double tilt = glm::radians(degrees);
        auto surface_y = [&](double x) {  // the step's middle above 1 mm voxel columns
            return 25.0 + std::floor((std::floor(x) + 0.5 - 30.0) * std::tan(tilt)) + 0.5;
        };
        const auto map = bone_in_brain(
            240, 240, [&](double x, double y) { return y > surface_y(x); }, 3.0);
        const glm::vec2 plane(float(-std::sin(tilt)), float(std::cos(tilt)));
        double worst_local = 0.0, worst_zone = 0.0;
        for (double x = 22.0; x <= 38.0; x += 0.37) {
            const glm::vec2 p{float(x), float(surface_y(x))};
            const glm::vec2 local = local_normal(map, p);
            const glm::vec2 zone = map.zone_normal(p, local);
            worst_local = std::max(worst_local, degrees_between(local, plane));
            worst_zone = std::max(worst_zone, degrees_between(zone, plane));
            ASSERT_GT(glm::dot(zone, local), 0.0f) << "the local normal's sign";
        }
        std::printf(
            "%.0f degree staircase: texels' normals up to %.1f deg off the plane, zone "
            "normals %.2f\n",
            degrees, worst_local, worst_zone);
        EXPECT_GT(worst_local, 10.0) << "the steps should turn the texels' normals";
        EXPECT_LT(worst_zone, 2.0) << degrees;
    }
}

// A plate of bone 1.5 mm thick tilted by 20 degrees (a thin temporal squama): the zone
// normal of each face is the plate's, pointing as that face's own (grad Z into the bone:
// opposite on the two faces), not cancelled by the other face within the zone.
TEST(ZoneNormal, AThinPlateKeepsEachFacesSign) {
    const double tilt = glm::radians(20.0), c = std::cos(tilt), s = std::sin(tilt);
    auto across = [&](double x, double y) { return -s * (x - 30.0) + c * (y - 25.0); };
    const auto map = bone_in_brain(
        240, 200, [&](double x, double y) { return std::abs(across(x, y)) < 0.75; }, 3.0);
    const glm::vec2 plane(float(-s), float(c));
    for (double t = -8.0; t <= 8.0; t += 1.3) {
        for (const double face : {-0.75, 0.75}) {
            const glm::vec2 p(float(30.0 + c * t - s * face), float(25.0 + s * t + c * face));
            const glm::vec2 local = local_normal(map, p);
            const glm::vec2 zone = map.zone_normal(p, local);
            const glm::vec2 expected = face < 0.0 ? plane : -plane;  // into the bone
            EXPECT_LT(degrees_between(zone, expected), 2.0) << "t " << t << ", face " << face;
        }
    }
}

// A bone body smaller than the zone (a disc 1.5 mm across, sigma 3 mm) has no orientation
// of its own at that scale: its texels keep their normals. A map built without smoothing
// has no zone normals at all.
TEST(ZoneNormal, ABodySmallerThanTheZoneAndAnUnsmoothedMapKeepTheirOwnNormals) {
    auto disc = [](double x, double y) { return std::hypot(x - 20.0, y - 20.0) < 0.75; };
    for (const double sigma : {3.0, 0.0}) {
        const auto map = bone_in_brain(160, 160, disc, sigma);
        for (int k = 0; k < 16; ++k) {
            const double a = 2.0 * std::numbers::pi * k / 16.0;
            const glm::vec2 p(float(20.0 + 0.75 * std::cos(a)), float(20.0 + 0.75 * std::sin(a)));
            const glm::vec2 local = local_normal(map, p);
            const glm::vec2 zone = map.zone_normal(p, local);
            EXPECT_EQ(zone, local) << "sigma " << sigma << ", angle " << k;
        }
    }
}

}  // namespace
}  // namespace sonotrace::tissue
