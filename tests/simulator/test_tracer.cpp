// The particle tracer against closed-form physics: exponential attenuation, unbiased roulette, the
// energy ledger, 3D refraction, byte-identical results on 1 and 2 threads, and bad settings.
// Snell's law, the critical angle, the reflected fraction against the angle, reverberation and the
// fibre guide of figure 4 are cases of the validation suite (phantoms/validation, run by
// test_validation).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <random>

#include "simulator/batch.h"
#include "simulator/interactions.h"
#include "simulator/trace_setups.h"
#include "simulator/tracer.h"
#include "tests/test_util.h"
#include "tissue/tissue_table.h"

namespace sonotrace::simulator {
namespace {

using tissue::AcousticProperties;
using tissue::Property;

constexpr double kH = 0.25;  // mm per texel of the test maps

TEST(Tracer, HomogeneousAttenuationIsExponential) {
    // alpha = 0.5 dB/(cm MHz), f = 5 MHz: intensity falls as exp(-2 alpha_Np f d) with
    // alpha_Np = alpha / 8.686 per cm. Particles run straight down a 60 mm column.
    AcousticProperties p = lossless_medium(1540, 1000);
    p[Property::attenuation] = 0.5f;
    const auto map = tissue::AcousticMap<2>::build(homogeneous(40, 241, kH, p));
    TraceSettings s = interfaces_only_settings();
    s.frequency_mhz = 5.0;
    s.physics.set(Physics::attenuation, true);
    const auto result = trace(map, parallel_beam({5.0f, 0.0f}, {0.0f, 1.0f}, 4.0f, 50), s);
    // Each particle crosses the 60 mm domain (rows 0..240); it is still inside at exactly
    // 60 mm, so it leaves after floor(60 / s) + 1 steps.
    const double step = s.step_texels * kH;
    const double travelled = (std::floor(60.0 / step + 1e-9) + 1.0) * step;
    const double expected = std::exp(-2.0 * (0.5 / 8.685889638) * 5.0 * travelled / 10.0);
    // Float energies over 481 multiplications: relative rounding ~481 * 6e-8 = 3e-5.
    EXPECT_NEAR(result.ledger.escaped / result.ledger.injected, expected, 5e-5 * expected);
    // The fluence along depth follows the same law (row 0 is only half crossed: the
    // particles start on it, so rows are compared with row 8).
    const tissue::Volume& f = result.fluence;
    for (int j : {40, 120, 200}) {
        const double ratio = double(f.at(20, j)) / f.at(20, 8);
        EXPECT_NEAR(ratio, std::exp(-2.0 * (0.5 / 8.685889638) * 5.0 * ((j - 8) * kH) / 10.0), 1e-3)
            << "row " << j;
    }
}

TEST(Tracer, EnergyLedgerBalancesToOnePartPerMillion) {
    // Everything on: attenuation, scattering, interfaces with diffuse lobes, roulette,
    // a capturing probe face; a random smooth medium.
    const double h = 0.25;
    tissue::PropertyMaps maps =
        homogeneous(200, 200, h, tissue::find_tissue("soft_tissue", "", "").properties);
    for (int j = 0; j < 200; ++j) {
        for (int i = 0; i < 200; ++i) {
            const double r = glm::length(glm::dvec2(i, j) * h - glm::dvec2(25, 28));
            const double blob = std::clamp((8.0 - r) / (2 * h) + 0.5, 0.0, 1.0);
            maps[Property::speed_of_sound].at(i, j) += float(blob * 1900.0);
            maps[Property::density].at(i, j) += float(blob * 800.0);
            maps[Property::roughness].at(i, j) = float(0.2 + 0.3 * blob);
        }
    }
    const auto map = tissue::AcousticMap<2>::build(maps);
    TraceSettings s;  // defaults: all physics on
    s.roulette_energy = 0.05;
    ProbeFace<2> face;
    face.centre = {25.0f, 0.5f};
    face.normal = {0.0f, 1.0f};
    face.half_width_mm = 10.0f;
    face.reflectivity = 0.3f;
    s.probe_face_2d = face;
    Sources<2> src;
    for (int line = 0; line < 8; ++line) {
        auto beam = fan_beam({25.0f, 0.6f}, {0.0f, 1.0f}, 25.0f, 200, uint32_t(line));
        src.insert(src.end(), beam.begin(), beam.end());
    }
    const auto result = trace(map, src, s);
    const EnergyLedger& l = result.ledger;
    EXPECT_NEAR(l.relative_error(), 0.0, 1e-6);
    EXPECT_GT(l.absorbed, 0.0);
    EXPECT_GT(l.escaped, 0.0);
    EXPECT_GT(l.recorded, 0.0);
    EXPECT_GT(l.roulette_killed, 0.0);
    EXPECT_GT(result.stats.captured, 0u);
    EXPECT_GT(result.stats.reflections, 0u);
    // The absorbed map holds the absorbed energy (64-bit fixed point, per texel rounding).
    double map_total = 0.0;
    for (float v : result.absorbed.voxels()) map_total += v;
    EXPECT_NEAR(map_total, l.absorbed, 1e-6 * l.injected);

    // Without the maps: the same paths (deposits draw no random numbers), the balance
    // still closes, the absorbed energy is the same up to the order of its sum.
    s.deposition_maps = false;
    const auto unmapped = trace(map, src, s);
    EXPECT_NEAR(unmapped.ledger.relative_error(), 0.0, 1e-6);
    EXPECT_NEAR(unmapped.ledger.absorbed, l.absorbed, 1e-6 * l.injected);
    EXPECT_EQ(unmapped.ledger.escaped, l.escaped);
    EXPECT_EQ(unmapped.stats.steps, result.stats.steps);
    EXPECT_TRUE(unmapped.absorbed.voxels().empty());
    EXPECT_TRUE(unmapped.fluence.voxels().empty());
}

// A homogeneous absorbing column without scattering or interfaces, 10 x 60 mm, and 40
// lines of 500 particles down it: each escapes with exp(-2 alpha_Np f L) exactly, L the
// path of its whole steps (`exact`).
struct AbsorbingColumn {
    tissue::AcousticMap<2> map;
    Sources<2> sources;
    TraceSettings settings;
    double exact = 0.0;
};
AbsorbingColumn absorbing_column(float attenuation_db_per_cm_mhz) {
    AbsorbingColumn c;
    AcousticProperties p = lossless_medium(1540, 1000);
    p[Property::attenuation] = attenuation_db_per_cm_mhz;
    c.map = tissue::AcousticMap<2>::build(homogeneous(40, 241, kH, p));
    c.settings = interfaces_only_settings();
    c.settings.physics.set(Physics::attenuation, true);
    c.settings.record_paths = 0;
    for (int line = 0; line < 40; ++line) {
        auto beam = parallel_beam({5.0f, 0.0f}, {0.0f, 1.0f}, 4.0f, 500, uint32_t(line));
        c.sources.insert(c.sources.end(), beam.begin(), beam.end());
    }
    const double step = c.settings.step_texels * kH;
    c.exact = std::exp(-2.0 * (attenuation_db_per_cm_mhz / 8.685889638) * c.settings.frequency_mhz *
                       (std::floor(60.0 / step + 1e-9) + 1.0) * step / 10.0);
    return c;
}

TEST(Tracer, RussianRouletteIsUnbiased) {
    // The absorbing column: the only randomness is roulette. With an aggressive threshold
    // (0.3) the mean escaped energy must equal the exact one within 3 standard errors
    // (sample variance of 20000 independent particles).
    const AbsorbingColumn column = absorbing_column(0.5f);
    const auto& [map, src, settings, exact] = column;
    TraceSettings s = settings;
    s.roulette_energy = 0.3;
    // Each particle's escaped energy X lies in [0, 0.6] (a survivor restarts at twice the
    // threshold and only decays), so Var(X) <= E[X^2] <= 0.6 E[X]: the standard error of
    // the mean is at most sqrt(0.6 * exact / n).
    const auto result = trace(map, src, s);
    const double n = double(src.size());
    const double mean = result.ledger.escaped / n;
    const double sigma = std::sqrt(0.6 * exact / n);
    EXPECT_NEAR(mean, exact, 3.0 * sigma) << "roulette killed " << result.ledger.roulette_killed;
    EXPECT_GT(result.ledger.roulette_killed, 0.1 * n * 0.3) << "the test must exercise roulette";
    EXPECT_NEAR(result.ledger.relative_error(), 0.0, 1e-6);
}

// The roulette's threshold can follow a nominal loss with the particle's time
// (TraceSettings::roulette_loss_db_per_mm; frames follow the automatic TGC's, so that a
// particle deep in the frame is not ended for being weak). A column losing 1 dB/mm (2
// dB/(cm MHz) at 5 MHz), 60 mm long, energies known in closed form as above:
// - a fixed threshold (1e-3) ends particles 30 dB down, half-way along;
// - following the column's own loss, no particle ever falls below the threshold: none is
//   rouletted, and each escapes with the exact energy;
// - following half of it with an aggressive threshold (0.3), roulette runs all along and
//   the mean escaped energy is the exact one within 3 standard errors (a survivor restarts
//   at twice the threshold and only decays, so X <= 0.6 x the followed decay at the exit,
//   30 dB: Var(X) <= 6e-4 E[X]).
TEST(Tracer, TheRouletteFollowsTheNominalLoss) {
    const AbsorbingColumn column = absorbing_column(2.0f);
    const auto& [map, src, settings, exact] = column;
    TraceSettings s = settings;
    s.roulette_energy = 1e-3;
    const double n = double(src.size());
    const auto fixed = trace(map, src, s);
    EXPECT_GT(fixed.ledger.roulette_killed, 0.0);

    s.roulette_loss_db_per_mm = 2.0 * s.frequency_mhz / 10.0;
    const auto following = trace(map, src, s);
    EXPECT_EQ(following.ledger.roulette_killed, 0.0);
    EXPECT_EQ(following.ledger.roulette_added, 0.0);
    EXPECT_NEAR(following.ledger.escaped / n, exact, 1e-3 * exact);

    s.roulette_loss_db_per_mm *= 0.5;
    s.roulette_energy = 0.3;
    const auto half = trace(map, src, s);
    const double sigma = std::sqrt(0.6 * 1e-3 * exact / n);
    EXPECT_NEAR(half.ledger.escaped / n, exact, 3.0 * sigma);
    EXPECT_GT(half.ledger.roulette_killed, 0.0) << "the test must exercise roulette";
    EXPECT_NEAR(half.ledger.relative_error(), 0.0, 1e-6);
}

TEST(Tracer, RouletteKeepsTheTwoWayEchoUnbiased) {
    // The scattered echo of a step goes as E^2 / E0 (the energy that arrives times the
    // same loss on the way back). Roulette raises a survivor's E by 1 / (its survival
    // probability); the echo stays unbiased only if the way back keeps the loss before the
    // raise (the survival probability joins the return factor). Homogeneous scattering
    // and absorbing column: the echo profile beyond 30 mm (where every particle has met
    // roulette at 0.3: exp(-0.576 / cm x 21 mm) = 0.3) against the same trace without
    // roulette, over 20000 particles: within 5 % (the standard error of the mean of
    // per-particle sums of relative spread about 1 is 0.7 %); with a roulette-raised E^2
    // it read 4.06 times as much.
    AcousticProperties p = lossless_medium(1540, 1000);
    p[Property::attenuation] = 0.5f;
    p[Property::backscatter] = 1.0f;
    const auto map = tissue::AcousticMap<2>::build(homogeneous(40, 241, kH, p));
    TraceSettings s = interfaces_only_settings();
    s.mode = PhysicsMode::acoustic;
    s.physics.set(Physics::attenuation, true);
    s.physics.set(Physics::scattering, true);
    s.scatter_echo_fraction = 1e-6;  // scattering events take next to nothing
    s.record_paths = 0;
    const double bin_s = 1e-7;
    s.echo_profile = EchoProfileSettings{bin_s, 1000};
    Sources<2> src;
    for (int line = 0; line < 40; ++line) {
        auto beam = parallel_beam({5.0f, 0.0f}, {0.0f, 1.0f}, 4.0f, 500, uint32_t(line));
        src.insert(src.end(), beam.begin(), beam.end());
    }
    auto late_echo = [&](double roulette) {
        s.roulette_energy = roulette;
        const auto r = trace(map, src, s);
        const int first = int(2.0 * 30e-3 / 1540.0 / bin_s);  // echo time of 30 mm
        double sum = 0.0;
        for (int l = 0; l < r.echo_profile.lines; ++l)
            for (int i = first; i < r.echo_profile.bins; ++i) sum += r.echo_profile.at(l, i);
        return std::pair{sum, r.ledger.roulette_killed};
    };
    const auto [exact, none_killed] = late_echo(1e-12);
    const auto [with_roulette, killed] = late_echo(0.3);
    EXPECT_EQ(none_killed, 0.0);
    EXPECT_GT(killed, 0.0) << "the test must exercise roulette";
    ASSERT_GT(exact, 0.0);
    EXPECT_NEAR(with_roulette / exact, 1.0, 0.05);
}

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
TEST(ReceiveWeights, ColumnIsTheDivisionsFloorAwayFromEdgesAndMonotonic) {
    auto by_division = [](const ReceiveWeights& w, double t) {
        const double u = t / w.bin_s;
        return u <= 0.0 ? 0 : (u >= double(w.bins) ? w.bins - 1 : int(u));
    };
    std::mt19937_64 rng(7);
    long checked = 0, off_by_one = 0;
    for (double bin_s : {0.25e-3 / 1540.0, 1e-7, 3.3e-8, 1.0 / 3.0}) {
        ReceiveWeights w;
        w.set_bin_s(bin_s);
        w.bins = 400;
        std::uniform_real_distribution<double> anywhere(-bin_s, 410.0 * bin_s);
        for (int n = 0; n < 200000; ++n, ++checked) {
            const double t = anywhere(rng);
            const double u = t / bin_s;
            if (std::abs(u - std::round(u)) < 1e-9 * std::max(1.0, std::abs(u))) continue;
            ASSERT_EQ(w.column(t), by_division(w, t)) << "t = " << t;
        }
        for (int k = 0; k <= 401; ++k) {  // each edge k bin_s and its neighbours
            double t = double(k) * bin_s;
            for (int ulp = 0; ulp < 4; ++ulp) t = std::nextafter(t, 0.0);
            int previous = w.column(t);
            for (int step = 0; step < 9; ++step, ++checked) {
                const int c = w.column(t);
                ASSERT_LE(std::abs(c - by_division(w, t)), 1) << "edge " << k << ", t = " << t;
                ASSERT_GE(c, previous) << "edge " << k << ", t = " << t;
                off_by_one += c != by_division(w, t);
                previous = c;
                t = std::nextafter(t, 1.0);
            }
        }
        EXPECT_EQ(w.column(-1.0), 0);
        EXPECT_EQ(w.column(1e9 * bin_s), w.bins - 1);
        EXPECT_EQ(w.column(std::numeric_limits<double>::quiet_NaN()), 0);
    }
    EXPECT_GT(checked, 800000);
    EXPECT_LT(off_by_one, checked / 1000) << "off by one column only right at edges";
}

TEST(TracerErrors, BadSettingsAndSourcesAreNamed) {
    const auto map =
        tissue::AcousticMap<2>::build(homogeneous(10, 10, 1.0, lossless_medium(1540, 1000)));
    TraceSettings s;
    s.step_texels = 0.0;
    test::expect_input_error([&] { trace(map, Sources<2>{}, s); }, "trace settings", "step");
    s = TraceSettings{};
    s.frequency_mhz = std::nan("");
    test::expect_input_error([&] { trace(map, Sources<2>{}, s); }, "trace settings", "frequency");
    Sources<2> bad = {{{1.0f, 1.0f}, {0.0f, 0.0f}, 1.0f, 0}};
    test::expect_input_error([&] { trace(map, bad, TraceSettings{}); }, "sources",
                             "sources[0].direction");
    bad = {{{1.0f, std::nanf("")}, {0.0f, 1.0f}, 1.0f, 0}};
    test::expect_input_error([&] { trace(map, bad, TraceSettings{}); }, "sources", "sources[0]",
                             "finite");
}

}  // namespace
}  // namespace sonotrace::simulator

namespace sonotrace::simulator {
namespace {

// 3D: the same template on a volume. A plane tilted about two axes, smoothed over 2 texels.
tissue::AcousticMap<3> interface_map_3d(float c1, float c2, glm::dvec3 normal, double h = 0.25,
                                        int n = 96) {
    tissue::VolumeGeometry g;
    g.dims = {n, n, n};
    g.spacing = glm::dvec3(h);
    tissue::PropertyMaps maps;
    const auto a = lossless_medium(c1, 1000), b = lossless_medium(c2, 1000);
    for (tissue::Volume& f : maps.fields) f = tissue::Volume(g);
    const glm::dvec3 centre(0.5 * (n - 1) * h);
    normal = glm::normalize(normal);
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const double d = glm::dot(glm::dvec3(i, j, k) * h - centre, normal);
                const auto p = tissue::lerp(a, b, float(std::clamp(d / (2 * h) + 0.5, 0.0, 1.0)));
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                    maps.fields[f].at(i, j, k) = p.values[f];
            }
    return tissue::AcousticMap<3>::build(maps);
}

TEST(Tracer3D, RefractionFollowsSnellWithinHalfADegree) {
    const glm::dvec3 normal = glm::normalize(glm::dvec3(0.25, 1.0, 0.15));
    const auto map = interface_map_3d(1500, 1800, normal);
    const glm::dvec3 centre(0.5 * 95 * 0.25);
    TraceSettings s = interfaces_only_settings();
    s.physics.set(Physics::specular, false);
    s.record_paths = 1;
    s.max_path_mm = 18.0;
    glm::vec3 b1, b2;
    orthonormal_basis(glm::vec3(normal), &b1, &b2);
    for (double incidence = 5.0; incidence <= 45.0; incidence += 10.0) {
        const double a = glm::radians(incidence);
        const glm::dvec3 tangent = glm::normalize(glm::dvec3(b1) + 0.5 * glm::dvec3(b2));
        const glm::dvec3 dir = std::cos(a) * normal + std::sin(a) * tangent;
        const Sources<3> src = {{glm::vec3(centre - 9.0 * dir), glm::vec3(dir), 1.0f, 0}};
        const auto result = trace(map, src, s);
        const auto& v = result.paths.at(0).vertices;
        const glm::vec3 out = glm::normalize(v.back().position - v[v.size() - 9].position);
        const double measured =
            glm::degrees(std::acos(std::abs(glm::dot(glm::dvec3(out), normal))));
        const double expected = glm::degrees(std::asin(std::sin(a) * 1800.0 / 1500.0));
        EXPECT_NEAR(measured, expected, 0.5) << "incidence " << incidence;
        // Snell keeps the ray in the plane of incidence.
        EXPECT_NEAR(glm::dot(glm::dvec3(out), glm::cross(normal, tangent)), 0.0, 0.01);
    }
}

TEST(Tracer, RefractionThroughASmoothedSoftInterfaceFollowsSnell) {
    // An extended soft-tissue interface (1480 -> 1650 m/s, tilted 20 degrees to the grid)
    // with the index smoothed at sigma = 2 mm (tissue::soft_tissue_smoothed_index): n
    // sin(theta) is conserved through a graded planar layer, so the ray leaves the
    // transition at Snell's angle, as at the sharp interface.
    const double h = 0.125, sigma = 2.0;
    const int n = 401;
    const glm::dvec2 normal =
        glm::normalize(glm::dvec2(std::sin(glm::radians(20.0)), std::cos(glm::radians(20.0))));
    const glm::dvec2 centre(0.5 * (n - 1) * h);
    const tissue::PropertyMaps maps = planar_interface(
        n, n, h, centre, normal, lossless_medium(1480, 1000), lossless_medium(1650, 1000), 1.0);
    const auto map = tissue::AcousticMap<2>::build(maps, sigma);
    TraceSettings s = interfaces_only_settings();
    s.physics.set(Physics::specular, false);
    s.record_paths = 1;
    s.max_path_mm = 44.0;
    const glm::dvec2 tangent(normal.y, -normal.x);
    for (double incidence = 10.0; incidence <= 50.0; incidence += 20.0) {
        const double a = glm::radians(incidence);
        const glm::dvec2 dir = std::cos(a) * normal + std::sin(a) * tangent;
        const Sources<2> src = {{glm::vec2(centre - 22.0 * dir), glm::vec2(dir), 1.0f, 0}};
        const auto result = trace(map, src, s);
        const auto& v = result.paths.at(0).vertices;
        // The last 2 mm, beyond 4 sigma of the transition.
        const glm::dvec2 out =
            glm::normalize(glm::dvec2(v.back().position - v[v.size() - 17].position));
        const double measured = glm::degrees(std::acos(std::abs(glm::dot(out, normal))));
        const double expected = glm::degrees(std::asin(std::sin(a) * 1650.0 / 1480.0));
        EXPECT_NEAR(measured, expected, 0.5) << "incidence " << incidence;
    }
}

TEST(Tracer3D, LedgerBalancesAndThreadsAgree) {
    const auto map = interface_map_3d(1540, 2200, glm::dvec3(0.2, 1.0, 0.1), 0.5, 48);
    TraceSettings s;  // all physics
    s.roulette_energy = 0.05;
    Sources<3> src;
    for (int line = 0; line < 6; ++line) {
        auto beam = fan_beam_3d({12.0f, 0.2f, 12.0f}, {0.1f * line - 0.25f, 1.0f, 0.0f}, 15.0f, 8,
                                uint32_t(line));
        src.insert(src.end(), beam.begin(), beam.end());
    }
    auto run = [&](int threads) {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        return trace(map, src, s);
    };
    const auto a = run(1), b = run(2);
    EXPECT_NEAR(a.ledger.relative_error(), 0.0, 1e-6);
    EXPECT_GT(a.stats.reflections, 0u);
    EXPECT_TRUE(a.echoes == b.echoes);
    EXPECT_EQ(a.fluence.voxels(), b.fluence.voxels());
    EXPECT_EQ(a.stats.steps, b.stats.steps);
}

}  // namespace
}  // namespace sonotrace::simulator
