// The broadband aperture model (probe/pulse.h's Band, probe/aperture.h's broadband
// fields, imaging/psf.h's tables) against the fuller physics written out here: the
// pulse-echo waveform summed over a dense spectrum of the element fields, each frequency's
// field a direct double-precision sum over the elements.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <vector>

#include "probe/aperture.h"
#include "probe/pulse.h"
#include "probe/transducer.h"

namespace sonotrace {
namespace {

// Poisson's summation: the band's weights sum back to the tabulated waveform within its
// window. Tolerance 2e-3 of the peak: the skirts dropped below 1e-3 of the spectrum's peak.
TEST(PulseBand, SumsBackToTheWaveformWithinItsWindow) {
    for (const probe::Transducer& t : probe::transducer_presets()) {
        const probe::PulseEcho pulse(t);
        const double period = 1.0 / pulse.frequency_hz();
        const probe::PulseEcho::Band band = pulse.band(3.0 * period);
        SCOPED_TRACE(t.name + ": " + std::to_string(band.count()) + " frequencies");
        EXPECT_LE(band.count(), 24);
        EXPECT_GT(band.first_hz, 0.0);
        double worst = 0.0;
        for (double x = -pulse.half_length_s(); x <= pulse.half_length_s(); x += period / 16)
            worst = std::max(worst, std::abs(band.waveform(x) - pulse.analytic(x)));
        EXPECT_LT(worst, 2e-3);
        std::printf("%s: %d frequencies, worst %.2e; energy band %d\n", t.name.c_str(), band.count(), worst, pulse.band(0.0, probe::kEnergyFloor).count());
        // Beyond the window the waveform repeats: the band is periodic in 1 / step.
        EXPECT_NEAR(std::abs(band.waveform(1.0 / band.step_hz)), std::abs(band.waveform(0.0)), 1e-9);
    }
}

constexpr double kPi = std::numbers::pi;

// The fuller physics, written out independently of probe/aperture.cpp: the pulse-echo
// spectrum S(f) (n cycles of a sine at f0, integrated directly, times the transducer's
// stated two-way response, the generalized Gaussian through B6 and B20 = shape B6) on a
// grid f0 / 100 apart (a window of 100 periods: nothing wraps), and at each frequency the
// 2D element sums in double: sum_e w_e D_e(f) exp(-i k path_e) / sqrt(r_e), D_e =
// sinc(pi w sin(theta) / lambda) cos(theta), normalised by sqrt(pitch / (lambda sum
// w_e^2)), the receive focused at the point's depth. The echo h(t) = sum_f S T R exp(i 2
// pi f t) df on a grid of f0 / 32 over +-8 periods; the image's lateral profile is its
// envelope's peak over t, over the pulse's own.
class Reference {
  public:
    // periods: the window 1 / df in periods of f0 (df = f0 / periods).
    Reference(const probe::Transducer& t, int line, double periods = 100.0)
        : t_(t), array_(probe::line_array(t, line)),
          tx_(probe::aperture_weights(array_, t.active_aperture_mm(), t.tx_apodization)) {
        const double f0 = t.frequency_mhz * 1e6, df = f0 / periods;
        const double exponent = std::log(std::log(10.0) / std::log(2.0)) / std::log(t.band_shape);
        for (double f = df; f < 3.0 * f0; f += df) {
            const double u = (f - f0) / (0.5 * t.bandwidth * f0);
            const double response = std::exp(-std::log(2.0) * std::pow(std::abs(u), exponent));
            std::complex<double> excitation = 0.0;
            const int steps = int(std::lround(400 * t.cycles));
            const double dt = t.cycles / f0 / steps;
            for (int i = 0; i < steps; ++i) {
                const double time = (i + 0.5) * dt;
                excitation += std::sin(2 * kPi * f0 * time) * std::polar(dt, -2 * kPi * f * time);
            }
            const std::complex<double> s = excitation * response * df;
            if (std::abs(s) < 1e-7 * df / f0) continue;
            frequency_.push_back(f), spectrum_.push_back(s);
        }
        for (int k = -8 * 32; k <= 8 * 32; ++k)
            for (double f : frequency_)
                carrier_.push_back(std::polar(1.0, 2 * kPi * f * k / (32.0 * f0)));
        pulse_peak_ = peak(std::vector<std::complex<double>>(frequency_.size(), 1.0));
    }
    // The envelope's peak over t of sum_f S(f) H(f) exp(i 2 pi f t).
    double peak(const std::vector<std::complex<double>>& h) const {
        std::vector<std::complex<double>> sh(h.size());
        for (std::size_t i = 0; i < h.size(); ++i) sh[i] = spectrum_[i] * h[i];
        double best = 0.0;
        for (std::size_t at = 0; at < carrier_.size(); at += sh.size()) {
            std::complex<double> e = 0.0;
            for (std::size_t i = 0; i < sh.size(); ++i) e += sh[i] * carrier_[at + i];
            best = std::max(best, std::abs(e));
        }
        return best;
    }
    std::complex<double> field(const glm::dvec2& q, const std::vector<double>& w, double focus,
                               double f) const {
        const double lambda = 1540e3 / f, k = 2 * kPi / lambda;
        std::complex<double> sum = 0.0;
        double w2 = 0.0;
        for (std::size_t e = 0; e < w.size(); ++e) {
            w2 += w[e] * w[e];
            if (w[e] == 0.0) continue;
            const glm::dvec2 d = q - array_.position[e], n = array_.normal[e];
            const double r = glm::length(d);
            const double cos_t = glm::dot(d, n) / r, sin_t = (d.x * n.y - d.y * n.x) / r;
            const double a = kPi * t_.element_width_mm * sin_t / lambda;
            const double directivity = (a == 0.0 ? 1.0 : std::sin(a) / a) * std::max(cos_t, 0.0);
            const double path = r - glm::length(glm::dvec2(0.0, focus) - array_.position[e]) +
                                focus - q.y;
            sum += w[e] * directivity * std::polar(1.0 / std::sqrt(r), -k * path);
        }
        return sum / std::sqrt(lambda / t_.pitch_mm * w2);
    }
    // T_f R_f at every frequency of the dense grid.
    std::vector<std::complex<double>> two_way(const glm::dvec2& q) const {
        const auto rx =
            probe::aperture_weights(array_, t_.receive_aperture_mm(q.y), t_.rx_apodization);
        std::vector<std::complex<double>> h;
        for (double f : frequency_)
            h.push_back(field(q, tx_, t_.focus_mm, f) * field(q, rx, q.y, f));
        return h;
    }
    // The echo's energy over the pulse's: sum |S H|^2 / sum |S|^2 (Parseval).
    double energy(const std::vector<std::complex<double>>& h) const {
        double e = 0.0, p = 0.0;
        for (std::size_t i = 0; i < h.size(); ++i)
            e += std::norm(spectrum_[i] * h[i]), p += std::norm(spectrum_[i]);
        return e / p;
    }
    // sum_f |S|^2 H_f(a) conj(H_f(b)) / sum |S|^2: the broadband PSF's correlation.
    std::complex<double> correlation(const std::vector<std::complex<double>>& a,
                                     const std::vector<std::complex<double>>& b) const {
        std::complex<double> c = 0.0;
        double p = 0.0;
        for (std::size_t i = 0; i < a.size(); ++i)
            c += std::norm(spectrum_[i]) * a[i] * std::conj(b[i]), p += std::norm(spectrum_[i]);
        return c / p;
    }
    // A plane reflector through (0, z) perpendicular to the line: at each frequency the
    // integral of T R over the plane (receive focused at z), by the trapezoid rule over
    // +-reach at dx, then the envelope's peak over the pulse's.
    double plane_echo_peak(double z, double reach, double dx) const {
        const auto rx =
            probe::aperture_weights(array_, t_.receive_aperture_mm(z), t_.rx_apodization);
        std::vector<std::complex<double>> e(frequency_.size(), 0.0);
        for (double x = -reach; x <= reach + 1e-9; x += dx)
            for (std::size_t i = 0; i < frequency_.size(); ++i)
                e[i] += field({x, z}, tx_, t_.focus_mm, frequency_[i]) *
                        field({x, z}, rx, z, frequency_[i]) * dx;
        return peak(e) / pulse_peak_;
    }
    // The image's lateral profile value at q: max_t |h| / max_t |p|.
    double two_way_peak(const glm::dvec2& q) const {
        const auto rx =
            probe::aperture_weights(array_, t_.receive_aperture_mm(q.y), t_.rx_apodization);
        std::vector<std::complex<double>> h;
        for (double f : frequency_)
            h.push_back(field(q, tx_, t_.focus_mm, f) * field(q, rx, q.y, f));
        return peak(h) / pulse_peak_;
    }

  private:
    probe::Transducer t_;
    probe::LineArray array_;
    std::vector<double> tx_;
    std::vector<double> frequency_;
    std::vector<std::complex<double>> spectrum_, carrier_;  // carrier_: [time][frequency]
    double pulse_peak_ = 1.0;
};

struct Lobes {
    double fwhm_mm, first_side_lobe_db;
};
// FWHM (linear interpolation of the half-maximum crossings) and the first side lobe
// (the highest of the first maxima past the first minima either side) of a profile
// sampled dx apart.
Lobes lobes(const std::vector<double>& v, double dx) {
    const int peak = int(std::max_element(v.begin(), v.end()) - v.begin());
    const double half = 0.5 * v[std::size_t(peak)];
    Lobes out{0.0, -300.0};
    double width = 0.0;
    for (int step : {-1, 1}) {
        int i = peak;
        while (i + step >= 0 && i + step < int(v.size()) && v[std::size_t(i + step)] > half) i += step;
        const double a = v[std::size_t(i)], b = v[std::size_t(i + step)];
        width += std::abs(i + step * (a - half) / (a - b) - peak);
        int j = i;
        while (j + step >= 0 && j + step < int(v.size()) && v[std::size_t(j + step)] < v[std::size_t(j)])
            j += step;
        while (j + step >= 0 && j + step < int(v.size()) && v[std::size_t(j + step)] > v[std::size_t(j)])
            j += step;
        if (j + step >= 0 && j + step < int(v.size()))
            out.first_side_lobe_db = std::max(
                out.first_side_lobe_db, 20.0 * std::log10(v[std::size_t(j)] / v[std::size_t(peak)]));
    }
    // Lobes below -60 dB are numerical ripple of a smooth skirt: none.
    out.first_side_lobe_db = std::max(out.first_side_lobe_db, -60.0);
    out.fwhm_mm = width * dx;
    return out;
}

// The lateral profile of a point target (what its image shows line by line) through the
// broadband fields, against the reference: FWHM within 5 % (issue 51: 10 %) and the first
// side lobe within 1.5 dB (issue 51: 2 dB) at 10, 20 and 30 mm, for a receive at F/2 and
// the whole array, rectangular and the preset's apodizations. The narrowband field misses
// the side lobes by 4-6 dB here.
TEST(BroadbandFields, PointTargetLateralProfileFollowsTheBroadbandElementSum) {
    for (const bool preset_apodization : {false, true})
        for (const double rx_f_number : {2.0, 0.25}) {
            probe::Transducer t = probe::find_transducer("linear", "test");
            t.rx_f_number = rx_f_number;
            if (!preset_apodization)
                t.tx_apodization = t.rx_apodization = probe::Apodization::rectangular;
            const int line = t.lines / 2;
            const probe::LineFields fields(t, probe::line_array(t, line));
            const Reference reference(t, line);
            for (const double z : {10.0, 20.0, 30.0}) {
                SCOPED_TRACE("z " + std::to_string(z) + " mm, rx F/" + std::to_string(rx_f_number) +
                             (preset_apodization ? ", preset apodization" : ", rectangular"));
                const double dx = 0.02, reach = 0.25 * z;
                std::vector<double> model, expected, narrowband;
                for (double x = -reach; x <= reach + 1e-9; x += dx) {
                    model.push_back(std::abs(fields.two_way({x, z})));
                    narrowband.push_back(std::abs(fields.two_way_narrowband({x, z})));
                    expected.push_back(reference.two_way_peak({x, z}));
                }
                const Lobes m = lobes(model, dx), e = lobes(expected, dx),
                            n = lobes(narrowband, dx);
                std::printf(
                    "z %4.1f rx F/%.2f %s: FWHM %.3f / %.3f mm, side lobe %.1f / %.1f dB "
                    "(narrowband %.3f mm %.1f dB)\n",
                    z, rx_f_number, preset_apodization ? "preset" : "rect  ", m.fwhm_mm, e.fwhm_mm,
                    m.first_side_lobe_db, e.first_side_lobe_db, n.fwhm_mm, n.first_side_lobe_db);
                EXPECT_NEAR(m.fwhm_mm / e.fwhm_mm, 1.0, 0.05);
                // A skirt without a lobe above -50 dB (the broadband beam's usual case away
                // from the focus): the model's ripple stays below -45 dB.
                if (e.first_side_lobe_db > -50.0)
                    EXPECT_NEAR(m.first_side_lobe_db, e.first_side_lobe_db, 1.5);
                else
                    EXPECT_LT(m.first_side_lobe_db, -45.0);
            }
        }
}

// A flat reflector's echo from 6 to 40 mm (LineFields::plane_echo: image sources and
// stationary phase at each frequency of the band) against the integral of T R over the
// plane at every frequency of a grid f0 / 25 apart (a 25-period window: a plane's echo
// spreads over a few periods at most), within 0.5 dB (issue 51: 1 dB), rectangular and
// preset apertures. Both normalise as the simulator does: each field to unit lateral power
// at its frequency, so a matched transmit and receive return the whole beam (1).
TEST(BroadbandFields, FlatReflectorEchoFollowsTheIntegralOverThePlane) {
    for (const bool rectangular : {true, false}) {
        probe::Transducer t = probe::find_transducer("linear", "test");
        if (rectangular) t.tx_apodization = t.rx_apodization = probe::Apodization::rectangular;
        const int line = t.lines / 2;
        const probe::LineFields fields(t, probe::line_array(t, line));
        const Reference reference(t, line, 25.0);
        double worst = 0.0, narrowband_worst = 0.0;
        for (double z = 6.0; z <= 40.0; z += 4.25) {
            const double expected = reference.plane_echo_peak(z, 0.5 * t.array_length_mm() + 4.0, 0.025);
            const double db = 20.0 * std::log10(std::abs(fields.plane_echo(z, 0.0)) / expected);
            worst = std::max(worst, std::abs(db));
            std::printf("z %5.2f %s: plane echo %+.2f dB from the integral (%.3f)\n", z,
                        rectangular ? "rect  " : "preset", db, expected);
            EXPECT_NEAR(db, 0.0, 0.5) << "z " << z;
        }
        (void)narrowband_worst;
        std::printf("worst %.2f dB\n", worst);
    }
}

// The speckle's share of the table (LineFields::speckle on the energy band) against the
// dense reference: the lateral power integral sum |S H|^2 dx / sum |S|^2, which sets the
// mean speckle level, within 0.3 dB from 5 to 40 mm (issue 51: speckle level within 1.5
// dB), and the width of the lateral correlation |integral w(x) conj w(x + d) dx| (the
// speckle grain; the reference correlates every frequency's PSF and sums them weighted by
// |S|^2) within 8 % at the focus and at 10 and 30 mm (issue 51: 10 %; the weight's phase is
// H's at f0, measured 1-6 % wider than the sum over the band; the energy-weighted mean
// phase was 4-10 % wider).
TEST(BroadbandFields, SpeckleTableEnergyFollowsTheFullBand) {
    for (const bool rectangular : {true, false}) {
        probe::Transducer t = probe::find_transducer("linear", "test");
        if (rectangular) t.tx_apodization = t.rx_apodization = probe::Apodization::rectangular;
        const int line = t.lines / 2;
        const probe::LineFields fields(t, probe::line_array(t, line));
        const Reference reference(t, line);
        for (const double z : {5.0, 10.0, 20.0, 30.0, 40.0}) {
            SCOPED_TRACE("z " + std::to_string(z) + (rectangular ? " rectangular" : " preset"));
            const double dx = 0.02, reach = std::max(0.25 * z, 3.0);
            const auto receive = fields.receive_aperture(z);
            std::vector<std::complex<double>> weight;
            std::vector<std::vector<std::complex<double>>> dense;
            double power = 0.0, expected = 0.0;
            for (double x = -reach; x <= reach + 1e-9; x += dx) {
                const auto s = fields.speckle({x, z}, receive);
                weight.push_back(s.weight);
                power += s.power * dx;
                dense.push_back(reference.two_way({x, z}));
                expected += reference.energy(dense.back()) * dx;
            }
            const double db = 10.0 * std::log10(power / expected);
            EXPECT_NEAR(db, 0.0, 0.3);
            if (z == 5.0 || z == 40.0) continue;
            // Correlation widths at half the zero lag's magnitude.
            auto width = [&](auto correlate) {
                const double zero = std::abs(correlate(0));
                for (int d = 1; d < int(weight.size()); ++d) {
                    const double c = std::abs(correlate(d));
                    if (c < 0.5 * zero) {
                        const double before = std::abs(correlate(d - 1));
                        return 2.0 * dx * (d - 1 + (before - 0.5 * zero) / (before - c));
                    }
                }
                return 0.0;
            };
            const double model = width([&](int d) {
                std::complex<double> c = 0.0;
                for (std::size_t i = 0; i + std::size_t(d) < weight.size(); ++i)
                    c += weight[i] * std::conj(weight[i + std::size_t(d)]);
                return c;
            });
            const double truth = width([&](int d) {
                std::complex<double> c = 0.0;
                for (std::size_t i = 0; i + std::size_t(d) < dense.size(); ++i)
                    c += reference.correlation(dense[i], dense[i + std::size_t(d)]);
                return c;
            });
            std::printf("z %4.1f %s: power %+.2f dB, grain %.3f / %.3f mm\n", z,
                        rectangular ? "rect  " : "preset", db, model, truth);
            EXPECT_NEAR(model / truth, 1.0, 0.08);
        }
    }
}

}  // namespace
}  // namespace sonotrace
