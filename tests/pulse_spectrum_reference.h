#pragma once
// The pulse-echo waveform's spectrum, written out independently of probe/pulse.h's band:
// S(f) df on f = k df (the analytic waveform p(t) = in_phase + i quadrature sampled at 64
// per period, Fourier-summed here), where |S| exceeds 1e-5 of its peak. The references of
// the channel-data tests sum echoes over it.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <utility>
#include <vector>

#include "probe/pulse.h"
#include "probe/transducer.h"

namespace sonotrace::test {

struct Spectrum {
    std::vector<double> f;
    std::vector<std::complex<double>> s;  // S(f_k) df
};

inline Spectrum pulse_spectrum(const probe::Transducer& t, double df) {
    const probe::PulseEcho pulse(t);
    const double dt = 1.0 / (64.0 * t.frequency_mhz * 1e6), reach = pulse.half_length_s();
    std::vector<std::pair<double, std::complex<double>>> samples;
    for (double time = -reach; time <= reach; time += dt)
        samples.push_back({time, pulse.analytic(time)});
    Spectrum all;
    double peak = 0.0;
    for (double f = df; f < 3.0 * t.frequency_mhz * 1e6; f += df) {
        std::complex<double> sum = 0.0;
        for (const auto& [time, p] : samples)
            sum += p * std::polar(1.0, -2.0 * std::numbers::pi * f * time);
        all.f.push_back(f);
        all.s.push_back(sum * dt * df);
        peak = std::max(peak, std::abs(all.s.back()));
    }
    Spectrum kept;
    for (std::size_t k = 0; k < all.f.size(); ++k)
        if (std::abs(all.s[k]) > 1e-5 * peak)
            kept.f.push_back(all.f[k]), kept.s.push_back(all.s[k]);
    return kept;
}

}  // namespace sonotrace::test
