#include "imaging/electronic_noise.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <numbers>

#include "probe/pulse.h"
#include "tissue/base/hash.h"

namespace sonotrace::imaging {

namespace {

// A standard normal deviate from two 53-bit uniforms of the counter (Box-Muller's cosine
// half: each sample its own pair, so no value depends on its neighbour's draw).
double normal_at(uint64_t line_key, uint64_t sample) {
    const uint64_t a = base::mix64(line_key ^ (2 * sample)),
                   b = base::mix64(line_key ^ (2 * sample + 1));
    const double u1 = (double(a >> 11) + 0.5) * 0x1.0p-53;  // in (0, 1): the log is finite
    const double u2 = double(b >> 11) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

}  // namespace

NoiseShape noise_shape(const probe::Transducer& t, double fs_hz) {
    const probe::PulseEcho pulse(t);
    const int half = int(std::ceil(pulse.half_length_s() * fs_hz));
    NoiseShape shape;
    shape.taps.resize(std::size_t(2 * half + 1));
    for (int m = -half; m <= half; ++m) {
        const double h = pulse.in_phase(m / fs_hz);
        shape.taps[std::size_t(m + half)] = float(h);
        shape.power += h * h;
    }
    return shape;
}

double add_electronic_noise(LineData& rf, const probe::Transducer& t, double snr_db,
                            uint64_t seed) {
    double power = 0.0;
    for (const float v : rf.values) power += double(v) * double(v);
    if (rf.values.empty() || power == 0.0) return 0.0;
    power /= double(rf.values.size());
    const NoiseShape shape = noise_shape(t, rf.fs_hz);
    const double variance = power / std::pow(10.0, snr_db / 10.0);
    const double scale = std::sqrt(variance / shape.power);
    const int half = int(shape.taps.size() / 2), samples = rf.samples;
    const uint64_t frame_key = base::mix64(seed ^ 0x6e6f697365ull);  // "noise"
    tbb::parallel_for(0, rf.lines, [&](int line) {
        const uint64_t line_key = base::mix64(frame_key ^ uint64_t(line));
        // w over [-half, samples + half): every output sample sees a full window.
        std::vector<double> white(std::size_t(samples + 2 * half));
        for (std::size_t k = 0; k < white.size(); ++k) white[k] = normal_at(line_key, k);
        for (int i = 0; i < samples; ++i) {
            double sum = 0.0;
            for (std::size_t m = 0; m < shape.taps.size(); ++m)
                sum += white[std::size_t(i) + m] * double(shape.taps[m]);
            rf.at(line, i) += float(sum * scale);
        }
    });
    return variance;
}

}  // namespace sonotrace::imaging
