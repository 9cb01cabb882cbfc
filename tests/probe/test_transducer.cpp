// Transducer models: parameter validation, scan geometry and its inverse for the three
// types, and the beam sampler (Hann apodization and Gaussian aim offsets, chi-square).
#include <gtest/gtest.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <complex>
#include <numbers>
#include <set>
#include <string>
#include <variant>

#include "probe/aperture.h"
#include "probe/array_geometry.h"
#include "probe/beam.h"
#include "probe/elevation.h"
#include "probe/transducer.h"
#include "tests/elevation_reference.h"
#include "tests/test_util.h"
#include "tissue/base/error.h"

namespace sonotrace {
namespace {

using probe::Transducer;
using probe::TransducerType;

TEST(Transducer, PresetsAreValid) {
    for (const Transducer& t : probe::transducer_presets()) {
        EXPECT_NO_THROW(t.validate(t.name)) << t.name;
    }
    EXPECT_EQ(probe::find_transducer("linear", "x").type, TransducerType::linear);
    EXPECT_DOUBLE_EQ(probe::find_transducer("linear", "x").frequency_mhz, 7.6);
    EXPECT_EQ(probe::find_transducer("convex", "x").type, TransducerType::convex);
    EXPECT_DOUBLE_EQ(probe::find_transducer("convex", "x").frequency_mhz, 3.5);
    EXPECT_EQ(probe::find_transducer("phased", "x").type, TransducerType::phased);
    EXPECT_DOUBLE_EQ(probe::find_transducer("phased", "x").frequency_mhz, 2.7);
    test::expect_input_error([] { probe::find_transducer("sector", "--probe"); }, "--probe",
                             "probe", "linear, convex, phased");
}

// The parameter table is the one way the CLI sets a transducer and the sidecar reads
// it: each row's value, written as text and read back through its own row into a default
// transducer, is the preset's (every preset differs from the default somewhere, so a
// row that read or wrote another member would show); keys and flags are unique.
TEST(Transducer, EveryParameterRowReadsAndWritesItsOwnMember) {
    using Value = probe::TransducerParameterDoc::Value;
    auto text = [](const Value& v) {
        return std::visit(
            [](const auto& x) -> std::string {
                if constexpr (std::is_same_v<std::decay_t<decltype(x)>, std::string>) {
                    return x;
                } else {
                    char buffer[64];
                    const auto end = std::to_chars(buffer, buffer + sizeof buffer, x).ptr;
                    return std::string(buffer, end);  // shortest text that reads back exactly
                }
            },
            v);
    };
    const auto& docs = probe::transducer_parameter_docs();
    std::set<std::string> keys, records;
    for (const auto& doc : docs) {
        EXPECT_TRUE(keys.insert(doc.key).second) << doc.key;
        EXPECT_TRUE(records.insert(doc.record_key).second) << doc.record_key;
    }
    for (const probe::Transducer& preset : probe::transducer_presets()) {
        probe::Transducer t;
        for (const auto& doc : docs) doc.set(t, text(doc.get(preset)), "test");
        for (const auto& doc : docs)
            EXPECT_EQ(doc.get(t), doc.get(preset)) << preset.name << ": " << doc.key;
    }
    probe::Transducer t;
    for (const auto& doc : docs) {
        if (std::holds_alternative<std::string>(doc.get(t))) continue;
        EXPECT_THROW(doc.set(t, "12x", "test"), base::InputError) << doc.key;
        EXPECT_THROW(doc.set(t, "", "test"), base::InputError) << doc.key;
    }
}

TEST(Transducer, ImpossibleGeometryIsRejected) {
    Transducer t = probe::find_transducer("convex", "x");
    Transducer zero = t;
    zero.elements = 0;
    test::expect_input_error([&] { zero.validate("probe"); }, "probe", "elements");
    Transducer deep_focus = t;
    deep_focus.focus_mm = t.depth_mm + 1.0;
    test::expect_input_error([&] { deep_focus.validate("probe"); }, "probe", "focus",
                             "beyond the imaging depth");
    Transducer wide = probe::find_transducer("phased", "x");
    wide.fov_deg = 190.0;
    test::expect_input_error([&] { wide.validate("probe"); }, "probe", "fov");
    Transducer arc = t;
    arc.fov_deg = 100.0;  // 128 * 0.508 / 49.57 rad = 75 degrees of arc
    test::expect_input_error([&] { arc.validate("probe"); }, "probe", "fov", "arc");
    Transducer nan = t;
    nan.frequency_mhz = std::nan("");
    test::expect_input_error([&] { nan.validate("probe"); }, "probe", "frequency");
}

// Every line's points invert to (line, depth); known points land where geometry says.
TEST(ScanGeometry, PointsAndInverseForAllTypes) {
    for (const Transducer& t : probe::transducer_presets()) {
        const probe::ScanGeometry g(t);
        for (int l = 0; l < t.lines; l += 7) {
            for (double d : {0.0, 10.0, t.depth_mm}) {
                if (d == 0.0 && t.type == TransducerType::phased) continue;  // common origin
                const glm::dvec2 back = g.line_and_depth(g.point(l, d));
                EXPECT_NEAR(back.x, l, 1e-9) << t.name;
                EXPECT_NEAR(back.y, d, 1e-9) << t.name;
            }
        }
    }
    // Linear: lines spread evenly over the array, straight down.
    const Transducer linear = probe::find_transducer("linear", "x");
    const probe::ScanGeometry lg(linear);
    const double span = linear.array_length_mm();
    EXPECT_NEAR(lg.point(0, 5.0).x, -0.5 * span + 0.5 * span / linear.lines, 1e-12);
    EXPECT_NEAR(lg.point(0, 5.0).y, 5.0, 1e-12);
    // Convex: the centre line at depth d lies at (0, d); the outermost line at angle
    // -fov/2 + half a line, from the centre of curvature (0, -R).
    const Transducer convex = probe::find_transducer("convex", "x");
    const probe::ScanGeometry cg(convex);
    const double half = 0.5 * convex.fov_deg * std::numbers::pi / 180.0;
    const double first = -half + half / convex.lines;
    const glm::dvec2 p = cg.point(0, 30.0);
    EXPECT_NEAR(p.x, (convex.radius_mm + 30.0) * std::sin(first), 1e-9);
    EXPECT_NEAR(p.y, (convex.radius_mm + 30.0) * std::cos(first) - convex.radius_mm, 1e-9);
    // Phased: all lines start at the origin.
    const probe::ScanGeometry pg(probe::find_transducer("phased", "x"));
    EXPECT_NEAR(glm::length(pg.point(0, 0.0)), 0.0, 1e-12);
    EXPECT_NEAR(glm::length(pg.point(77, 40.0)), 40.0, 1e-9);
}

double chi_square(const std::vector<int>& counts, const std::vector<double>& p, int n) {
    double chi2 = 0.0;
    for (std::size_t b = 0; b < counts.size(); ++b) {
        const double e = p[b] * n;
        chi2 += (counts[b] - e) * (counts[b] - e) / e;
    }
    return chi2;
}

// The inverse CDFs map uniform draws onto their densities: chi-square against the
// exact bin probabilities (CDF differences), 20 bins, p = 0.001 critical value 43.82
// (19 degrees of freedom); 20000 pseudo-random (not stratified) draws.
TEST(BeamSampling, HannInverseCdfFollowsTheDensity) {
    const int bins = 20, n = 20000;
    std::vector<int> counts(bins, 0);
    uint64_t state = 12345;
    for (int i = 0; i < n; ++i) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        const double u = double(state >> 11) * 0x1.0p-53;
        counts[std::min(bins - 1, int(probe::hann_inverse_cdf(u) * bins))]++;
    }
    auto cdf = [](double v) {
        return v - std::sin(2 * std::numbers::pi * v) / (2 * std::numbers::pi);
    };
    std::vector<double> p(bins);
    for (int b = 0; b < bins; ++b) p[b] = cdf(double(b + 1) / bins) - cdf(double(b) / bins);
    EXPECT_LT(chi_square(counts, p, n), 43.82);
}

TEST(BeamSampling, NormalInverseCdfMatchesErf) {
    for (double u : {1e-10, 1e-4, 0.01, 0.2, 0.5, 0.7, 0.99, 1 - 1e-6}) {
        const double x = probe::normal_inverse_cdf(u);
        EXPECT_NEAR(0.5 * std::erfc(-x / std::numbers::sqrt2), u, 1e-12 * std::max(1.0, u / 1e-3))
            << u;
    }
}

// Beams: each line's particles leave the active aperture and aim at the focus; their
// offsets at the focal depth follow N(0, sigma) with sigma = lambda F / 2.355 (chi-square
// over the line's particles pooled across lines), and the transmit delays make every
// particle reach the focal point at focus / c0.
TEST(Beams, ConvergeOnTheFocusWithGaussianWaist) {
    Transducer t = probe::find_transducer("linear", "x");
    t.lines = 16;
    const probe::BeamSettings settings{400, 7};
    const auto sources = probe::make_beams(t, settings, {0.0, 0.0});
    ASSERT_EQ(sources.size(), std::size_t(16 * 400));
    const probe::ScanGeometry g(t);
    const double c0_mm_per_s = 1540e3;
    const int bins = 16;
    std::vector<int> counts(bins, 0);
    int n = 0;
    for (const auto& s : sources) {
        const probe::ScanLine line = g.line(int(s.line));
        const glm::dvec2 focus = line.origin + t.focus_mm * line.direction;
        const glm::dvec2 from(s.position), dir(s.direction);
        EXPECT_NEAR(glm::length(dir), 1.0, 1e-6);
        // Where the particle crosses the focal depth, relative to the focal point.
        const double along = (focus.y - from.y) / dir.y;
        const double offset = (from + along * dir).x - focus.x;
        // Aperture: within the active aperture around the line (clipped to the array).
        EXPECT_LE(std::abs(from.x - line.origin.x), 0.5 * t.active_aperture_mm() + 1e-6);
        EXPECT_LE(std::abs(from.x), 0.5 * t.array_length_mm() + 1e-6);
        // Delay: the particle's clock reads focus / c0 at the focal point's distance.
        const double distance = glm::length(focus - from);
        EXPECT_NEAR(s.time_s + distance / c0_mm_per_s, t.focus_mm / c0_mm_per_s, 1e-9);
        if (s.line < 4 || s.line >= 12) continue;  // full-aperture lines only
        double lo = line.origin.x - 0.5 * t.active_aperture_mm();
        double hi = line.origin.x + 0.5 * t.active_aperture_mm();
        lo = std::max(lo, -0.5 * t.array_length_mm());
        hi = std::min(hi, 0.5 * t.array_length_mm());
        const double sigma = probe::focal_sigma_mm(t, hi - lo);
        const double z = offset / sigma;
        const double u = 0.5 * std::erfc(-z / std::numbers::sqrt2);
        counts[std::min(bins - 1, int(u * bins))]++;
        ++n;
    }
    // Stratified draws are more even than chance, so this bound is conservative.
    EXPECT_LT(chi_square(counts, std::vector<double>(bins, 1.0 / bins), n), 37.70);  // 15 dof
}

// 3D beams (make_beams_3d): in the scan plane each particle is its 2D twin (same start,
// same heading once the elevation component is removed, same line and energy); in
// elevation the starts are uniform over the elements' height (chi-square, 10 bins) and
// the heights where particles cross the elevation focus follow N(0, sigma) with FWHM =
// slice thickness (chi-square, 16 bins), for every array type.
TEST(Beams, ThreeDBeamsAreTheTwoDBeamsWithAnElevationLens) {
    for (const char* preset : {"linear", "convex", "phased", "radial"}) {
        Transducer t = probe::find_transducer(preset, "x");
        t.lines = 8;
        const probe::BeamSettings settings{300, 5};
        const glm::dvec3 to_map(10.0, 2.0, 7.0);
        const auto flat = probe::make_beams(t, settings, {to_map.x, to_map.y});
        const auto beams = probe::make_beams_3d(t, settings, to_map);
        ASSERT_EQ(beams.size(), flat.size()) << preset;
        const double half_height = 0.5 * t.elevation_aperture_mm();
        const double sigma = t.slice_thickness_mm / (2.0 * std::sqrt(2.0 * std::log(2.0)));
        const int start_bins = 10, aim_bins = 16;
        std::vector<int> starts(start_bins, 0), aims(aim_bins, 0);
        for (std::size_t k = 0; k < beams.size(); ++k) {
            const auto& b = beams[k];
            const auto& f = flat[k];
            EXPECT_EQ(b.position.x, f.position.x);
            EXPECT_EQ(b.position.y, f.position.y);
            EXPECT_EQ(b.line, f.line);
            EXPECT_EQ(b.energy, f.energy);
            const glm::dvec2 in_plane = glm::normalize(glm::dvec2(b.direction.x, b.direction.y));
            EXPECT_NEAR(in_plane.x, f.direction.x, 1e-6);
            EXPECT_NEAR(in_plane.y, f.direction.y, 1e-6);
            // The lens: a height z starts sqrt(F^2 + z^2) - F earlier than its twin.
            const double z = b.position.z - to_map.z;
            const double lens_s =
                (std::hypot(t.elevation_focus_mm, z) - t.elevation_focus_mm) / 1540e3;
            EXPECT_NEAR(b.time_s, f.time_s - lens_s, 1e-9);
            ASSERT_LE(std::abs(z), half_height + 1e-6);
            starts[std::min(start_bins - 1,
                            int((z + half_height) / (2 * half_height) * start_bins))]++;
            // Height after elevation_focus mm travelled in the scan plane.
            const double in_plane_length = std::hypot(b.direction.x, b.direction.y);
            const double at_focus = z + t.elevation_focus_mm * b.direction.z / in_plane_length;
            const double u = 0.5 * std::erfc(-at_focus / sigma / std::numbers::sqrt2);
            aims[std::min(aim_bins - 1, int(u * aim_bins))]++;
        }
        const int n = int(beams.size());
        // p = 0.001 critical values: 27.88 (9 dof), 37.70 (15 dof); stratified draws are
        // more even than chance, so the bounds are conservative.
        EXPECT_LT(chi_square(starts, std::vector<double>(start_bins, 1.0 / start_bins), n), 27.88)
            << preset;
        EXPECT_LT(chi_square(aims, std::vector<double>(aim_bins, 1.0 / aim_bins), n), 37.70)
            << preset;
    }
}

// The elements' height from the presets' own numbers (probe/transducer.cpp: slice
// thickness = wavelength x F / height, with the datasheet heights 5, 13.5 and 14 mm).
TEST(Transducer, ElevationApertureIsTheLensThatGivesTheSliceThickness) {
    EXPECT_NEAR(probe::find_transducer("linear", "x").elevation_aperture_mm(), 5.0, 0.05);
    EXPECT_NEAR(probe::find_transducer("convex", "x").elevation_aperture_mm(), 13.5, 0.1);
    EXPECT_NEAR(probe::find_transducer("phased", "x").elevation_aperture_mm(), 14.0, 0.1);
}

// The radial array (probe/arrays/radial.cpp). Expectations from the ring's geometry
// alone: a circle of radius R centred at (0, -R), lines leaving it along its radii every
// 2 pi / L, and a ring that looks the same from every line (rotational symmetry).
// The lens's elevation profile (probe/elevation.h) against the closed form at the focus,
// its unit integral, and the two-way -6 dB width of the independent Rayleigh-Sommerfeld
// model (tests/elevation_reference.h) before, at and beyond the focus.
TEST(ElevationBeam, FollowsTheLensApertureAtAndAwayFromTheFocus) {
    constexpr double kPi = std::numbers::pi;
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const probe::ElevationBeam beam(t);
    const double H = t.elevation_aperture_mm(), F = t.elevation_focus_mm,
                 lambda = t.wavelength_mm();
    // At the focus: p = H sinc^2(H e / (lambda F)) / (lambda F).
    for (double e : {0.0, 0.05, 0.2, 0.35, 0.6}) {
        const double u = kPi * H * e / (lambda * F);
        const double sinc = e == 0.0 ? 1.0 : std::sin(u) / u;
        const double expected = H * sinc * sinc / (lambda * F);
        EXPECT_NEAR(beam.profile(e, F), expected, 0.005 * H / (lambda * F)) << e;
    }
    for (double z : {0.5 * F, F, 2.0 * F, 3.0 * F}) {
        SCOPED_TRACE(z);
        // Unit integral over the elevation (Parseval).
        double integral = 0.0;
        const double reach = beam.reach_mm(z), de = lambda / 16.0;
        for (double e = -reach; e <= reach; e += de) integral += beam.profile(e, z) * de;
        EXPECT_NEAR(integral, 1.0, 0.02);
        const double expected = test::half_amplitude_width(
            [&](double e) { return test::rayleigh_elevation_two_way(t, e, z); }, 0.5 * reach,
            lambda / 50.0);
        const double got = test::half_amplitude_width([&](double e) { return beam.profile(e, z); },
                                                      0.5 * reach, lambda / 50.0);
        EXPECT_NEAR(got, expected, 0.05 * expected) << "two-way -6 dB width (mm)";
    }
}

TEST(RadialArray, LinesLeaveTheRingAlongItsRadiiAllAround) {
    const Transducer t = probe::find_transducer("radial", "x");
    const probe::ScanGeometry g(t);
    const glm::dvec2 centre(0.0, -t.radius_mm);
    EXPECT_TRUE(g.closed());
    EXPECT_NEAR(t.array_length_mm(), 2.0 * std::numbers::pi * t.radius_mm, 1e-4);
    for (int l = 0; l < t.lines; ++l) {
        const probe::ScanLine line = g.line(l);
        EXPECT_NEAR(glm::length(line.origin - centre), t.radius_mm, 1e-9) << l;
        const glm::dvec2 radial = (line.origin - centre) / t.radius_mm;
        EXPECT_NEAR(glm::length(line.direction - radial), 0.0, 1e-12) << l;
        // The angle to the next line, the last one's next being the first.
        const probe::ScanLine next = g.line((l + 1) % t.lines);
        const double step =
            std::acos(std::clamp(glm::dot(line.direction, next.direction), -1.0, 1.0));
        EXPECT_NEAR(step, 2.0 * std::numbers::pi / t.lines, 1e-9) << l;
        const double cross =
            line.direction.x * next.direction.y - line.direction.y * next.direction.x;
        EXPECT_LT(cross, 0.0) << l;  // always turning the same way round
    }
    EXPECT_NEAR(g.line_spacing_mm(20.0), (t.radius_mm + 20.0) * 2.0 * std::numbers::pi / t.lines,
                1e-12);
}

TEST(RadialArray, EveryLineSeesTheSameRing) {
    const Transducer t = probe::find_transducer("radial", "x");
    // Line 0 sits where the elements' numbering wraps (its aperture takes the last and
    // the first elements); line L/2 does not. By symmetry they see the same array.
    const probe::LineFields wrapping(t, probe::line_array(t, 0));
    const probe::LineFields inside(t, probe::line_array(t, t.lines / 2));
    const probe::LineFields quarter(t, probe::line_array(t, t.lines / 4 + 3));
    double largest = 0.0, worst = 0.0;
    for (double z : {5.0, t.focus_mm, 35.0})
        for (double x = -4.0; x <= 4.0; x += 0.25) {
            const glm::dvec2 q(x, z);
            const std::complex<double> h = inside.two_way(q);
            largest = std::max(largest, std::abs(h));
            worst = std::max(
                {worst, std::abs(wrapping.two_way(q) - h), std::abs(quarter.two_way(q) - h)});
        }
    ASSERT_GT(largest, 0.0);
    EXPECT_LT(worst, 1e-6 * largest);
    // The aperture is centred on the line: the weights are mirror-symmetric about it.
    const probe::LineArray a = probe::line_array(t, 0);
    const std::vector<double> w =
        probe::aperture_weights(a, t.active_aperture_mm(), t.tx_apodization);
    double first_moment = 0.0, total = 0.0;
    for (std::size_t e = 0; e < w.size(); ++e)
        first_moment += w[e] * a.position[e].x, total += w[e];
    EXPECT_GT(total, 0.0);
    EXPECT_NEAR(first_moment / total, 0.0, 1e-9);
}

TEST(RadialArray, BeamsLeaveTheRingWithinTheActiveArc) {
    Transducer t = probe::find_transducer("radial", "x");
    const probe::BeamSettings settings{200, 3};
    const auto sources = probe::make_beams(t, settings, {0.0, 0.0});
    const probe::ScanGeometry g(t);
    const glm::dvec2 centre(0.0, -t.radius_mm);
    const double c0_mm_per_s = 1540e3;
    for (const auto& s : sources) {
        const probe::ScanLine line = g.line(int(s.line));
        const glm::dvec2 from(s.position);
        EXPECT_NEAR(glm::length(from - centre), t.radius_mm, 1e-5);
        // The arc from the line's foot: within half the active aperture, also across
        // the numbering's wrap.
        const double turn = std::acos(
            std::clamp(glm::dot((from - centre) / t.radius_mm, line.direction), -1.0, 1.0));
        EXPECT_LE(turn * t.radius_mm, 0.5 * t.active_aperture_mm() + 1e-4);
        const glm::dvec2 focus = line.origin + t.focus_mm * line.direction;
        EXPECT_NEAR(s.time_s + glm::length(focus - from) / c0_mm_per_s, t.focus_mm / c0_mm_per_s,
                    1e-9);
    }
}

TEST(RadialArray, ImpossibleRingsAreRefusedNamingTheField) {
    const Transducer t = probe::find_transducer("radial", "x");
    Transducer open = t;
    open.elements = 128;  // half the ring's circumference
    test::expect_input_error([&] { open.validate("probe"); }, "probe", "radius",
                             "closes on itself");
    Transducer fan = t;
    fan.fov_deg = 300.0;
    test::expect_input_error([&] { fan.validate("probe"); }, "probe", "fov", "360");
    // Apertures asked wider than the half of the ring that faces a line are clipped to it.
    Transducer wide = t;
    wide.f_number = 0.6;     // 25 mm asked on a 37.7 mm ring
    wide.rx_f_number = 1.0;  // 40 mm at the imaging depth
    EXPECT_NO_THROW(wide.validate("probe"));
    EXPECT_NEAR(wide.active_aperture_mm(), std::numbers::pi * t.radius_mm, 1e-9);
    EXPECT_NEAR(wide.receive_aperture_mm(t.depth_mm), std::numbers::pi * t.radius_mm, 1e-9);
    EXPECT_EQ(probe::parse_transducer_type("radial", "--type", ""), TransducerType::radial);
    test::expect_input_error([] { probe::parse_transducer_type("sector", "--type", ""); }, "--type",
                             "", "linear, convex, phased, radial");
}

}  // namespace
}  // namespace sonotrace
