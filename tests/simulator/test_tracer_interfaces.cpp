// The tracer at sharp interfaces against closed forms: what a reflection records (the
// lobe's share, the rough bounces, the shear share past the critical angle), where an
// echo happens, surfaces against a gas, and that a particle enters a gas only by a
// transmission decision. The tracer's other physics: test_tracer.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "simulator/interactions.h"
#include "simulator/trace_setups.h"
#include "simulator/tracer.h"
#include "tests/test_util.h"

namespace sonotrace::simulator {
namespace {

using tissue::AcousticProperties;
using tissue::Property;

constexpr double kH = 0.25;  // mm per texel of the test maps

// A homogeneous medium of nx x ny texels over a half-space of another (speed, density)
// from row `first_row` on: a horizontal interface.
tissue::PropertyMaps over_half_space(int nx, int ny, const AcousticProperties& above, int first_row,
                                     float speed, float density) {
    tissue::PropertyMaps maps = homogeneous(nx, ny, kH, above);
    for (int j = first_row; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
            maps[Property::speed_of_sound].at(i, j) = speed;
            maps[Property::density].at(i, j) = density;
        }
    return maps;
}

// A bone slab (rows 60-99, 3000 m/s) in soft tissue: particles that enter it reflect at
// its floor and again at its roof on the way up, so some echoes follow a reflection.
// Switched off by its row (Physics::bounces), the tracer retires a particle at its first
// reflection, whose echo still counts: every echo then has no reflection before it. The
// switch acts in the tracer itself, not through max_bounces, which stays as set.
TEST(Tracer, WithBouncesOffEveryEchoIsAFirstReflection) {
    tissue::PropertyMaps maps =
        over_half_space(80, 161, lossless_medium(1540, 1000), 60, 3000.0f, 1900.0f);
    for (int j = 100; j < 161; ++j)
        for (int i = 0; i < 80; ++i) {
            maps[Property::speed_of_sound].at(i, j) = 1540.0f;
            maps[Property::density].at(i, j) = 1000.0f;
        }
    const auto map = tissue::AcousticMap<2>::build(maps);
    const Sources<2> src = parallel_beam({10.0f, 0.5f}, {0.0f, 1.0f}, 4.0f, 2000);
    auto deepest_echo = [&](bool bounces) {
        TraceSettings s;
        s.physics.set(Physics::attenuation, false);
        s.physics.set(Physics::scattering, false);
        s.physics.set(Physics::bounces, bounces);
        s.roulette_energy = 0.0;
        const auto r = trace(map, src, s);
        EXPECT_EQ(s.max_bounces, 64);
        int most = 0, echoes = 0;
        for (const auto& e : r.echoes) {
            most = std::max(most, int(e.bounces));
            ++echoes;
        }
        EXPECT_GT(echoes, 100);
        return most;
    };
    EXPECT_GE(deepest_echo(true), 1);
    EXPECT_EQ(deepest_echo(false), 0);
}

TEST(Tracer, AnEchoThroughARoughReflectionReturnsTheLobesShare) {
    // Particles run down onto a rough horizontal interface (roughness 0.5: lobe cos^3),
    // reflect with probability R^2 into the lobe and scatter in the medium above. By
    // reciprocity those echoes go back through the same reflection, which sends towards
    // the way the particle came only the share of its lobe within the receive's
    // half-angle delta: for a particle leaving at phi from the mirror direction (straight
    // up), the Gaussian form of the lobe, sigma = 1 / sqrt(3), integrated over
    // [phi - delta, phi + delta], written out here with erfc. Each scatter echo after the
    // reflection must carry R^2 (the reflection's own echo weight) times that share in
    // its return weight; without the setting, R^2 alone.
    tissue::PropertyMaps maps =
        over_half_space(80, 161, lossless_medium(1540, 1000), 80, 3000.0f, 1900.0f);
    for (float& r : maps[Property::roughness].voxels()) r = 0.5f;
    for (float& b : maps[Property::backscatter].voxels()) b = 0.5f;
    const auto map = tissue::AcousticMap<2>::build(maps);
    TraceSettings s;
    s.physics.set(Physics::attenuation, false);
    s.roulette_energy = 0.0;
    s.record_paths = 0;
    constexpr double kDelta = 0.2;
    const Sources<2> src = parallel_beam({10.0f, 0.5f}, {0.0f, 1.0f}, 4.0f, 400);
    for (const double delta : {0.0, kDelta}) {
        s.diffuse_return_half_angle_rad = delta;
        const auto r = trace(map, src, s);
        std::map<uint32_t, const EchoEvent<2>*> reflection;  // by particle
        for (const auto& e : r.echoes)
            if (e.kind == EchoKind::diffuse && e.bounces == 0) reflection[e.particle] = &e;
        int checked = 0;
        for (const auto& e : r.echoes) {
            if (e.kind != EchoKind::scatter || e.bounces != 1 || !reflection.count(e.particle))
                continue;
            const EchoEvent<2>& at = *reflection[e.particle];
            ASSERT_NEAR(at.lobe_exponent, 3.0f, 1e-4f);
            const double phi = std::acos(std::clamp(double(-e.direction.y), -1.0, 1.0));
            const double sigma = 1.0 / std::sqrt(3.0);
            auto cdf = [](double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); };
            const double share =
                delta > 0.0 ? cdf((delta - phi) / sigma) - cdf((-delta - phi) / sigma) : 1.0;
            EXPECT_NEAR(e.return_weight, double(at.weight) * share, 1e-4 * at.weight)
                << "phi " << phi;
            ++checked;
        }
        EXPECT_GT(checked, 20) << "delta " << delta;
    }
}

// A gas takes the shape of the surface it meets, and the skin's relief lies below the
// Rayleigh criterion: a rough tissue (roughness 0.5, lobe cos^3) over air (343 m/s,
// 1.2 kg/m^3) reflects as a mirror (every reflection echo specular, the particles back
// up along the normal to float rounding), over bone (3000 m/s) into its lobe (diffuse,
// exponent 3). Air's R^2 at normal incidence is 0.9989: the reflections are nearly all
// the particles.
TEST(Tracer, ASurfaceAgainstAGasIsAMirrorWhateverItsRoughness) {
    for (const bool gas : {true, false}) {
        tissue::PropertyMaps maps = over_half_space(80, 161, lossless_medium(1540, 1000), 80,
                                                    gas ? 343.0f : 3000.0f, gas ? 1.2f : 1900.0f);
        for (float& r : maps[Property::roughness].voxels()) r = 0.5f;
        const auto map = tissue::AcousticMap<2>::build(maps);
        TraceSettings s;
        s.physics.set(Physics::attenuation, false);
        s.physics.set(Physics::scattering, false);
        s.roulette_energy = 0.0;
        s.record_paths = 400;
        const Sources<2> src = parallel_beam({10.0f, 0.5f}, {0.0f, 1.0f}, 4.0f, 400);
        const auto r = trace(map, src, s);
        int specular = 0, diffuse = 0;
        for (const auto& e : r.echoes) {
            if (e.bounces != 0) continue;
            if (e.kind == EchoKind::specular) ++specular;
            if (e.kind == EchoKind::diffuse) {
                ++diffuse;
                EXPECT_NEAR(e.lobe_exponent, 3.0f, 1e-4f);
            }
        }
        EXPECT_EQ(gas ? diffuse : specular, 0) << (gas ? "air" : "bone");
        EXPECT_GT(gas ? specular : diffuse, 300) << (gas ? "air" : "bone");
        if (!gas) continue;
        int mirrored = 0;  // paths whose last leg runs straight back up
        for (const auto& path : r.paths) {
            if (path.vertices.size() < 3) continue;
            const glm::vec2 a = path.vertices[path.vertices.size() - 2].position,
                            b = path.vertices.back().position;
            if (!(b.y < a.y)) continue;
            const glm::vec2 d = glm::normalize(b - a);
            EXPECT_NEAR(d.x, 0.0f, 1e-3f);
            ++mirrored;
        }
        EXPECT_GT(mirrored, 300);
    }
}

// Echoes count the reflections taken into a rough lobe (EchoEvent::rough_bounces, after
// which the image draws them as incoherent clutter): over rough bone every reflection is
// one, over air (a mirror whatever its roughness) none. The medium scatters, so each path
// leaves echoes after its reflections too.
TEST(Tracer, EchoesCountTheReflectionsTakenIntoARoughLobe) {
    for (const bool gas : {true, false}) {
        tissue::PropertyMaps maps = over_half_space(80, 161, lossless_medium(1540, 1000), 80,
                                                    gas ? 343.0f : 3000.0f, gas ? 1.2f : 1900.0f);
        for (float& r : maps[Property::roughness].voxels()) r = 0.5f;
        for (float& b : maps[Property::backscatter].voxels()) b = 1.0f;
        const auto map = tissue::AcousticMap<2>::build(maps);
        TraceSettings s;
        s.mode = PhysicsMode::acoustic;
        s.physics.set(Physics::attenuation, false);
        s.physics.set(Physics::scattering, true);
        s.scatter_echo_fraction = 1e-6;
        s.roulette_energy = 0.0;
        const auto r = trace(map, parallel_beam({10.0f, 0.5f}, {0.0f, 1.0f}, 4.0f, 400), s);
        int after_bounces = 0;
        for (const auto& e : r.echoes) {
            if (e.bounces == 0) {
                EXPECT_EQ(e.rough_bounces, 0);
                continue;
            }
            ++after_bounces;
            EXPECT_EQ(int(e.rough_bounces), gas ? 0 : int(e.bounces)) << (gas ? "air" : "bone");
        }
        EXPECT_GT(after_bounces, 100) << (gas ? "air" : "bone");
    }
}

// Soft tissue (1540 m/s, 1060 kg/m^3) over bone (3500 m/s, 1900 kg/m^3; shear
// kShearToLongitudinalSpeed x 3500 m/s), particles meeting the flat interface at 40
// degrees: past the longitudinal critical angle (26.1), short of the shear one (56.1).
// Brekhovskikh's fractions there (evaluated separately in Python's complex arithmetic;
// FluidSolid tests the formula): 0.186 reflects, 0.814 converts into the bone's shear
// wave, none goes on as its longitudinal wave. Each reflection echo carries 0.186; of
// 2000 particles that share reflects (binomial sigma 0.0087: 4 sigma allowed), and the
// rest is absorbed where it converts, none entering the bone (no other loss is on: to a
// particle or two in 2000, whose incidence the tracer reads as grazing). With
// the conversion off the interface is a fluid's: all reflect.
TEST(Tracer, BoneMetPastItsCriticalAngleTakesTheShearShare) {
    const auto map = tissue::AcousticMap<2>::build(
        over_half_space(240, 161, lossless_medium(1540, 1060), 80, 3500.0f, 1900.0f));
    TraceSettings s;
    s.physics.set(Physics::attenuation, false);
    s.physics.set(Physics::scattering, false);
    s.roulette_energy = 0.0;
    s.record_paths = 0;
    const float angle = 40.0f * std::numbers::pi_v<float> / 180.0f;
    const Sources<2> src =
        parallel_beam({8.0f, 4.0f}, {std::sin(angle), std::cos(angle)}, 2.0f, 2000);
    for (const bool conversion : {true, false}) {
        s.physics.set(Physics::shear, conversion);
        const auto r = trace(map, src, s);
        int reflections = 0, at_the_share = 0;
        for (const auto& e : r.echoes) {
            if (e.kind == EchoKind::scatter || e.bounces != 0) continue;
            at_the_share += std::abs(e.weight - (conversion ? 0.18596f : 1.0f)) < 2e-3f;
            ++reflections;
        }
        // The incidence is read from the particle's direction in the interface's fringe,
        // which a rare particle gets wrong (taken as grazing: reflects all).
        EXPECT_GE(at_the_share, reflections - reflections / 200);
        ASSERT_GT(reflections, 1900) << "each particle meets the interface once first";
        const double reflected = double(r.stats.reflections) / 2000.0;
        if (conversion) {
            EXPECT_NEAR(reflected, 0.18596, 0.035);
            EXPECT_NEAR(r.ledger.absorbed / r.ledger.injected, 1.0 - reflected, 1e-3);
        } else {
            EXPECT_EQ(r.stats.reflections, 2000u);
            EXPECT_NEAR(r.ledger.absorbed, 0.0, 1e-9);
        }
    }
}

// A reflection happens where the particle's own path crosses the interface. Particles
// run down 0.2-0.45 mm beside the side wall of a step (the choroid plexus's shape in the
// default head): the wall's gradient starts the interface search 2 mm before the face
// their path meets, and the search walks across the path to the wall. Timed there, with
// the Fresnel zone's normal facing them, their echoes came up to 2 mm early, inside the
// CSF. Geometry gives the answer: each first echo where the path meets the face, y = 21 mm
// (within a texel: the step sits between texel centres), at the time of its 16 mm of path
// through the CSF; and the face's R^2 at normal incidence.
TEST(Tracer, AnEchoHappensWhereThePathMeetsTheFaceNotBesideAWall) {
    const AcousticProperties csf = lossless_medium(1515, 1007),
                             plexus = lossless_medium(1580, 1037);
    tissue::PropertyMaps maps = homogeneous(161, 161, kH, csf);
    for (int j = 0; j < 161; ++j)
        for (int i = 0; i < 161; ++i)
            if (j * kH >= 21.0 || (i * kH >= 10.0 && j * kH >= 19.0))  // a face; a step on it
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                    maps.fields[f].at(i, j) = plexus.values[f];
    const double fresnel_mm = 3.0;  // the convex probe's: zone normals on
    const auto map = tissue::AcousticMap<2>::build(maps, fresnel_mm);
    TraceSettings s = interfaces_only_settings();
    s.step_texels = 1.0;
    Sources<2> src;
    for (int k = 0; k < 6; ++k)
        src.push_back({glm::vec2(9.55f + 0.05f * float(k), 5.0f), glm::vec2(0.0f, 1.0f), 1.0f, 0});
    const auto r = trace(map, src, s);
    const double z_csf = 1515.0 * 1007.0, z_plexus = 1580.0 * 1037.0;
    const double r2 = std::pow((z_plexus - z_csf) / (z_plexus + z_csf), 2.0);
    const double seconds_per_mm_csf = 1e-3 / 1515.0;
    std::vector<bool> seen(src.size(), false);
    for (const auto& e : r.echoes) {
        if (e.kind == EchoKind::scatter || e.bounces != 0 || seen[e.particle]) continue;
        seen[e.particle] = true;
        EXPECT_NEAR(e.position.y, 21.0, kH) << "particle " << e.particle;
        EXPECT_NEAR(e.position.x, src[e.particle].position.x, 0.05) << "particle " << e.particle;
        EXPECT_NEAR(e.time_s, 16.0 * seconds_per_mm_csf, kH * seconds_per_mm_csf);
        EXPECT_NEAR(e.weight, r2, 0.02 * r2);
    }
    for (std::size_t k = 0; k < src.size(); ++k) EXPECT_TRUE(seen[k]) << "particle " << k;
}

// The receive weights' column is found by a multiply: it must be floor(t / bin_s),
// clamped, the division's, except within a few ulps of a column's edge, where the two
// roundings may disagree by one column; it never decreases with t (an echo profile's
// steps walk the row forward), and NaN gives column 0.
// A particle enters a gas only by a transmission decision, which multiplies its return
// weight by 1 - R^2 (about 1e-3 between tissue and air at normal incidence, less
// obliquely). A 3 mm air gap (x 18-21 mm) in tissue; particles start in the fringe of the
// gap's right wall, on the tissue side, heading every way (fixed angles): those heading
// away from the gap meet the fringe from behind. Every reflection met from inside the gap
// (its normal, which faces the particle's side, points into the gap) must carry a return
// weight of at most 0.01: a particle that slipped in without a decision carries its full
// weight and bounces between the walls at R^2 = 1, as particles did in the gap beside the
// temporal view's probe.
TEST(Tracer, ParticlesEnterAGasOnlyByATransmissionDecision) {
    constexpr int kN = 160;
    tissue::PropertyMaps maps = homogeneous(kN, kN, kH, lossless_medium(1540, 1000));
    const AcousticProperties air = lossless_medium(343, 1.2);
    for (int j = 0; j < kN; ++j)
        for (int i = 72; i < 84; ++i) {  // x = 18.0 to 20.75 mm
            maps[Property::speed_of_sound].at(i, j) = air[Property::speed_of_sound];
            maps[Property::density].at(i, j) = air[Property::density];
        }
    const auto map = tissue::AcousticMap<2>::build(maps);
    TraceSettings s = interfaces_only_settings();
    Sources<2> sources;
    int index = 0;
    for (int start = 0; start < 8; ++start)
        for (int a = 0; a < 64; ++a) {
            const float angle = 2.0f * std::numbers::pi_v<float> * (float(a) + 0.5f) / 64.0f;
            sources.push_back({glm::vec2(20.85f + 0.1f * float(start), 20.0f + 0.3f * float(a % 8)),
                               glm::vec2(std::cos(angle), std::sin(angle)), 1.0f,
                               uint32_t(index++ / 64)});
        }
    const auto r = trace(map, sources, s);
    int from_inside = 0, reflections = 0;
    for (const auto& e : r.echoes) {
        if (e.kind != EchoKind::specular) continue;
        ++reflections;
        const bool left_wall = std::abs(e.position.x - 18.0f) < 1.0f;
        const bool right_wall = std::abs(e.position.x - 20.75f) < 1.0f;
        const bool into_gap =
            (left_wall && e.normal.x > 0.5f) || (right_wall && e.normal.x < -0.5f);
        if (!into_gap) continue;
        ++from_inside;
        EXPECT_LE(e.return_weight, 0.01f)
            << "particle " << e.particle << " of line " << e.line << " at (" << e.position.x << ", "
            << e.position.y << "), " << e.bounces << " reflections before";
    }
    EXPECT_GT(reflections, 200) << "the particles must meet the wall";
    ::testing::Test::RecordProperty("reflections_from_inside", from_inside);
}

}  // namespace
}  // namespace sonotrace::simulator
