#include "imaging/channel_data.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include <tbb/parallel_for.h>

#include "probe/aperture.h"
#include "probe/pulse.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"

namespace sonotrace::imaging {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

double sinc(double x) {
    return std::abs(x) < 1e-8 ? 1.0 : std::sin(x) / x;
}

// The three waveforms g_j(k / fs), k = -half .. half (header): the pulse-echo band's
// weights times the transmit's half-integration and (f / f0 - 1)^j.
struct Waveforms {
    int half = 0;
    std::array<std::vector<std::complex<float>>, 3> g;
};

Waveforms make_waveforms(const probe::Transducer& t, double fs, bool half_integrated) {
    const auto band = probe::pulse_band(t, probe::BandUse::echo);
    const probe::PulseEcho pulse(t);
    Waveforms w;
    // The half-integration lengthens the pulse a little; the band repeats its waveform
    // every 1 / step, which the taps must stay inside.
    w.half = std::min(int(std::ceil(1.5 * pulse.half_length_s() * fs)),
                      int(std::floor(0.5 / band->step_hz * fs)) - 1);
    const double f0 = band->centre_hz;
    const std::complex<double> quarter =
        half_integrated ? std::polar(1.0, -0.25 * std::numbers::pi) : 1.0;
    for (int j = 0; j < 3; ++j) {
        w.g[std::size_t(j)].resize(std::size_t(2 * w.half + 1));
        for (int k = -w.half; k <= w.half; ++k) {
            std::complex<double> sum = 0.0;
            for (int m = 0; m < band->count(); ++m) {
                const double f = band->frequency_hz(m);
                sum += band->weight[std::size_t(m)] * (half_integrated ? std::sqrt(f0 / f) : 1.0) *
                       quarter *
                       std::pow(f / f0 - 1.0, j) * std::polar(1.0, kTwoPi * f * k / fs);
            }
            w.g[std::size_t(j)][std::size_t(k + w.half)] = std::complex<float>(sum);
        }
    }
    return w;
}

// The fit's frequencies f0 (1 + nu_q), q = 0, 1, 2: the -6 dB band edges and f0.
std::array<double, 3> fit_points(const probe::Transducer& t) {
    const double b = 0.5 * t.bandwidth;
    return {-b, 0.0, b};
}

// Coefficients of the quadratic in nu = f / f0 - 1 through (nu_q, p_q).
template <class Real>
std::array<Real, 3> quadratic(const std::array<Real, 3>& p, Real b) {
    return {p[1], (p[2] - p[0]) / (Real(2) * b), (p[2] + p[0] - Real(2) * p[1]) / (Real(2) * b * b)};
}

// The element's directivity sinc(pi w f sin theta / c0) at the fit's frequencies, tabulated
// over |sin theta| in [0, 1] and interpolated linearly (its second derivative is below
// (pi w / lambda)^2 (1 + b)^2: at 1024 intervals the error is below 2e-5 for w <= lambda).
class DirectivityTable {
  public:
    DirectivityTable(double scale, const std::array<double, 3>& nu) {
        for (int k = 0; k <= kIntervals; ++k)
            for (int q = 0; q < 3; ++q)
                values_[std::size_t(k)][std::size_t(q)] =
                    float(sinc(scale * (1.0 + nu[std::size_t(q)]) * k / double(kIntervals)));
    }
    std::array<float, 3> operator()(float sin_theta) const {
        const float x = std::min(std::abs(sin_theta), 1.0f) * float(kIntervals);
        const int k = std::min(int(x), kIntervals - 1);
        const float f = x - float(k);
        std::array<float, 3> out;
        for (int q = 0; q < 3; ++q)
            out[std::size_t(q)] = values_[std::size_t(k)][std::size_t(q)] * (1.0f - f) +
                                  values_[std::size_t(k + 1)][std::size_t(q)] * f;
        return out;
    }

  private:
    static constexpr int kIntervals = 1024;
    std::array<std::array<float, 3>, kIntervals + 1> values_;
};

// An echo as one transmit lights it.
struct LitEcho {
    float x, z;                      // mm
    float time_s;                    // arrival of the transmit plus the extra delay, from start
    std::complex<float> amplitude;   // sigma times the transmit's amplitude at r
    std::array<float, 3> transmit_directivity;  // at the fit's frequencies
    int family;  // 0: lit by the transmit's wave (half-integrated pulse); 1: lit by particles
};

}  // namespace

ChannelData channel_layout(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                           const ChannelSettings& settings) {
    ChannelData c;
    c.transmits = int(scheme.waves.size());
    c.elements = t.elements;
    c.frequency_hz = t.frequency_mhz * 1e6;
    c.fs_hz = settings.sampling_mhz > 0.0 ? settings.sampling_mhz * 1e6 : 4.0 * c.frequency_hz;
    c.start_s = settings.start_us * 1e-6;
    c.speed_m_s = tissue::kReferenceSpeed;
    c.element_x_mm = probe::element_positions_mm(t);
    c.waves = scheme.waves;
    const double depth = settings.depth_mm > 0.0 ? settings.depth_mm : t.depth_mm;
    const double span = t.array_length_mm();
    const probe::PulseEcho pulse(t);
    double latest = 0.0;
    for (const probe::TransmitWave& wave : scheme.waves) {
        const probe::TransmitField field(t, wave);
        c.delays_s.push_back(field.delays_s());
        for (double x : {-0.5 * span, 0.0, 0.5 * span})
            latest = std::max(latest, field.at({x, depth}).time_s);
    }
    latest += std::hypot(depth, span) / kC0MmPerS + 1.5 * pulse.half_length_s();
    c.samples = std::max(1, int(std::ceil((latest - c.start_s) * c.fs_hz)) + 1);
    return c;
}

ChannelData channel_data(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                         const std::vector<ChannelEcho>& echoes, const ChannelSettings& settings) {
    return channel_data(t, scheme, [&](int) { return echoes; }, settings);
}

ChannelData channel_data(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                         const TransmitEchoes& echoes_of, const ChannelSettings& settings) {
    ChannelData c = channel_layout(t, scheme, settings);
    const int S = c.samples;
    c.values.assign(std::size_t(c.transmits) * std::size_t(c.elements) * std::size_t(S), 0.0f);
    const std::array<Waveforms, 2> waveforms{make_waveforms(t, c.fs_hz, true),
                                             make_waveforms(t, c.fs_hz, false)};
    const std::array<double, 3> nu = fit_points(t);
    const double b = nu[2];
    const double f0 = c.frequency_hz, fs = c.fs_hz;
    const double directivity_scale = std::numbers::pi * t.element_width_mm / t.wavelength_mm();
    const DirectivityTable receive_directivity(directivity_scale, nu);
    const std::complex<float> step_forward(std::polar(1.0, kTwoPi * f0 / fs));

    for (int w = 0; w < c.transmits; ++w) {
        const probe::TransmitField field(t, scheme.waves[std::size_t(w)]);
        const std::vector<ChannelEcho> echoes = echoes_of(w);
        std::vector<LitEcho> lit;
        lit.reserve(echoes.size());
        bool particles = false;
        for (const ChannelEcho& echo : echoes) {
            probe::TransmitField::Arrival a;
            if (echo.lit) {
                a = {echo.lit->arrival_s, 1.0, echo.lit->transmit_sin_angle};
                particles = true;
            } else {
                a = field.at(echo.position);
            }
            if (!(a.amplitude > 0.0)) continue;
            LitEcho l{float(echo.position.x), float(echo.position.y),
                      float(a.time_s + echo.extra_delay_s - c.start_s),
                      std::complex<float>(echo.strength * a.amplitude), {}, echo.lit ? 1 : 0};
            for (int q = 0; q < 3; ++q)
                l.transmit_directivity[std::size_t(q)] =
                    float(sinc(directivity_scale * (1.0 + nu[std::size_t(q)]) * a.sin_angle));
            lit.push_back(l);
        }
        tbb::parallel_for(0, c.elements, [&](int e) {
            // The three amplitude trains of this channel (header), per family.
            std::array<std::array<std::vector<std::complex<float>>, 3>, 2> trains;
            for (int family = 0; family < (particles ? 2 : 1); ++family)
                for (auto& v : trains[std::size_t(family)]) v.assign(std::size_t(S), 0.0f);
            const float xe = float(c.element_x_mm[std::size_t(e)]);
            const float inverse_c0 = float(1.0 / kC0MmPerS);
            const float turns_per_sample = float(f0 / fs);
            for (const LitEcho& l : lit) {
                const float dx = l.x - xe, R2 = dx * dx + l.z * l.z;
                if (!(R2 > 0.0f)) continue;
                const float R = std::sqrt(R2), inverse_R = 1.0f / R;
                const std::array<float, 3> back = receive_directivity(dx * inverse_R);
                std::array<float, 3> p;
                for (int q = 0; q < 3; ++q)
                    p[std::size_t(q)] = l.transmit_directivity[std::size_t(q)] * back[std::size_t(q)];
                const std::array<float, 3> coefficient = quadratic(p, float(b));
                const float position = (l.time_s + R * inverse_c0) * float(fs);
                const int n0 = base::floor_to_int(position);
                if (n0 < 0 || n0 + 1 >= S) continue;
                const float u = position - float(n0);
                // The carrier at each of the two samples: exp(-i 2 pi f0 (arrival - t_n)).
                float sine, cosine;
                base::sincos_turns(-u * turns_per_sample, sine, cosine);
                const std::complex<float> at_n0(cosine, sine);
                const std::complex<float> at_n1 = at_n0 * step_forward;
                const std::complex<float> amplitude =
                    l.amplitude * (l.z * inverse_R / std::sqrt(R));
                auto& train = trains[std::size_t(l.family)];
                for (int j = 0; j < 3; ++j) {
                    const std::complex<float> a = amplitude * coefficient[std::size_t(j)];
                    train[std::size_t(j)][std::size_t(n0)] += a * at_n0 * (1.0f - u);
                    train[std::size_t(j)][std::size_t(n0 + 1)] += a * at_n1 * u;
                }
            }
            // RF = Re sum_j train_j (*) g_j.
            float* out = c.channel(w, e);
            for (int family = 0; family < (particles ? 2 : 1); ++family)
            for (int j = 0; j < 3; ++j) {
                const int H = waveforms[std::size_t(family)].half;
                const auto& g = waveforms[std::size_t(family)].g[std::size_t(j)];
                const auto& a = trains[std::size_t(family)][std::size_t(j)];
                for (int n = 0; n < S; ++n) {
                    if (a[std::size_t(n)] == std::complex<float>(0.0f)) continue;
                    const int lo = std::max(-H, -n), hi = std::min(H, S - 1 - n);
                    const float ar = a[std::size_t(n)].real(), ai = a[std::size_t(n)].imag();
                    for (int k = lo; k <= hi; ++k) {
                        const std::complex<float> gk = g[std::size_t(k + H)];
                        out[n + k] += ar * gk.real() - ai * gk.imag();
                    }
                }
            }
        });
    }
    return c;
}

}  // namespace sonotrace::imaging
