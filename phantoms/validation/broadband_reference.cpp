#include "phantoms/validation/broadband_reference.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace sonotrace::validation {

namespace {
constexpr double kPi = std::numbers::pi;
}

PulseSpectrum::PulseSpectrum(const probe::Transducer& t, double periods, double reach_periods) {
    const double f0 = t.frequency_mhz * 1e6, df = f0 / periods;
    const double exponent = std::log(std::log(10.0) / std::log(2.0)) / std::log(t.band_shape);
    const int steps = std::max(1, int(std::lround(400 * t.cycles)));
    const double dt = t.cycles / f0 / steps;
    for (double f = df; f < 3.0 * f0; f += df) {
        const double u = (f - f0) / (0.5 * t.bandwidth * f0);
        const double response = std::exp(-std::log(2.0) * std::pow(std::abs(u), exponent));
        std::complex<double> excitation = 0.0;
        for (int i = 0; i < steps; ++i) {
            const double time = (i + 0.5) * dt;
            excitation += std::sin(2 * kPi * f0 * time) * std::polar(dt, -2 * kPi * f * time);
        }
        const std::complex<double> s = excitation * response * df;
        if (std::abs(s) < 1e-7 * df / f0) continue;
        frequency_.push_back(f), weight_.push_back(s);
    }
    const int reach = int(std::ceil(reach_periods * 32));
    for (int k = -reach; k <= reach; ++k)
        for (double f : frequency_)
            carrier_.push_back(std::polar(1.0, 2 * kPi * f * k / (32.0 * f0)));
    pulse_peak_ = envelope_peak(std::vector<std::complex<double>>(frequency_.size(), 1.0));
}

double PulseSpectrum::envelope_peak(const std::vector<std::complex<double>>& h) const {
    std::vector<std::complex<double>> sh(h.size());
    for (std::size_t i = 0; i < h.size(); ++i) sh[i] = weight_[i] * h[i];
    double best = 0.0;
    for (std::size_t at = 0; at < carrier_.size(); at += sh.size()) {
        std::complex<double> e = 0.0;
        for (std::size_t i = 0; i < sh.size(); ++i) e += sh[i] * carrier_[at + i];
        best = std::max(best, std::abs(e));
    }
    return best;
}

double PulseSpectrum::peak(const std::vector<std::complex<double>>& h) const {
    return envelope_peak(h) / pulse_peak_;
}

double PulseSpectrum::energy(const std::vector<std::complex<double>>& h) const {
    double e = 0.0, p = 0.0;
    for (std::size_t i = 0; i < h.size(); ++i)
        e += std::norm(weight_[i] * h[i]), p += std::norm(weight_[i]);
    return e / p;
}

double first_side_lobe_db(const std::vector<double>& v) {
    const auto peak = int(std::max_element(v.begin(), v.end()) - v.begin());
    double lobe = 0.0;
    for (int step : {-1, 1}) {
        int i = peak;
        while (i + step > 0 && i + step < int(v.size()) - 1 &&
               v[std::size_t(i + step)] <= v[std::size_t(i)])
            i += step;
        while (i + step > 0 && i + step < int(v.size()) - 1 &&
               v[std::size_t(i + step)] >= v[std::size_t(i)])
            i += step;
        lobe = std::max(lobe, v[std::size_t(i)]);
    }
    return std::max(20.0 * std::log10(lobe / v[std::size_t(peak)]), kNoSideLobeDb);
}

}  // namespace sonotrace::validation
