// Point targets and layers through the whole frame pipeline (tracer + RF + envelope):
// wire depths, the speed-of-sound displacement behind a layer, and the lateral
// resolution at the focus, against their closed forms.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>

#include "imaging/simulation.h"
#include "tissue/tissue_table.h"

namespace sonotrace {
namespace {

constexpr double kC0 = tissue::kReferenceSpeed;

tissue::AcousticProperties medium(double c, double rho, double roughness = 0.0) {
    tissue::AcousticProperties p;
    p[tissue::Property::speed_of_sound] = float(c);
    p[tissue::Property::density] = float(rho);
    p[tissue::Property::attenuation] = 0.0f;  // no attenuation: echoes keep their level
    p[tissue::Property::roughness] = float(roughness);
    return p;
}

// A phantom in probe-plane coordinates (x lateral, y depth from the face, mm).
using Phantom = std::function<tissue::AcousticProperties(glm::dvec2)>;

// The envelope of one frame of `phantom` (no speckle: targets and layers only).
imaging::LineData frame_envelope(const probe::Transducer& t, const Phantom& phantom,
                                 double map_pixel_mm, int particles_per_line) {
    const probe::Pose pose = probe::Pose::looking({0, 0, 0}, {0, 1, 0}, {1, 0, 0});
    const imaging::PlaneGrid grid = imaging::plane_grid(t, pose, map_pixel_mm);
    tissue::PropertyMaps maps;
    for (auto& f : maps.fields) f = tissue::Volume(grid.geometry);
    const glm::ivec3 dims = grid.geometry.dims;
    for (int j = 0; j < dims.y; ++j) {
        for (int i = 0; i < dims.x; ++i) {
            // Texel (i, j) sits at map (i h, j h); plane = map - to_map.
            const glm::dvec2 plane = glm::dvec2(i, j) * map_pixel_mm - grid.to_map;
            const tissue::AcousticProperties p = phantom(plane);
            for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                maps.fields[f].at(i, j) = p.values[f];
        }
    }
    const auto map = tissue::AcousticMap<2>::build(maps);
    imaging::SimulationSettings settings;
    settings.transducer = t;
    settings.quality = imaging::Quality::high;
    settings.imaging.speckle = false;
    (void)particles_per_line;
    return imaging::simulate_frame(map, grid, pose, settings).envelope;
}

// Depth (mm, c0 t / 2) of the first echo of a line within [from, to]: the first local
// maximum of the envelope at half the window's maximum or more (a wire's back wall, 0.3 mm
// behind its front, can be the stronger), refined by a parabola through its neighbours.
double peak_depth(const imaging::LineData& env, int line, double from_mm, double to_mm) {
    float strongest = 0.0f;
    for (int i = 1; i + 1 < env.samples; ++i)
        if (env.depth_mm(i) >= from_mm && env.depth_mm(i) <= to_mm)
            strongest = std::max(strongest, env.at(line, i));
    int best = -1;
    for (int i = 1; i + 1 < env.samples && best < 0; ++i) {
        if (env.depth_mm(i) < from_mm || env.depth_mm(i) > to_mm) continue;
        const float v = env.at(line, i);
        if (v >= 0.5f * strongest && v >= env.at(line, i - 1) && v >= env.at(line, i + 1)) best = i;
    }
    const double a = env.at(line, best - 1), b = env.at(line, best), c = env.at(line, best + 1);
    const double shift = (a - 2 * b + c) != 0.0 ? 0.5 * (a - c) / (a - 2 * b + c) : 0.0;
    return env.depth_mm(best) + shift * (env.depth_mm(1) - env.depth_mm(0));
}

// A wire: a mirror-smooth disc of bone-like impedance in a c0 medium. Its echo comes from
// the front surface, where the beam meets it at normal incidence.
constexpr double kWireRadius = 0.3;
Phantom wires_in(const std::vector<glm::dvec2>& centres, const Phantom& background,
                 double radius = kWireRadius) {
    return [=](glm::dvec2 p) {
        for (const glm::dvec2& c : centres)
            if (glm::length(p - c) <= radius) return medium(3000.0, 1900.0);
        return background(p);
    };
}

probe::Transducer linear_probe(int lines) {
    probe::Transducer t = probe::find_transducer("linear", "test");
    t.lines = lines;
    t.depth_mm = 40.0;
    t.focus_mm = 20.0;
    return t;
}

TEST(ImagingPhysics, WiresAppearAtTheirDepthInC0) {
    const probe::Transducer t = linear_probe(64);
    const Phantom water = [](glm::dvec2) { return medium(kC0, 1000.0); };
    const std::vector<glm::dvec2> wires = {{0.0, 10.0}, {0.0, 20.0}, {0.0, 30.0}};
    const auto env = frame_envelope(t, wires_in(wires, water), 0.1, 128);
    const int centre = t.lines / 2;  // lines at +-pitch/2: either sees the wire
    for (const glm::dvec2& w : wires) {
        const double front = w.y - kWireRadius;
        const double seen = std::max(peak_depth(env, centre, front - 3, front + 3),
                                     peak_depth(env, centre - 1, front - 3, front + 3));
        std::printf("wire front %.2f mm seen at %.3f mm\n", front, seen);
        EXPECT_NEAR(seen, front, 0.5) << "wire at " << front << " mm";
    }
}

// Behind a layer of thickness L and speed c, a wire appears deeper by L (c0/c - 1): the
// shift between frames with and without the layer (same impedance: no reflection).
TEST(ImagingPhysics, SpeedLayerShiftsWiresByTheDelayDifference) {
    const probe::Transducer t = linear_probe(32);
    const double layer_top = 5.0, thickness = 10.0, c_layer = 1450.0;
    const double z0 = kC0 * 1000.0;
    const Phantom plain = [&](glm::dvec2) { return medium(kC0, 1000.0); };
    const Phantom layered = [&](glm::dvec2 p) {
        if (p.y >= layer_top && p.y < layer_top + thickness) return medium(c_layer, z0 / c_layer);
        return medium(kC0, 1000.0);
    };
    const std::vector<glm::dvec2> wires = {{0.0, 25.0}};
    const auto a = frame_envelope(t, wires_in(wires, plain), 0.1, 128);
    const auto b = frame_envelope(t, wires_in(wires, layered), 0.1, 128);
    const double expected = thickness * (kC0 / c_layer - 1.0);  // 0.621 mm
    const int line = t.lines / 2;
    const double front = 25.0 - kWireRadius;
    const double shift =
        peak_depth(b, line, front - 3, front + 3) - peak_depth(a, line, front - 3, front + 3);
    std::printf("shift %.3f mm, L (c0/c - 1) %.3f mm (plain %.3f)\n", shift, expected,
                peak_depth(a, line, front - 3, front + 3));
    EXPECT_NEAR(shift, expected, 0.1 * expected);
}

// Across the lines, a wire at the focus traces the two-way lateral PSF: FWHM = lambda F#
// (probe/beam.h) within 25 %.
TEST(ImagingPhysics, LateralResolutionAtTheFocus) {
    // A thin wire (0.12 mm, 3 texels of a 0.04 mm map) so its own width adds little.
    probe::Transducer t = linear_probe(256);  // line spacing 0.15 mm: the PSF is sampled
    t.depth_mm = 24.0;
    const double radius = 0.12;
    const Phantom water = [](glm::dvec2) { return medium(kC0, 1000.0); };
    const glm::dvec2 wire(0.07, t.focus_mm + radius);
    const auto env = frame_envelope(t, wires_in({wire}, water, radius), 0.04, 128);
    const probe::ScanGeometry g(t);
    std::vector<double> x, peak;
    for (int l = 0; l < t.lines; ++l) {
        double best = 0.0;
        for (int i = 0; i < env.samples; ++i)
            if (std::abs(env.depth_mm(i) - t.focus_mm) < 2.0)
                best = std::max(best, double(env.at(l, i)));
        x.push_back(g.point(l, t.focus_mm).x);
        peak.push_back(best);
    }
    const auto top = std::max_element(peak.begin(), peak.end()) - peak.begin();
    const double half = 0.5 * peak[std::size_t(top)];
    auto crossing = [&](int direction) {
        for (std::ptrdiff_t l = top; l >= 0 && l < std::ptrdiff_t(peak.size()); l += direction) {
            const std::size_t a = std::size_t(l), b = std::size_t(l + direction);
            if (b >= peak.size()) break;
            if (peak[b] < half)
                return x[a] + (x[b] - x[a]) * (peak[a] - half) / (peak[a] - peak[b]);
        }
        return x[std::size_t(top)];
    };
    const double fwhm = crossing(1) - crossing(-1);
    const double expected = t.wavelength_mm() * t.f_number;
    std::printf("lateral FWHM %.3f mm, lambda F# %.3f mm\n", fwhm, expected);
    EXPECT_NEAR(fwhm, expected, 0.25 * expected) << "lambda F# = " << expected;
}

}  // namespace
}  // namespace sonotrace
