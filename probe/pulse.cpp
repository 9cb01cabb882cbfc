#include "probe/pulse.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <opencv2/core.hpp>

#include "probe/transducer.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/half_maximum.h"

namespace sonotrace::probe {

namespace {
constexpr int kSamplesPerPeriod = 64;
}  // namespace

double PulseEcho::transducer_response(double f, double frequency_hz, double bandwidth,
                                      double band_shape) {
    // exp(-ln 2 |u|^p) with u the offset in -6 dB half-widths: 1/2 at |u| = 1, and 1/10 at
    // the -20 dB half-width u20 = B20 / B6 when (u20)^p = ln 10 / ln 2.
    const double exponent = std::log(std::log(10.0) / std::log(2.0)) / std::log(band_shape);
    const double u = (f - frequency_hz) / (0.5 * bandwidth * frequency_hz);
    return f > 0.0 ? std::exp(-std::log(2.0) * std::pow(std::abs(u), exponent)) : 0.0;
}

PulseEcho::PulseEcho(const Transducer& t)
    : PulseEcho(t.frequency_mhz * 1e6, t.bandwidth, t.band_shape, t.cycles) {}

PulseEcho::PulseEcho(double frequency_hz, double bandwidth, double band_shape, double cycles)
    : f0_(frequency_hz) {
    dt_ = 1.0 / (kSamplesPerPeriod * f0_);
    // The analytic pulse-echo waveform from its spectrum: the excitation's spectrum times
    // the transducer's two-way response on positive frequencies, doubled, none on negative
    // ones (so the real part is the waveform and the imaginary part its Hilbert transform,
    // and no DC passes). The window holds the excitation and the response's ringing: a
    // band of B f0 rings for about 1 / (B f0), the flattest allowed band shapes a few
    // times longer; 40 of those leave the wrap-around below 1e-6 of the peak.
    const int e_len = std::max(1, int(std::lround(cycles * kSamplesPerPeriod)));
    const int n =
        cv::getOptimalDFTSize(e_len + int(std::ceil(40.0 * kSamplesPerPeriod / bandwidth)));
    const double w = 2.0 * std::numbers::pi * f0_;
    cv::Mat excitation(1, n, CV_64FC2, cv::Scalar(0, 0));
    const int start = (n - e_len) / 2;  // centred: the response rings both ways
    for (int i = 0; i < e_len; ++i)
        excitation.at<cv::Vec2d>(0, start + i)[0] =
            std::sin(w * (i + 0.5) * dt_) * dt_;  // midpoint rule
    cv::Mat spectrum;
    cv::dft(excitation, spectrum);
    auto* c = spectrum.ptr<cv::Vec2d>(0);
    for (int k = 0; k < n; ++k) {
        const double gain =
            2 * k < n ? 2.0 * transducer_response(k / (n * dt_), f0_, bandwidth, band_shape) : 0.0;
        c[k] *= gain;
    }
    cv::Mat analytic;
    cv::dft(spectrum, analytic, cv::DFT_INVERSE | cv::DFT_SCALE);
    const auto* values = analytic.ptr<cv::Vec2d>(0);
    std::vector<double> p(static_cast<std::size_t>(n)), q(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) p[std::size_t(i)] = values[i][0], q[std::size_t(i)] = values[i][1];

    // Centre on the envelope's peak, scale it to 1, keep where it exceeds 1e-4.
    std::vector<double> env(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i)
        env[std::size_t(i)] = std::hypot(p[std::size_t(i)], q[std::size_t(i)]);
    const int peak = int(std::max_element(env.begin(), env.end()) - env.begin());
    const double top = env[std::size_t(peak)];
    int lo = peak, hi = peak;
    for (int i = 0; i < n; ++i) {
        if (env[std::size_t(i)] > 1e-4 * top) lo = std::min(lo, i), hi = std::max(hi, i);
    }
    const int half = std::max(peak - lo, hi - peak) + 1;
    centre_ = half;
    in_phase_.assign(std::size_t(2 * half + 1), 0.0);
    quadrature_.assign(std::size_t(2 * half + 1), 0.0);
    for (int k = -half; k <= half; ++k) {
        const int i = peak + k;
        if (i < 0 || i >= n) continue;
        in_phase_[std::size_t(k + half)] = p[std::size_t(i)] / top;
        quadrature_[std::size_t(k + half)] = q[std::size_t(i)] / top;
    }
    half_length_ = half * dt_;
    fwhm_ = base::half_maximum(n, peak, [&](int i) { return env[std::size_t(i)]; }).width() * dt_;
}

double PulseEcho::sample(const std::vector<double>& table, double t) const {
    const double x = t / dt_ + centre_;
    if (!(x >= 0.0) || x >= double(table.size() - 1)) return 0.0;
    const auto i = std::size_t(x);
    const double f = x - double(i);
    return table[i] + f * (table[i + 1] - table[i]);
}

std::complex<double> PulseEcho::analytic(double t) const {
    const double x = t / dt_ + centre_;
    if (!(x >= 0.0) || x >= double(in_phase_.size() - 1)) return 0.0;
    const auto i = std::size_t(x);
    const double f = x - double(i);
    return {in_phase_[i] + f * (in_phase_[i + 1] - in_phase_[i]),
            quadrature_[i] + f * (quadrature_[i + 1] - quadrature_[i])};
}

std::complex<double> PulseEcho::Band::waveform(double t) const {
    std::complex<double> sum = 0.0;
    for (int m = 0; m < count(); ++m)
        sum +=
            weight[std::size_t(m)] * std::polar(1.0, 2.0 * std::numbers::pi * frequency_hz(m) * t);
    return sum;
}

PulseEcho::Band PulseEcho::band(double spread_s, double floor) const {
    // S(f) = integral p(t) exp(-i 2 pi f t) dt over the table (trapezoid: the table's
    // ends are below 1e-4 of the peak).
    const int n = int(in_phase_.size());
    auto spectrum = [&](double f) {
        std::complex<double> sum = 0.0;
        const std::complex<double> step = std::polar(1.0, -2.0 * std::numbers::pi * f * dt_);
        std::complex<double> turn = std::polar(1.0, 2.0 * std::numbers::pi * f * centre_ * dt_);
        for (int k = 0; k < n; ++k, turn *= step)
            sum +=
                std::complex<double>(in_phase_[std::size_t(k)], quadrature_[std::size_t(k)]) * turn;
        return sum * dt_;
    };
    int first = centre_, last = centre_;
    for (int k = 0; k < n; ++k)
        if (std::hypot(in_phase_[std::size_t(k)], quadrature_[std::size_t(k)]) > floor)
            first = std::min(first, k), last = std::max(last, k);
    Band b;
    b.step_hz = 1.0 / ((last - first) * dt_ + 2.0 * spread_s);
    // The band's reach: the analytic waveform holds positive frequencies only, its peak
    // near f0; scanned out to 4 f0 on a grid of a twentieth of the step.
    const double scan = b.step_hz / 20.0;
    double peak = 0.0;
    std::vector<double> magnitude;
    for (double f = scan; f < 4.0 * f0_; f += scan) {
        magnitude.push_back(std::abs(spectrum(f)));
        peak = std::max(peak, magnitude.back());
    }
    double lo = 0.0, hi = 0.0;
    for (std::size_t i = 0; i < magnitude.size(); ++i)
        if (magnitude[i] >= floor * peak) {
            const double f = double(i + 1) * scan;
            lo = lo > 0.0 ? lo : f, hi = f;
        }
    // Nodes on a grid through f0 (the centre frequency is always one of them).
    const int below = std::min(int(std::ceil((f0_ - lo) / b.step_hz)),
                               int(std::ceil(f0_ / b.step_hz)) - 1),  // all above 0 Hz
        above = int(std::ceil((hi - f0_) / b.step_hz));
    b.centre_hz = f0_;
    b.first_hz = f0_ - below * b.step_hz;
    for (int m = 0; m <= below + above; ++m) {
        b.weight.push_back(spectrum(b.frequency_hz(m)) * b.step_hz);
        b.power += std::norm(b.weight.back());
    }
    const double span = std::max(b.count() - 1, 1) * b.step_hz;
    b.search_dt = 0.25 / span;
    b.search_half = int(std::ceil(0.5 / (b.step_hz * b.search_dt)));
    for (int k = -b.search_half; k <= b.search_half; ++k)
        for (int m = 0; m < b.count(); ++m)
            b.search.push_back(
                std::polar(1.0, 2.0 * std::numbers::pi * m * b.step_hz * k * b.search_dt));
    return b;
}

double PulseEcho::axial_fwhm_mm() const {
    return 0.5 * tissue::kReferenceSpeed * fwhm_ * 1e3;
}

}  // namespace sonotrace::probe
