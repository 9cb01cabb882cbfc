// Imaging case: axial and lateral resolution against a broadband element sum written out
// here, independent of the image pipeline.
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

// The element sum of probe/aperture.h written out again for a linear array, over the
// pulse's whole spectrum, as the prediction the lateral resolution is held to
// (independent of the image pipeline, whose point targets go through probe::LineFields):
// the line at lateral position x_line (mm), the point (x, z); rectangular, Hann or Tukey
// weights across the clipped active span; elements of the preset's width (sinc
// directivity, cosine obliquity), 1/sqrt(r) cylindrical spreading, focusing delays to the
// transmit focus and to the point's depth, each field normalised to unit lateral power at
// its frequency; the echo's envelope peak over the pulse's spectrum (PulseSpectrum, f0 / 50
// apart), over +-6 periods.
struct ReferenceLinearArray {
    probe::Transducer t;
    PulseSpectrum spectrum;
    explicit ReferenceLinearArray(const probe::Transducer& transducer)
        : t(transducer), spectrum(transducer, 50.0, 6.0) {}
    static double weight(probe::Apodization a, double u) {
        if (u < 0.0 || u > 1.0) return 0.0;
        if (a == probe::Apodization::hann) return 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * u);
        if (a == probe::Apodization::tukey) {
            const double e = std::min(u, 1.0 - u);
            return e >= 0.25 ? 1.0 : 0.5 - 0.5 * std::cos(std::numbers::pi * e / 0.25);
        }
        return 1.0;
    }
    std::complex<double> field(double x_line, double width, probe::Apodization a, double focus,
                               double x, double z, double f) const {
        const double lambda = kC0 / f * 1e3, k = 2.0 * std::numbers::pi / lambda;
        const double half_array = 0.5 * t.elements * t.pitch_mm;
        width = std::max(width, 2.0 * t.pitch_mm);
        const double lo = std::max(x_line - 0.5 * width, -half_array),
                     hi = std::min(x_line + 0.5 * width, half_array);
        std::complex<double> sum = 0.0;
        double w2 = 0.0;
        for (int e = 0; e < t.elements; ++e) {
            const double xe = -half_array + (e + 0.5) * t.pitch_mm;
            if (xe < lo || xe > hi) continue;
            const double dx = x - xe, r = std::hypot(dx, z);
            const double s = std::numbers::pi * t.element_width_mm * (dx / r) / lambda;
            const double directivity = (s == 0.0 ? 1.0 : std::sin(s) / s) * (z / r);
            const double path = r - std::hypot(x_line - xe, focus) + focus - z;
            const double w = weight(a, (xe - lo) / (hi - lo));
            w2 += w * w;
            sum += w * directivity / std::sqrt(r) * std::polar(1.0, -k * path);
        }
        return sum / std::sqrt(lambda / t.pitch_mm * std::max(w2, 1e-30));
    }
    // The envelope peak of the echo on the line at x_line of a point at (x, z), the
    // receive focused at z, over the pulse's.
    double two_way(double x_line, double x, double z) const {
        const double tx = std::min(t.focus_mm / t.f_number, t.elements * t.pitch_mm);
        const double rx = std::min(z / t.rx_f_number, t.elements * t.pitch_mm);
        std::vector<std::complex<double>> h;
        for (double f : spectrum.frequency())
            h.push_back(field(x_line, tx, t.tx_apodization, t.focus_mm, x, z, f) *
                        field(x_line, rx, t.rx_apodization, z, x, z, f));
        return spectrum.peak(h);
    }
};

// A 0.1 mm wire target at (x, z) of the probe plane in water, imaged by `t` through the
// beams without being traced (speckle off).
PhantomFrame wire_in_water(const probe::Transducer& t, const tissue::AcousticProperties& water,
                           double x, double z, uint64_t seed) {
    PhantomFrame f;
    f.phantom.name = "lateral", f.phantom.source = "validation:resolution";
    f.phantom.size = {40.0, 40.0, 10.0};
    f.phantom.background = water;
    f.phantom.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
    f.transducer = t;
    imaging::SimulationSettings settings;
    settings.transducer = t;
    settings.quality = imaging::Quality::standard;
    settings.imaging.speckle = false;
    settings.seed = seed;
    tissue::PointTarget wire;
    wire.type = tissue::PointTarget::Type::wire;
    wire.at = {20.0 + x, z, 5.0};
    settings.targets = {wire};
    const imaging::PlaneGrid grid = imaging::plane_grid(t, f.phantom.pose, 0.25);
    const auto map = imaging::frame_map(phantoms::rasterise(f.phantom, grid.geometry), settings);
    f.frame = imaging::simulate_frame(map, grid, f.phantom.pose, settings);
    return f;
}

}  // namespace

CaseResult resolution(const CaseContext& ctx) {
    CaseResult r;
    // Axial: the echo of a flat interface (water over a bone-like half-space at 15 mm,
    // one reflection, no back wall) is the pulse-echo waveform's envelope: its FWHM in
    // depth is c0/2 times the envelope's in time. The waveform (an n-cycle sine (*) the
    // two-way impulse response, probe/pulse.h) is checked against a first-principles
    // construction in tests/imaging/test_psf.cpp; here the image must keep its width, within 10 %.
    const tissue::AcousticProperties water = [] {
        tissue::AcousticProperties p;
        p[tissue::Property::speed_of_sound] = float(kC0);
        p[tissue::Property::density] = 1000.0f;
        return p;
    }();
    tissue::AcousticProperties bone = water;
    bone[tissue::Property::speed_of_sound] = 3000.0f;
    bone[tissue::Property::density] = 1900.0f;
    {
        phantoms::Phantom ph;
        ph.name = "axial", ph.source = "validation:resolution";
        ph.size = {40.0, 30.0, 10.0};
        ph.smoothing_mm = 0.1;
        ph.background = water;
        phantoms::Shape s;
        s.type = phantoms::ShapeType::half_space;
        s.a = {20.0, 15.0, 0.0}, s.b = {0.0, 1.0, 0.0};
        s.properties = bone;
        ph.shapes.push_back(s);
        ph.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
        const PhantomFrame f =
            image_phantom(ph, {25.0, 32, imaging::Quality::high, false}, ctx.seed);
        const imaging::LineData& env = f.frame.envelope;
        const int l = env.lines / 2;
        int peak = 0;
        for (int i = 0; i < env.samples; ++i)
            if (env.at(l, i) > env.at(l, peak)) peak = i;
        const double fwhm =
            base::half_maximum(env.samples, peak, [&](int i) { return env.at(l, i); }).width() *
            (env.depth_mm(1) - env.depth_mm(0));
        const probe::Transducer& t = f.transducer;
        const double expected = probe::PulseEcho(t).axial_fwhm_mm();
        r.measurements.push_back({"axial FWHM (linear 7.6 MHz, B 0.79, one cycle)", fwhm, expected,
                                  0.1 * expected, "mm"});
        Plot plot{"axial profile of a flat interface's echo",
                  "depth from the peak (mm)",
                  "envelope / peak",
                  {{"pulse-echo envelope", {}, {}, false}, {"measured", {}, {}, true}},
                  {}};
        const probe::PulseEcho pulse(t);
        for (int i = std::max(0, peak - 12); i <= std::min(env.samples - 1, peak + 12); ++i) {
            plot.series[1].x.push_back(env.depth_mm(i) - env.depth_mm(peak));
            plot.series[1].y.push_back(env.at(l, i) / env.at(l, peak));
        }
        for (double d = -0.5; d <= 0.5; d += 0.01) {
            const double time_s = 2.0 * d * 1e-3 / kC0;
            plot.series[0].x.push_back(d);
            plot.series[0].y.push_back(
                std::hypot(pulse.in_phase(time_s), pulse.quadrature(time_s)));
        }
        r.plots.push_back(plot);
    }
    // Lateral: a 0.1 mm wire target at the transmit focus (20 mm), imaged through the
    // beams without being traced, across 512 lines 0.075 mm apart. With uniform (rectangular)
    // transmit and receive apertures of the same width D = z / F# at the focus, the
    // two-way field there is the square of the aperture's Fraunhofer pattern,
    // sinc^2(pi D x / (lambda z)): FWHM 0.886 lambda F# (sinc(u) = 1/sqrt 2 at
    // u = 1.3916) and a first side lobe of sinc^2 at u = 4.4934, -26.5 dB. Element
    // directivity and cylindrical spreading change both by under a percent at F/2.
    {
        probe::Transducer t = probe::find_transducer("linear", "validation");
        t.lines = 512;
        t.depth_mm = 24.0;
        t.tx_apodization = probe::Apodization::rectangular;
        t.rx_apodization = probe::Apodization::rectangular;
        t.rx_f_number = t.f_number;
        const PhantomFrame f = wire_in_water(t, water, 0.03, t.focus_mm, ctx.seed);
        const LateralProfile p = lateral_profile(f, t.focus_mm - 1.0, t.focus_mm + 1.0, -3.0, 3.0);
        const double lambda = t.wavelength_mm();
        const double expected = 0.886 * lambda * t.f_number;
        r.measurements.push_back({"lateral FWHM at the focus (20 mm, F/2, uniform apertures)",
                                  p.fwhm, expected, 0.1 * expected, "mm"});
        // First side lobe: the largest peak between the first zero (lambda F# from the
        // centre) and the second (2 lambda F#), on both sides.
        const double top = *std::max_element(p.peak.begin(), p.peak.end());
        double lobe = 0.0;
        for (std::size_t i = 0; i < p.x.size(); ++i) {
            const double off = std::abs(p.x[i] - p.centre);
            if (off > 1.1 * lambda * t.f_number && off < 1.9 * lambda * t.f_number)
                lobe = std::max(lobe, p.peak[i]);
        }
        const double sinc_lobe = std::sin(4.4934) / 4.4934;
        r.measurements.push_back({"first side lobe (two-way)", 20.0 * std::log10(lobe / top),
                                  40.0 * std::log10(std::abs(sinc_lobe)), 3.0, "dB"});
        Plot plot{"lateral profile of a 0.1 mm wire at the focus (512 lines)",
                  "lateral position (mm)",
                  "envelope / peak",
                  {{"sinc^2 of the uniform aperture", {}, {}, false}, {"measured", {}, {}, true}},
                  {}};
        for (std::size_t i = 0; i < p.x.size(); ++i) {
            if (std::abs(p.x[i] - p.centre) > 1.5) continue;
            plot.series[1].x.push_back(p.x[i]), plot.series[1].y.push_back(p.peak[i] / top);
        }
        for (double x = -1.5; x <= 1.5; x += 0.01) {
            const double u = std::numbers::pi * x / (lambda * t.f_number);
            const double sinc = std::abs(u) < 1e-9 ? 1.0 : std::sin(u) / u;
            plot.series[0].x.push_back(p.centre + x);
            plot.series[0].y.push_back(sinc * sinc);
        }
        r.plots.push_back(plot);
    }
    // Lateral at 10, 20 and 30 mm with the preset's apertures (transmit focus 20 mm at F/2,
    // Tukey; receive Hann) and rectangular ones, for a receive at F/2 and on the whole array: the
    // FWHM of a 0.1 mm wire across 768 lines 0.05 mm apart within 10 % of the broadband element
    // sum's, and its first side lobe within 2 dB.
    for (const bool rectangular : {false, true})
        for (const double rx_f : {2.0, 0.1}) {
            probe::Transducer t = probe::find_transducer("linear", "validation");
            t.lines = 768;
            t.rx_f_number = rx_f;
            if (rectangular) t.tx_apodization = t.rx_apodization = probe::Apodization::rectangular;
            const char* apertures = rectangular ? "rectangular" : "preset apodization";
            const ReferenceLinearArray reference(t);
            for (const double z : {10.0, 20.0, 30.0}) {
                t.depth_mm = z + 4.0;
                const double x0 = 0.013;  // off any line
                const PhantomFrame f = wire_in_water(t, water, x0, z, ctx.seed);
                const LateralProfile measured = lateral_profile(f, z - 1.0, z + 1.0, -3.0, 3.0);
                std::vector<double> predicted;
                for (const double xl : measured.x)
                    predicted.push_back(reference.two_way(xl, x0, z));
                const double expected = analyse_lateral(measured.x, predicted).fwhm;
                char quantity[96];
                std::snprintf(quantity, sizeof quantity, "lateral FWHM at %.0f mm, receive %s, %s",
                              z, rx_f < 1.0 ? "on the whole array" : "at F/2", apertures);
                r.measurements.push_back({quantity, measured.fwhm, expected, 0.1 * expected, "mm"});
                std::snprintf(quantity, sizeof quantity,
                              "first side lobe at %.0f mm, receive %s, %s", z,
                              rx_f < 1.0 ? "on the whole array" : "at F/2", apertures);
                r.measurements.push_back({quantity, first_side_lobe_db(measured.peak),
                                          first_side_lobe_db(predicted), 2.0, "dB"});
            }
        }
    return r;
}

}  // namespace sonotrace::validation
