// Imaging cases: echo levels (shadow and enhancement, a flat reflector against depth, two
// layers), against transmission losses and the aperture's plane response.
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "phantoms/scene/scene.h"
#include "phantoms/validation/broadband_reference.h"
#include "phantoms/validation/cases_imaging.h"
#include "phantoms/validation/phantom_frames.h"
#include "phantoms/validation/validation.h"
#include "probe/aperture.h"
#include "probe/pulse.h"
#include "tissue/base/half_maximum.h"
#include "tissue/tissue_table.h"

namespace sonotrace::validation {
namespace {

double impedance(const tissue::AcousticProperties& p) {
    return property(p, tissue::Property::speed_of_sound) * property(p, tissue::Property::density);
}
double intensity_reflection(double z1, double z2) {
    return std::pow((z2 - z1) / (z2 + z1), 2.0);
}

}  // namespace

CaseResult shadow_and_enhancement(const CaseContext& ctx) {
    const PhantomFrame f = image_phantom(catalogue(ctx, "cyst_and_stone"), {50.0, 0}, ctx.seed);
    // The reference: the same phantom without its shapes (plain liver), same seed. The
    // scatterers are fixed in the tissue, so where the beams are alike the speckle is the
    // same and cancels from the ratio; and no reference column is half in a shadow.
    phantoms::Phantom plain_phantom = f.phantom;
    plain_phantom.shapes.clear();
    const PhantomFrame plain = image_phantom(plain_phantom, {50.0, 0}, ctx.seed);
    const auto& cyst = shape(f.phantom, phantoms::ShapeType::sphere);
    const auto& plaque = shape(f.phantom, phantoms::ShapeType::box);
    const tissue::AcousticProperties& liver = f.phantom.background;
    const double freq = f.transducer.frequency_mhz;
    const double a_liver = property(liver, tissue::Property::attenuation);  // dB/(cm MHz)
    // Mean intensity (envelope^2) in a 6 mm window below the object, +-1.5 mm about its
    // axis, with and without the objects.
    const glm::dvec2 cyst_c = f.plane(glm::dvec2(cyst.a)),
                     plaque_lo = f.plane(glm::dvec2(plaque.a)),
                     plaque_hi = f.plane(glm::dvec2(plaque.b));
    const double x_plaque = 0.5 * (plaque_lo.x + plaque_hi.x);
    auto ratio_db = [&](double x, double y0, double y1) {
        auto inside = [&](glm::dvec2 p) {
            return std::abs(p.x - x) <= 1.5 && p.y >= y0 && p.y <= y1;
        };
        return 10.0 * std::log10(mean_square(envelope_samples(f, inside)) /
                                 mean_square(envelope_samples(plain, inside)));
    };
    CaseResult r;
    // Shadow: two-way loss through the plaque (thickness d) instead of liver: the two
    // faces transmit (1 - R^2) each way, and the plaque attenuates a_p f d instead of the
    // liver's a_l f d. Tolerance 1.5 dB: ~150 independent speckle cells per window (the
    // shadowed speckle is not the reference's: the plaque reshapes the beams), a 4 sigma
    // error of a ratio of two means of ~1.4 dB.
    {
        const double d_cm = 0.1 * (plaque_hi.y - plaque_lo.y);
        const double R2 = intensity_reflection(impedance(liver), impedance(plaque.properties));
        const double a_p = property(plaque.properties, tissue::Property::attenuation);
        const double expected =
            2.0 * (2.0 * 10.0 * std::log10(1.0 - R2) - (a_p - a_liver) * freq * d_cm);
        // Below the mirror image of the liver above the plaque: the share R^2 the plaque's
        // top reflects meets the liver on its way back and returns through the same
        // reflection (R^4 = 0.04 of the liver, as bright as the shadow itself), drawn at
        // apparent depths down to twice the plaque's depth. The window starts 2 mm below.
        const double y0 = 2.0 * plaque_lo.y + 2.0, y1 = y0 + 6.0;
        const double measured = ratio_db(x_plaque, y0, y1);
        r.measurements.push_back(
            {"shadow contrast behind the plaque", measured, expected, 1.5, "dB"});
    }
    // Enhancement: the cyst (water) attenuates a_w instead of a_l over its chord; the mean
    // two-way gain over the window's chords, less the cyst walls' transmission. Within
    // 20 % (the issue).
    {
        const double a_w = property(cyst.properties, tissue::Property::attenuation);
        const double R2 = intensity_reflection(impedance(liver), impedance(cyst.properties));
        double chord = 0.0;
        for (int k = -15; k <= 15; ++k) {
            const double x = 0.1 * k;  // window +-1.5 mm
            chord += 2.0 * std::sqrt(std::max(0.0, cyst.radius * cyst.radius - x * x)) / 31.0;
        }
        const double expected =
            2.0 * ((a_liver - a_w) * freq * 0.1 * chord + 2.0 * 10.0 * std::log10(1.0 - R2));
        const double y0 = cyst_c.y + cyst.radius + 4.0, y1 = y0 + 6.0;
        const double measured = ratio_db(cyst_c.x, y0, y1);
        r.measurements.push_back({"posterior enhancement behind the cyst", measured, expected,
                                  0.2 * std::abs(expected), "dB"});
    }
    if (ctx.pictures)
        r.figures.push_back(frame_figure(f,
                                         "Liver with a fluid cyst (left: brighter behind) and a "
                                         "calcified plaque (right: shadow). No TGC difference "
                                         "between the columns compared."));
    return r;
}

namespace {

// The on-axis two-way echo of a perpendicular plane at depth z on the middle line of a
// linear probe (t.lines odd), computed by image sources directly from the elements: the
// plane at depth z mirrors transmit element e to (x_e, 2z - y_e), so the echo is
//   sum_e sum_r a_e b_r D(theta)^2 exp(-ik (L_er - tau_e - tau_r - 2z)) / (sqrt(L_er) cos theta)
// (L_er: image-to-receiver distance, theta its angle from the elements' normal, which is
// also its angle from the plane's, D = sinc(pi p sin theta / lambda) cos theta, tau: the
// transmit and dynamic-receive focusing delays) times sqrt(lambda) from the stationary
// phase over the plane, over each field's unit-power norm sqrt((lambda / p) sum w^2). No
// lateral integral and no table; a perfect mirror at the focus with matched apertures
// would give 1. The weights a, b are the apertures' definitions (probe/aperture.h).
double plane_echo_by_image_sources(const probe::Transducer& t, double z) {
    const double lambda = t.wavelength_mm(), k = 2.0 * std::numbers::pi / lambda;
    const probe::LineArray array = probe::line_array(t, t.lines / 2);
    const std::vector<double> tx =
        probe::aperture_weights(array, t.active_aperture_mm(), t.tx_apodization);
    const std::vector<double> rx =
        probe::aperture_weights(array, t.receive_aperture_mm(z), t.rx_apodization);
    auto directivity = [&](double sin_theta, double cos_theta) {
        const double x = std::numbers::pi * t.pitch_mm * sin_theta / lambda;
        return (std::abs(x) < 1e-12 ? 1.0 : std::sin(x) / x) * cos_theta;
    };
    std::complex<double> sum = 0.0;
    double tx2 = 0.0, rx2 = 0.0;
    for (double w : tx) tx2 += w * w;
    for (double w : rx) rx2 += w * w;
    for (std::size_t e = 0; e < tx.size(); ++e) {
        if (tx[e] == 0.0) continue;
        const glm::dvec2 pe = array.position[e], image(pe.x, 2.0 * z - pe.y);
        const double tau_e = glm::length(glm::dvec2(0.0, t.focus_mm) - pe) - t.focus_mm;
        for (std::size_t q = 0; q < rx.size(); ++q) {
            if (rx[q] == 0.0) continue;
            const glm::dvec2 pr = array.position[q];
            const double L = glm::length(pr - image);
            const double sin_theta = (pr.x - pe.x) / L, cos_theta = (2.0 * z) / L;
            const double tau_r = glm::length(glm::dvec2(0.0, z) - pr) - z;
            const double d = directivity(sin_theta, cos_theta);
            sum += tx[e] * rx[q] * d * d / (std::sqrt(L) * cos_theta) *
                   std::polar(1.0, -k * (L - tau_e - tau_r - 2.0 * z));
        }
    }
    return std::abs(sum) * std::sqrt(lambda) * (t.pitch_mm / lambda) / std::sqrt(tx2 * rx2);
}

// Water without attenuation, and a speed-matched layer of it whose density reflects the
// amplitude fraction r against `below` (Z (1 + r) / (1 - r)).
tissue::AcousticProperties lossless_water() {
    tissue::AcousticProperties w;
    w[tissue::Property::speed_of_sound] = float(kC0);
    w[tissue::Property::density] = 1000.0f;
    return w;
}
// Everything deeper than z (a half-space facing the probe) made of `properties`.
phantoms::Shape plane_below(double z, const tissue::AcousticProperties& properties) {
    phantoms::Shape plane;
    plane.type = phantoms::ShapeType::half_space;
    plane.a = {20.0, z, 0.0}, plane.b = {0.0, 1.0, 0.0};
    plane.properties = properties;
    return plane;
}

tissue::AcousticProperties reflecting(const tissue::AcousticProperties& above, double r) {
    tissue::AcousticProperties p = above;
    p[tissue::Property::density] = float(above[tissue::Property::density] * (1.0 + r) / (1.0 - r));
    return p;
}

}  // namespace

CaseResult flat_reflector(const CaseContext& ctx) {
    // The echo of a perpendicular flat reflector, moved from 6 to 40 mm in 0.5 mm steps,
    // in water without attenuation (a speed-matched density step, R = 0.05: scored, not
    // followed), against R times the plane echo by image sources (above): its mean level
    // within 1 dB, every depth within 1 dB, and no swing above 0.5 dB about a quadratic
    // trend (the swing the issue found had a 2 mm period).
    CaseResult r;
    probe::Transducer t = probe::find_transducer("linear", "validation");
    t.lines = 3;  // the frames' lines; the middle one is measured
    const tissue::AcousticProperties water = lossless_water();
    constexpr double kReflection = 0.05;  // amplitude; the beam carries unit power
    const tissue::AcousticProperties denser = reflecting(water, kReflection);
    std::vector<double> depth, measured_db, expected_db;
    for (double z = 6.0; z <= 40.0 + 1e-9; z += 0.5) {
        phantoms::Phantom ph;
        ph.name = "flat reflector", ph.source = "validation:flat_reflector";
        ph.size = {40.0, std::max(z, t.focus_mm) + 8.0, 10.0};
        ph.smoothing_mm = 0.1;
        ph.background = water;
        ph.shapes.push_back(plane_below(z, denser));
        ph.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
        const PhantomFrame f = image_phantom(
            ph, {std::max(z, t.focus_mm) + 4.0, 3, imaging::Quality::standard, false}, ctx.seed);
        depth.push_back(z);
        measured_db.push_back(20.0 * std::log10(line_peak(f.frame.envelope, 1, z - 1.0, z + 1.0)));
        expected_db.push_back(20.0 * std::log10(kReflection * plane_echo_by_image_sources(t, z)));
    }
    const std::size_t n = depth.size();
    double offset = 0.0;
    for (std::size_t i = 0; i < n; ++i) offset += (measured_db[i] - expected_db[i]) / double(n);
    std::vector<double> residual(n);
    double worst = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        residual[i] = measured_db[i] - expected_db[i] - offset;
        worst = std::max(worst, std::abs(residual[i]));
    }
    // The residual about its least-squares quadratic in depth (normal equations, 3 x 3).
    cv::Mat A(int(n), 3, CV_64F), b(int(n), 1, CV_64F), coef;
    for (std::size_t i = 0; i < n; ++i) {
        const double u = (depth[i] - 23.0) / 17.0;
        A.at<double>(int(i), 0) = 1.0, A.at<double>(int(i), 1) = u, A.at<double>(int(i), 2) = u * u;
        b.at<double>(int(i)) = residual[i];
    }
    cv::solve(A, b, coef, cv::DECOMP_SVD);
    double swing = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double u = (depth[i] - 23.0) / 17.0;
        const double trend =
            coef.at<double>(0) + coef.at<double>(1) * u + coef.at<double>(2) * u * u;
        swing = std::max(swing, std::abs(residual[i] - trend));
    }
    r.measurements.push_back(
        {"mean level against R x the plane echo (unit beam power)", offset, 0.0, 1.0, "dB"});
    r.measurements.push_back({"largest deviation from the on-axis two-way response (6-40 mm)",
                              worst, 1.0, 0.0, "dB", Check::at_most});
    r.measurements.push_back(
        {"largest residual about a quadratic trend", swing, 0.5, 0.0, "dB", Check::at_most});
    Plot plot{"echo of a flat reflector against depth (linear probe, focus 20 mm)",
              "depth of the reflector (mm)",
              "echo level (dB, one constant fitted)",
              {{"image sources of the aperture", {}, {}, false}, {"measured", {}, {}, true}},
              {t.focus_mm}};
    for (std::size_t i = 0; i < n; ++i) {
        plot.series[0].x.push_back(depth[i]), plot.series[0].y.push_back(expected_db[i] + offset);
        plot.series[1].x.push_back(depth[i]), plot.series[1].y.push_back(measured_db[i]);
    }
    r.plots.push_back(plot);
    return r;
}

CaseResult two_layers(const CaseContext& ctx) {
    // Water over two speed-matched layers (R12 = 0.3 at 10 mm, followed stochastically;
    // R23 = 0.2 at 20 mm): the second echo's intensity over the first's, each divided by
    // the on-axis plane echo at its depth (image sources, above), must be
    // R23^2 (1 - R12^2)^2 / R12^2 (the second echo crosses the first interface twice)
    // within 20 %. Averaged over the 27 lines within 8 mm of the centre, whose apertures
    // the array does not clip (the lines' particles choose reflection or transmission at
    // random: ~6 % spread per line).
    CaseResult r;
    constexpr double kR12 = 0.3, kR23 = 0.2, kZ1 = 10.0, kZ2 = 20.0;
    const tissue::AcousticProperties water = lossless_water();
    const tissue::AcousticProperties second = reflecting(water, kR12);
    const tissue::AcousticProperties third = reflecting(second, kR23);
    phantoms::Phantom ph;
    ph.name = "two layers", ph.source = "validation:two_layers";
    ph.size = {40.0, 40.0, 10.0};
    ph.smoothing_mm = 0.1;
    ph.background = water;
    ph.shapes = {plane_below(kZ1, second), plane_below(kZ2, third)};
    ph.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
    const PhantomFrame f =
        image_phantom(ph, {30.0, 65, imaging::Quality::standard, false}, ctx.seed);
    probe::Transducer centre = f.transducer;  // the middle line's apertures
    const double response2 = std::pow(
        plane_echo_by_image_sources(centre, kZ2) / plane_echo_by_image_sources(centre, kZ1), 2.0);
    const probe::ScanGeometry g(f.transducer);
    double sum = 0.0;
    int lines = 0;
    for (int l = 0; l < f.transducer.lines; ++l) {
        if (std::abs(g.point(l, 0.0).x) > 8.0) continue;
        const double a1 = line_peak(f.frame.envelope, l, kZ1 - 1.0, kZ1 + 1.0);
        const double a2 = line_peak(f.frame.envelope, l, kZ2 - 1.0, kZ2 + 1.0);
        sum += (a2 * a2) / (a1 * a1) / response2;
        ++lines;
    }
    const double expected = kR23 * kR23 * std::pow(1.0 - kR12 * kR12, 2.0) / (kR12 * kR12);
    r.measurements.push_back({"second / first echo intensity, on-axis response divided out (" +
                                  std::to_string(lines) + " lines)",
                              sum / lines, expected, 0.2 * expected, ""});
    return r;
}

}  // namespace sonotrace::validation
