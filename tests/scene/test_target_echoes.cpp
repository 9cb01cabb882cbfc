// Point and wire targets in phantoms, imaged (imaging::point_echoes -> RF -> envelope):
// their echo strength against the closed forms of their path losses and backscatter, and
// the elevation beam they show against the lens's Rayleigh-Sommerfeld sum
// (tests/elevation_reference.h). The phantoms make the scene; the expectations are
// computed here.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <vector>

#include "imaging/bmode.h"
#include "imaging/psf.h"
#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "probe/elevation.h"
#include "probe/transducer.h"
#include "tests/elevation_reference.h"
#include "tests/test_util.h"

namespace sonotrace {
namespace {

constexpr double kPi = std::numbers::pi;

// A target's echo strength (imaging::point_echoes) against the closed forms it stands for:
// the wire's 2D backscatter width pi a r^2 (tissue/point_target.h) through the echo
// amplitude sqrt(sigma lambda / (2 pi)), the one-way intensity loss alpha f L (dB) of the
// path to it (two-way in amplitude), 1 - R^2 at a layer crossed on the way, and a point's
// elevation weight d g(e, z) (g: the lens's two-way profile, unit integral over e).
// Within 1 % (the path is marched at half-texel steps).
TEST(Psf, TargetEchoStrengthFollowsItsPathLosses) {
    constexpr double kAlpha = 0.5, kR = 0.2, kDepth = 30.0, kLayerTop = 10.0;
    const nlohmann::json j = {
        {"name", "targets"},
        {"size", {40, 40, 10}},
        {"resolution", 0.125},
        {"smoothing", 0.2},
        {"background",
         {{"speed_of_sound", 1540},
          {"density", 1000},
          {"attenuation", kAlpha},
          {"backscatter", 0},
          {"scatterer_density", 0},
          {"roughness", 0}}},
        {"shapes",
         {{{"type", "half_space"},
           {"point", {20, kLayerTop, 0}},
           {"normal", {0, 1, 0}},
           {"speed_of_sound", 1540},
           {"density", 1000.0 * (1 + kR) / (1 - kR)},
           {"attenuation", kAlpha},
           {"backscatter", 0},
           {"scatterer_density", 0},
           {"roughness", 0}}}},
        {"targets",
         {{{"type", "wire"}, {"at", {20, kDepth}}, {"diameter", 0.1}, {"reflectivity", 0.3}},
          {{"type", "point"},
           {"at", {22, kDepth, 5.4}},
           {"diameter", 0.2},
           {"reflectivity", 0.3}}}},
        {"probe", {{"preset", "linear"}}}};
    const phantoms::Phantom ph = phantoms::parse_phantom(j, "test");
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const imaging::PlaneGrid grid = imaging::plane_grid(t, ph.pose, 0.125);
    const auto map = tissue::AcousticMap<2>::build(phantoms::rasterise(ph, grid.geometry));
    constexpr double kMargin = 0.3;
    const std::vector<imaging::PointEcho> echoes =
        imaging::point_echoes(ph.targets, map, grid, ph.pose, t, kMargin);
    ASSERT_EQ(echoes.size(), 2u);
    const double lambda = t.wavelength_mm();
    auto strength = [&](double d) {
        const double sigma = kPi * 0.5 * d * 0.3 * 0.3;
        return std::sqrt(sigma * lambda / (2.0 * kPi));
    };
    const double path_cm = 0.1 * (kDepth - 0.05 - kMargin);
    const double loss =
        std::pow(10.0, -kAlpha * t.frequency_mhz * path_cm / 10.0) * (1.0 - kR * kR);
    EXPECT_NEAR(echoes[0].amplitude, strength(0.1) * loss, 0.01 * strength(0.1) * loss);
    // The point 0.4 mm off the plane: d g(e) more than a wire of its diameter.
    // g: the lens's two-way elevation profile |U|^2 / (lambda z H) at e = 0.4 mm, z = 30 mm
    // (probe/elevation.h), its Fresnel integral by Simpson's rule here.
    const double H = t.elevation_aperture_mm(), F = t.elevation_focus_mm;
    auto lens_profile = [&](double e, double z) {
        const int n = 20000;  // even
        const double h = H / n, k = 2.0 * kPi / lambda;
        std::complex<double> sum = 0.0;
        for (int m = 0; m <= n; ++m) {
            const double x = -0.5 * H + m * h;
            const double w = m == 0 || m == n ? 1.0 : (m % 2 == 1 ? 4.0 : 2.0);
            sum += w * std::polar(1.0, k * (0.5 * x * x * (1.0 / z - 1.0 / F) - x * e / z));
        }
        return std::norm(sum * h / 3.0) / (lambda * z * H);
    };
    const double g = lens_profile(0.4, kDepth);
    const double path_point_cm = 0.1 * (std::hypot(kDepth, 0.0) - 0.1 - kMargin);
    const double loss_point =
        std::pow(10.0, -kAlpha * t.frequency_mhz * path_point_cm / 10.0) * (1.0 - kR * kR);
    EXPECT_NEAR(echoes[1].amplitude, strength(0.2) * 0.2 * g * loss_point,
                0.01 * strength(0.2) * 0.2 * g * loss_point);
    // Where they image: the map frame positions of their centres.
    EXPECT_NEAR(echoes[0].position.x - echoes[1].position.x, -2.0, 1e-9);
    EXPECT_NEAR(echoes[0].core_radius_mm, 0.05 + kMargin, 1e-12);
}

// Lossless water without scatterers, 40 x 64 x 10 mm, for the linear preset.
phantoms::Phantom clear_water() {
    const nlohmann::json j = {{"name", "water"},
                              {"size", {40, 64, 10}},
                              {"resolution", 0.125},
                              {"background",
                               {{"speed_of_sound", 1540},
                                {"density", 1000},
                                {"attenuation", 0.0},
                                {"backscatter", 0},
                                {"scatterer_density", 0},
                                {"roughness", 0}}},
                              {"probe", {{"preset", "linear"}}}};
    return phantoms::parse_phantom(j, "test");
}

// The elevation beam measured on the image: a 0.1 mm point moved out of the scan plane
// (point_echoes -> RF -> envelope, the peak over the frame), its two-way -6 dB width at
// the elevation focus and at twice its depth within 15 % of the lens aperture's own
// prediction (the Rayleigh-Sommerfeld sum of tests/elevation_reference.h).
TEST(Psf, ElevationBeamWidthFollowsTheLens) {
    const phantoms::Phantom ph = clear_water();
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const imaging::PlaneGrid grid = imaging::plane_grid(t, ph.pose, 0.125);
    const auto map = tissue::AcousticMap<2>::build(phantoms::rasterise(ph, grid.geometry));
    imaging::ImagingSettings settings;
    settings.speckle = false;
    const double F = t.elevation_focus_mm, lambda = t.wavelength_mm();
    for (const double z : {F, 2.0 * F}) {
        auto image_peak = [&](double e) {
            tissue::PointTarget target;
            target.at = ph.pose.position + ph.pose.axial() * z + ph.pose.elevation() * e +
                        ph.pose.lateral() * 0.013;
            const auto echoes = imaging::point_echoes({target}, map, grid, ph.pose, t, 0.3);
            const imaging::LineData env = imaging::envelope(imaging::synthesize_rf(
                t, {}, {}, {}, imaging::map_to_world(ph.pose, grid), settings, echoes));
            return double(*std::max_element(env.values.begin(), env.values.end()));
        };
        const double reach = 0.5 * probe::ElevationBeam(t).reach_mm(z);
        const double measured = test::half_amplitude_width(image_peak, reach, lambda / 10.0);
        const double expected = test::half_amplitude_width(
            [&](double e) { return test::rayleigh_elevation_two_way(t, e, z); }, reach,
            lambda / 50.0);
        std::printf("elevation beam at %.0f mm: two-way -6 dB width %.3f mm (lens %.3f)\n", z,
                    measured, expected);
        EXPECT_NEAR(measured, expected, 0.15 * expected) << z;
    }
}

// Wires through the elevation beam (measured on the envelope at the elevation focus): one
// crossing the plane at 30 degrees, perpendicular to the beam, shows only where the slice
// reaches it: over the lens's -6 dB width / tan 30 degrees, blurred by the lateral PSF
// (widths in quadrature, the PSF measured on a wire straight across the plane); a wire
// lying in the plane shows on every line it passes under.
TEST(Psf, WiresShowWhereTheyCrossTheSlice) {
    const phantoms::Phantom ph = clear_water();
    probe::Transducer t = probe::find_transducer("linear", "test");
    t.lines = 384;  // 0.1 mm apart
    const imaging::PlaneGrid grid = imaging::plane_grid(t, ph.pose, 0.125);
    const auto map = tissue::AcousticMap<2>::build(phantoms::rasterise(ph, grid.geometry));
    imaging::ImagingSettings settings;
    settings.speckle = false;
    const double F = t.elevation_focus_mm;
    const probe::Pose& pose = ph.pose;
    // The peak envelope of each line near depth F for one wire.
    auto line_peaks = [&](const glm::dvec3& axis) {
        tissue::PointTarget wire;
        wire.type = tissue::PointTarget::Type::wire;
        wire.at = pose.position + pose.axial() * F;
        wire.axis = glm::normalize(axis);
        const auto echoes = imaging::point_echoes({wire}, map, grid, pose, t, 0.3);
        const imaging::LineData env = imaging::envelope(imaging::synthesize_rf(
            t, {}, {}, {}, imaging::map_to_world(pose, grid), settings, echoes));
        std::vector<double> peaks;
        for (int l = 0; l < env.lines; ++l) {
            double peak = 0.0;
            for (int i = 0; i < env.samples; ++i) peak = std::max(peak, double(env.at(l, i)));
            peaks.push_back(peak);
        }
        return peaks;
    };
    const double spacing = probe::ScanGeometry(t).line_spacing_mm(F);
    const std::vector<double> across = line_peaks(pose.elevation());
    const double psf = test::peak_width_samples(across) * spacing;
    const double tilt = 30.0 * kPi / 180.0;
    const std::vector<double> oblique =
        line_peaks(pose.lateral() * std::cos(tilt) + pose.elevation() * std::sin(tilt));
    const double measured = test::peak_width_samples(oblique) * spacing;
    const double slice = test::half_amplitude_width(
        [&](double e) { return test::rayleigh_elevation_two_way(t, e, F); }, 3.0,
        t.wavelength_mm() / 50.0);
    const double expected = std::hypot(slice / std::tan(tilt), psf);
    std::printf(
        "wire at 30 degrees: shows over %.3f mm (slice %.3f mm / tan 30 + PSF %.3f mm: %.3f)\n",
        measured, slice, psf, expected);
    EXPECT_NEAR(measured, expected, 0.15 * expected);
    // In the plane: every line under the wire, away from the array's ends, sees it at
    // more than half the brightest line's level.
    const std::vector<double> along = line_peaks(pose.lateral());
    const double brightest = *std::max_element(along.begin(), along.end());
    int dim = 0;
    for (std::size_t l = along.size() / 5; l < along.size() * 4 / 5; ++l)
        dim += along[l] < 0.5 * brightest;
    EXPECT_EQ(dim, 0) << "lines of the middle 60 % where the in-plane wire is dim";
}

}  // namespace
}  // namespace sonotrace
