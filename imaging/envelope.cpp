#include "imaging/bmode.h"
#include "imaging/box_filter.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <mutex>
#include <numbers>
#include <vector>

#include "probe/pulse.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"

// Detection: the analytic signal of each RF line (a Hilbert transformer), the envelope
// and the baseband signal, each low-passed to the output pixel (PixelBand) so that scan
// conversion does not alias (imaging/bmode.h).
namespace sonotrace::imaging {

namespace {

// Taps of the Hilbert transformer (envelope): h = sum over odd k in [1, K] of c_k (x[i - k]
// - x[i + k]), c_k = 2 / (pi k) times a Blackman window over |k| <= K. Within 0.07-0.43
// of the sampling rate (the RF's band: fs = 4 f0 with the presets' bandwidths, and down
// to 8 f0) its gain is 1 to within 1e-4. A finite filter rather than the DFT's ideal
// one: the ideal kernel falls as 1/t, so a strong echo near the face leaves a floor along
// the whole line (wrapping round the transform), which a deep TGC raises into stripes.
constexpr int kHilbertReach = 48;
const std::array<float, kHilbertReach / 2>& hilbert_taps() {
    static const std::array<float, kHilbertReach / 2> taps = [] {
        std::array<float, kHilbertReach / 2> c{};
        const double span = 2.0 * (kHilbertReach + 1);  // Blackman over 2K + 3 points, ends dropped
        for (int m = 0; m < kHilbertReach / 2; ++m) {
            const int k = 2 * m + 1;
            const double x = 2.0 * std::numbers::pi * double(k + kHilbertReach + 1) / span;
            const double window = 0.42 - 0.5 * std::cos(x) + 0.08 * std::cos(2.0 * x);
            c[std::size_t(m)] = float(2.0 / (std::numbers::pi * k) * window);
        }
        return c;
    }();
    return taps;
}

}  // namespace

namespace {
PixelBand make_pixel_band(const probe::Transducer& t, const LineData& layout, double pixel_mm) {
    PixelBand band;
    const probe::PulseEcho pulse(t);
    band.carrier_hz = pulse.frequency_hz();
    const double fs = layout.fs_hz;
    const double samples_per_mm = 2.0 * 1e-3 / tissue::kReferenceSpeed * fs;
    const double pulse_sigma = pulse.envelope_fwhm_s() * fs / base::kFwhmPerSigma;
    const double target = kPixelSigmas * pixel_mm * samples_per_mm;
    band.sigma_samples = std::max(target, pulse_sigma);
    const double extra2 = target * target - pulse_sigma * pulse_sigma;
    if (!(extra2 > 0.25)) return band;  // under half a sample: nothing to show that aliases
    band.box_radius = box3_radius(std::sqrt(extra2));
    if (band.box_radius == 0) return band;
    // The boxes' response at baseband frequency f (cycles per sample): (sin(pi f b) / (b
    // sin(pi f)))^3, b = 2 r + 1; weighted by the pulse-echo spectrum's power.
    const double b = 2.0 * band.box_radius + 1.0;
    const probe::PulseEcho::Band spectrum = pulse.band(0.0, 1e-3);
    double kept = 0.0;
    for (int m = 0; m < spectrum.count(); ++m) {
        const double f = (spectrum.frequency_hz(m) - band.carrier_hz) / fs;
        const double box =
            std::abs(std::sin(std::numbers::pi * f)) < 1e-12
                ? 1.0
                : std::sin(std::numbers::pi * f * b) / (b * std::sin(std::numbers::pi * f));
        kept += std::norm(spectrum.weight[std::size_t(m)]) * std::pow(box, 6.0);
    }
    band.gain = kept > 0.0 ? std::sqrt(spectrum.power / kept) : 1.0;
    return band;
}
}  // namespace

PixelBand pixel_band(const probe::Transducer& t, const LineData& layout, double pixel_mm) {
    // Kept for the next frames: the pulse's tables and spectrum cost more than the filter.
    const std::array<double, 6> key{t.frequency_mhz, t.bandwidth,  t.band_shape,
                                    t.cycles,        layout.fs_hz, pixel_mm};
    static std::mutex mutex;
    static std::vector<std::pair<std::array<double, 6>, PixelBand>> kept;
    const std::lock_guard<std::mutex> lock(mutex);
    for (const auto& [k, band] : kept)
        if (k == key) return band;
    kept.emplace_back(key, make_pixel_band(t, layout, pixel_mm));
    if (kept.size() > 8) kept.erase(kept.begin());
    return kept.back().second;
}

namespace {
// The analytic signal of every line and what is asked of it: the banded envelope, the
// plain one, the banded baseband signal (envelope(), baseband()).
void detect(const LineData& rf, const PixelBand& band, LineData* banded, LineData* unbanded,
            BasebandLines* baseband) {
    if (banded) *banded = rf;
    if (unbanded) *unbanded = rf;
    if (baseband) {
        baseband->lines = rf.lines, baseband->samples = rf.samples, baseband->fs_hz = rf.fs_hz;
        baseband->sigma_samples = band.sigma_samples;
        baseband->values.resize(rf.values.size());
    }
    const auto& taps = hilbert_taps();
    const int n = rf.samples, K = kHilbertReach;
    // The carrier's phasors by sample, shared by the lines.
    std::vector<std::complex<double>> carrier;
    if (band.box_radius > 0 || baseband) {
        carrier.resize(std::size_t(n));
        for (int i = 0; i < n; ++i)
            carrier[std::size_t(i)] =
                std::polar(1.0, -2.0 * std::numbers::pi * band.carrier_hz * i / rf.fs_hz);
    }
    tbb::parallel_for(0, rf.lines, [&](int l) {
        // The line between K zeros at each end: the taps read past the ends without a
        // branch per sample.
        std::vector<float> padded(std::size_t(n + 2 * K), 0.0f), hilbert(std::size_t(n), 0.0f);
        const float* x = rf.values.data() + std::size_t(l) * std::size_t(n);
        std::copy_n(x, n, padded.begin() + K);
        const float* centre = padded.data() + K;
        float* __restrict h = hilbert.data();
        for (int m = 0; m < K / 2; ++m) {  // tap by tap over the samples: a loop that vectorises
            const int k = 2 * m + 1;
            const float c = taps[std::size_t(m)];
            const float* before = centre - k;
            const float* after = centre + k;
            for (int i = 0; i < n; ++i) h[i] += c * (before[i] - after[i]);
        }
        float* out = banded ? banded->values.data() + std::size_t(l) * std::size_t(n) : nullptr;
        float* plain =
            unbanded ? unbanded->values.data() + std::size_t(l) * std::size_t(n) : nullptr;
        std::complex<float>* shown =
            baseband ? baseband->values.data() + std::size_t(l) * std::size_t(n) : nullptr;
        if (band.box_radius == 0) {
            for (float* to : {out, plain})
                if (to)
                    for (int i = 0; i < n; ++i) to[i] = std::sqrt(x[i] * x[i] + h[i] * h[i]);
            if (shown)
                for (int i = 0; i < n; ++i)
                    shown[i] = std::complex<float>(std::complex<double>(x[i], h[i]) *
                                                   carrier[std::size_t(i)]);
            return;
        }
        if (plain)
            for (int i = 0; i < n; ++i) plain[i] = std::sqrt(x[i] * x[i] + h[i] * h[i]);
        // At baseband, low-passed by the boxes (padded by r zeros either side, as
        // smooth_box3 reads), then its magnitude.
        const int r = band.box_radius;
        // Scratch per thread (a zeroed buffer per line cost more than the filter): only the
        // padding must be zero, the rest is written before it is read.
        thread_local std::vector<Moments> buffer;
        buffer.resize(2 * std::size_t(n + 2 * r));
        Moments* const m = buffer.data() + r;
        for (Moments* padding : {buffer.data(), m + n, m + n + r, m + 2 * n + 2 * r})
            std::fill_n(padding, r, Moments{});
        for (int i = 0; i < n; ++i) {
            const std::complex<double> a =
                std::complex<double>(x[i], h[i]) * carrier[std::size_t(i)];
            m[i] = {a.real(), a.imag(), 0.0, 0.0};
        }
        const Moments* smoothed = smooth_box3(m - r, buffer.data() + n + 2 * r, n, r);
        if (out)
            for (int i = 0; i < n; ++i)
                out[i] = float(band.gain * std::sqrt(smoothed[i][0] * smoothed[i][0] +
                                                     smoothed[i][1] * smoothed[i][1]));
        if (shown)
            for (int i = 0; i < n; ++i)
                shown[i] = std::complex<float>(float(band.gain * smoothed[i][0]),
                                               float(band.gain * smoothed[i][1]));
    });
}
}  // namespace

LineData envelope(const LineData& rf, const PixelBand& band, LineData* unbanded) {
    LineData banded;
    detect(rf, band, &banded, unbanded, nullptr);
    return banded;
}

BasebandLines baseband(const LineData& rf, const PixelBand& band, LineData* unbanded) {
    BasebandLines lines;
    detect(rf, band, nullptr, unbanded, &lines);
    return lines;
}

}  // namespace sonotrace::imaging
