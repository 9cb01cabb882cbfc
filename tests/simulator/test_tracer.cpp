// The particle tracer against closed-form physics: exponential attenuation, unbiased roulette, the
// energy ledger, 3D refraction, byte-identical results on 1 and 2 threads, and bad settings.
// Snell's law, the critical angle, the reflected fraction against the angle, reverberation and the
// fibre guide of figure 4 are cases of the validation suite (phantoms/validation, run by
// test_validation); interfaces (reflections' records, gases) in test_tracer_interfaces.cpp.
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
