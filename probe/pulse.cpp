#include "probe/pulse.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>

#include "probe/transducer.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"

namespace sonotrace::probe {

using base::kFwhmPerSigma;

namespace {
constexpr int kSamplesPerPeriod = 64;
}  // namespace

double PulseEcho::impulse_response(double t, double frequency_hz, double bandwidth) {
    const double sigma_f = bandwidth * frequency_hz / kFwhmPerSigma;
    const double s = 1.0 / (2.0 * std::numbers::pi * sigma_f);
    const double w = 2.0 * std::numbers::pi * frequency_hz;
    // Minus its DC (Morlet's correction): with DC the envelope grows 1/t tails.
    return std::exp(-0.5 * t * t / (s * s)) * (std::cos(w * t) - std::exp(-0.5 * w * w * s * s));
}

PulseEcho::PulseEcho(const Transducer& t)
    : PulseEcho(t.frequency_mhz * 1e6, t.bandwidth, t.cycles) {}

PulseEcho::PulseEcho(double frequency_hz, double bandwidth, double cycles) : f0_(frequency_hz) {
    dt_ = 1.0 / (kSamplesPerPeriod * f0_);
    const double sigma_t = kFwhmPerSigma / (2.0 * std::numbers::pi * bandwidth * f0_);
    // The impulse response over +-7 sigma (its Gaussian is below 3e-11 beyond), the
    // excitation over its n cycles; their convolution, sampled at dt.
    const int h_half = int(std::ceil(7.0 * sigma_t / dt_));
    const int e_len = std::max(1, int(std::lround(cycles * kSamplesPerPeriod)));
    std::vector<double> h(std::size_t(2 * h_half + 1));
    for (int k = -h_half; k <= h_half; ++k)
        h[std::size_t(k + h_half)] = impulse_response(k * dt_, f0_, bandwidth);
    const double w = 2.0 * std::numbers::pi * f0_;
    const int n = e_len + int(h.size()) - 1;
    std::vector<double> p(std::size_t(n), 0.0);
    for (int i = 0; i < e_len; ++i) {
        const double e = std::sin(w * (i + 0.5) * dt_) * dt_;  // midpoint rule
        for (std::size_t k = 0; k < h.size(); ++k) p[std::size_t(i) + k] += e * h[k];
    }
    // Quadrature: the Hilbert transform through the spectrum (-i on positive frequencies),
    // zero-padded fourfold so the transform's periodic wrap does not reach the pulse.
    const int padded = cv::getOptimalDFTSize(4 * n);
    cv::Mat line(1, padded, CV_64F, cv::Scalar(0));
    std::copy(p.begin(), p.end(), line.ptr<double>(0) + (padded - n) / 2);
    cv::Mat spectrum;
    cv::dft(line, spectrum, cv::DFT_COMPLEX_OUTPUT);
    auto* c = spectrum.ptr<cv::Vec2d>(0);
    for (int k = 0; k < padded; ++k) {
        const double sign = (k == 0 || 2 * k == padded) ? 0.0 : (2 * k < padded ? -1.0 : 1.0);
        const cv::Vec2d v = c[k];
        c[k] = cv::Vec2d(-sign * v[1], sign * v[0]);  // (a + ib) * (sign * i)
    }
    cv::Mat hilbert;
    cv::dft(spectrum, hilbert, cv::DFT_INVERSE | cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
    std::vector<double> q(static_cast<std::size_t>(n));
    std::copy_n(hilbert.ptr<double>(0) + (padded - n) / 2, n, q.begin());

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
    // FWHM by linear interpolation of the envelope's half-maximum crossings.
    auto crossing = [&](int step) {
        int i = peak;
        while (i + step >= 0 && i + step < n && env[std::size_t(i + step)] > 0.5 * top) i += step;
        if (i + step < 0 || i + step >= n) return double(i);
        const double a = env[std::size_t(i)], b = env[std::size_t(i + step)];
        return i + step * (a - 0.5 * top) / (a - b);
    };
    fwhm_ = (crossing(1) - crossing(-1)) * dt_;
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

double PulseEcho::axial_fwhm_mm() const {
    return 0.5 * tissue::kReferenceSpeed * fwhm_ * 1e3;
}

}  // namespace sonotrace::probe
