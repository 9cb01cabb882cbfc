#include "imaging/channel_data.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include <tbb/parallel_for.h>

#include "probe/aperture.h"
#include "probe/array_geometry.h"
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
    std::array<std::vector<float>, 3> re, im;
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
        w.re[std::size_t(j)].resize(std::size_t(2 * w.half + 1));
        w.im[std::size_t(j)].resize(std::size_t(2 * w.half + 1));
        for (int k = -w.half; k <= w.half; ++k) {
            std::complex<double> sum = 0.0;
            for (int m = 0; m < band->count(); ++m) {
                const double f = band->frequency_hz(m);
                sum += band->weight[std::size_t(m)] * (half_integrated ? std::sqrt(f0 / f) : 1.0) *
                       quarter * std::pow(f / f0 - 1.0, j) * std::polar(1.0, kTwoPi * f * k / fs);
            }
            w.re[std::size_t(j)][std::size_t(k + w.half)] = float(sum.real());
            w.im[std::size_t(j)][std::size_t(k + w.half)] = float(sum.imag());
        }
    }
    return w;
}

// The fit's frequencies f0 (1 + nu_q), q = 0, 1, 2: the -6 dB band edges and f0.
std::array<double, 3> fit_points(const probe::Transducer& t) {
    const double b = 0.5 * t.bandwidth;
    return {-b, 0.0, b};
}

// The echoes as one transmit lights them, a column per quantity (the pair loop reads them
// eight at a time).
struct LitEchoes {
    std::vector<float> x, z;    // mm
    std::vector<float> time;    // arrival of the transmit plus the extra delay, from start (s)
    std::vector<float> re, im;  // sigma times the transmit's amplitude at r
    std::array<std::vector<float>, 3> transmit;  // its directivity at the fit's frequencies
    std::vector<uint8_t> family;  // 0: lit by the transmit's wave (half-integrated); 1: particles
    // Facets (ChannelEcho::Lit): pi f0 w / c0 (s), d . t, and t; facets come first.
    std::vector<float> facet_scale, facet_dt, facet_tx, facet_tz;
    std::size_t facets = 0;
    std::size_t size() const { return x.size(); }
};

// Echoes per call of the pair loop, and the stride of its outputs.
constexpr int kPairBlock = 256;

// What the pair loop needs of an element and the fit.
struct PairConstants {
    float xe, ze, nx, nz;  // the element's place and normal
    bool curved;           // the face is curved (else ze = 0, normal (0, 1))
    float inverse_c0, fs, turns_per_sample, step_re, step_im;
    std::array<float, 3> directivity;  // pi w (1 + nu_q) / lambda0: sinc's argument per sin theta
    float b;
    // The closest an echo is taken to be to an element (mm): the far-field 1 / sqrt(R) of
    // the element's wave holds from about half a wavelength (nearer, it would diverge).
    float nearest;
    std::array<float, 3> frequency;  // 1 + nu_q: the fit's frequencies over f0
};

// A facet's columns for the pair loop (null: points).
struct FacetColumns {
    const float *scale = nullptr, *dt = nullptr, *tx = nullptr, *tz = nullptr;
};

// The terms of `count` echoes (their columns from x on) at one element: the sample n0 below each
// arrival and its six contributions (trains j = 0..2 at n0 and n0 + 1, real and imaginary:
// terms[(4 j + k) * kPairBlock + i], count <= kPairBlock, k = re n0, im n0, re n0+1, im n0+1).
// Plain float arithmetic in one loop without branches, so that it vectorises; the same numbers
// whichever instruction set runs it.
// Facets multiply each frequency's directivity by their Kirchhoff factor (ChannelEcho::Lit);
// a curved face's elements take the way back from their own normals. The loop is written
// once and instantiated with and without each (a flat face's: z - 0 and the normal (0, 1)
// left out, 5 % of a PICMUS acquisition).
template <bool Facets, bool Curved>
[[gnu::always_inline]] inline void pair_terms_body(
    int count, const float* __restrict x, const float* __restrict z, const float* __restrict time,
    const float* __restrict re, const float* __restrict im, const float* __restrict t0,
    const float* __restrict t1, const float* __restrict t2, const FacetColumns& facets,
    const PairConstants& k, int32_t* __restrict n0, float* __restrict terms) {
    const float half_b = 0.5f / k.b, half_b2 = 0.5f / (k.b * k.b);
    // The constants as locals: read through `k` they might alias the outputs.
    const float xe = k.xe, inverse_c0 = k.inverse_c0, fs = k.fs;
    [[maybe_unused]] const float ze = k.ze, nx = k.nx, nz = k.nz;
    const float turns_per_sample = k.turns_per_sample, step_re = k.step_re, step_im = k.step_im;
    const float d0 = k.directivity[0], d1 = k.directivity[1], d2 = k.directivity[2];
    const float f0 = k.frequency[0], f1 = k.frequency[1], f2 = k.frequency[2];
    const float nearest2 = k.nearest * k.nearest;
    for (int i = 0; i < count; ++i) {
        const float dx = x[i] - xe, dz = Curved ? z[i] - ze : z[i];
        const float R = std::sqrt(std::max(dx * dx + dz * dz, nearest2));
        const float inverse_R = 1.0f / R;
        // The way back's angle from the element's normal (a flat array's: dx / R, z / R).
        const float sin_back = (Curved ? dx * nz - dz * nx : dx) * inverse_R;
        const float cos_back = (Curved ? std::max(dx * nx + dz * nz, 0.0f) : dz) * inverse_R;
        // sinc(a) = sin |a| / |a|, |a| kept from 0 (sin 1e-6 / 1e-6 = 1 in float). Written
        // out for each frequency: a loop inside this one would keep it from vectorising.
        auto sinc_of = [](float a) {
            a = std::max(std::abs(a), 1e-6f);
            float sine, cosine;
            base::sincos_turns(a * float(0.5 / std::numbers::pi), sine, cosine);
            return sine / a;
        };
        float back[3] = {sinc_of(d0 * sin_back), sinc_of(d1 * sin_back), sinc_of(d2 * sin_back)};
        if constexpr (Facets) {
            // (d - u_e) . t, u_e = (p_e - r) / R.
            const float across = facets.dt[i] + (dx * facets.tx[i] + dz * facets.tz[i]) * inverse_R;
            const float a = facets.scale[i] * across;
            back[0] *= sinc_of(a * f0), back[1] *= sinc_of(a * f1), back[2] *= sinc_of(a * f2);
        }
        const float p0 = t0[i] * back[0], p1 = t1[i] * back[1], p2 = t2[i] * back[2];
        // The quadratic in nu = f / f0 - 1 through (-b, p0), (0, p1), (b, p2).
        const float c[3] = {p1, (p2 - p0) * half_b, (p2 + p0 - 2.0f * p1) * half_b2};
        const float position = (time[i] + R * inverse_c0) * fs;
        const int32_t n = base::floor_to_int(position);
        const float u = position - float(n);
        // The carrier at each of the two samples: exp(-i 2 pi f0 (arrival - t_n)).
        float sine, cosine;
        base::sincos_turns(-u * turns_per_sample, sine, cosine);
        const float next_re = cosine * step_re - sine * step_im,
                    next_im = cosine * step_im + sine * step_re;
        const float scale = cos_back / std::sqrt(R);
        const float ar = re[i] * scale, ai = im[i] * scale;
        const float w0 = 1.0f - u;
        const float a0r = (ar * cosine - ai * sine) * w0, a0i = (ar * sine + ai * cosine) * w0;
        const float a1r = (ar * next_re - ai * next_im) * u,
                    a1i = (ar * next_im + ai * next_re) * u;
        n0[i] = n;
        float* __restrict row = terms + i;
#define SONOTRACE_TRAIN_TERMS(j)                \
    row[(4 * j + 0) * kPairBlock] = c[j] * a0r; \
    row[(4 * j + 1) * kPairBlock] = c[j] * a0i; \
    row[(4 * j + 2) * kPairBlock] = c[j] * a1r; \
    row[(4 * j + 3) * kPairBlock] = c[j] * a1i;
        SONOTRACE_TRAIN_TERMS(0)
        SONOTRACE_TRAIN_TERMS(1)
        SONOTRACE_TRAIN_TERMS(2)
#undef SONOTRACE_TRAIN_TERMS
    }
}

[[gnu::target_clones("avx2", "default"), gnu::noinline]] void pair_terms(
    int count, const float* __restrict x, const float* __restrict z, const float* __restrict time,
    const float* __restrict re, const float* __restrict im, const float* __restrict t0,
    const float* __restrict t1, const float* __restrict t2, PairConstants k, int32_t* __restrict n0,
    float* __restrict terms) {
    if (k.curved)
        pair_terms_body<false, true>(count, x, z, time, re, im, t0, t1, t2, {}, k, n0, terms);
    else
        pair_terms_body<false, false>(count, x, z, time, re, im, t0, t1, t2, {}, k, n0, terms);
}

[[gnu::target_clones("avx2", "default"), gnu::noinline]] void facet_pair_terms(
    int count, const float* __restrict x, const float* __restrict z, const float* __restrict time,
    const float* __restrict re, const float* __restrict im, const float* __restrict t0,
    const float* __restrict t1, const float* __restrict t2, FacetColumns facets, PairConstants k,
    int32_t* __restrict n0, float* __restrict terms) {
    if (k.curved)
        pair_terms_body<true, true>(count, x, z, time, re, im, t0, t1, t2, facets, k, n0, terms);
    else
        pair_terms_body<true, false>(count, x, z, time, re, im, t0, t1, t2, facets, k, n0, terms);
}

// out[n + k] += Re(a_n g_k) over a train's nonzero samples (g split into its parts).
[[gnu::target_clones("avx2", "default")]] void convolve_train(const std::complex<float>* a, int S,
                                                              const float* __restrict g_re,
                                                              const float* __restrict g_im, int H,
                                                              float* __restrict out) {
    for (int n = 0; n < S; ++n) {
        const float ar = a[n].real(), ai = a[n].imag();
        if (ar == 0.0f && ai == 0.0f) continue;
        const int lo = std::max(-H, -n), hi = std::min(H, S - 1 - n);
        float* __restrict o = out + n;
        for (int k = lo; k <= hi; ++k) o[k] += ar * g_re[k + H] - ai * g_im[k + H];
    }
}

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
    c.pitch_mm = t.pitch_mm;
    c.element_s_mm = probe::element_arc_mm(t);
    c.element_points = probe::element_points(t);
    c.waves = scheme.waves;
    const double depth = settings.depth_mm > 0.0 ? settings.depth_mm : t.depth_mm;
    const double span = t.array_length_mm();
    const probe::PulseEcho pulse(t);
    // The deepest points: `depth` below the face's ends and centre, and the scanned
    // region's deepest corners and middle; the latest arrival there plus the longest way
    // back from any of them to any element.
    const probe::ScanGeometry scan(t);
    std::vector<glm::dvec2> deepest{{-0.5 * span, depth}, {0.0, depth}, {0.5 * span, depth}};
    for (double l : {-0.5, 0.5 * (t.lines - 1), t.lines - 0.5})
        deepest.push_back(scan.point(l, depth));
    double latest = 0.0, longest_way_back = 0.0;
    for (const probe::TransmitWave& wave : scheme.waves) {
        const probe::TransmitField field(t, wave);
        c.delays_s.push_back(field.delays_s());
        for (const glm::dvec2& r : deepest) latest = std::max(latest, field.at(r).time_s);
    }
    for (const glm::dvec2& r : deepest)
        for (const probe::ArrayPoint& e : c.element_points)
            longest_way_back = std::max(longest_way_back, glm::length(r - e.position));
    latest += longest_way_back / kC0MmPerS + 1.5 * pulse.half_length_s();
    c.samples = std::max(1, int(std::ceil((latest - c.start_s) * c.fs_hz)) + 1);
    return c;
}

ChannelData channel_data(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                         const std::vector<ChannelEcho>& echoes, const ChannelSettings& settings) {
    return channel_data(
        t, scheme, [&](int) { return echoes; }, settings);
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
    const std::complex<double> step_forward = std::polar(1.0, kTwoPi * f0 / fs);
    PairConstants constants{};
    constants.inverse_c0 = float(1.0 / kC0MmPerS);
    constants.fs = float(fs);
    constants.turns_per_sample = float(f0 / fs);
    constants.step_re = float(step_forward.real());
    constants.step_im = float(step_forward.imag());
    for (int q = 0; q < 3; ++q)
        constants.directivity[std::size_t(q)] =
            float(directivity_scale * (1.0 + nu[std::size_t(q)]));
    constants.b = float(b);
    for (int q = 0; q < 3; ++q)
        constants.frequency[std::size_t(q)] = float(1.0 + nu[std::size_t(q)]);
    constants.nearest = float(0.5 * t.wavelength_mm());
    constants.curved = probe::array_geometry(t)->face_radius_mm() > 0.0;

    for (int w = 0; w < c.transmits; ++w) {
        const probe::TransmitField field(t, scheme.waves[std::size_t(w)]);
        const std::vector<ChannelEcho> echoes = echoes_of(w);
        LitEchoes lit;
        bool particles = false;
        // Facets first (their own pair loop), then the rest, each in the order given.
        std::vector<const ChannelEcho*> ordered;
        ordered.reserve(echoes.size());
        for (const ChannelEcho& echo : echoes)
            if (echo.lit && echo.lit->facet_mm > 0.0) ordered.push_back(&echo);
        for (const ChannelEcho& echo : echoes)
            if (!(echo.lit && echo.lit->facet_mm > 0.0)) ordered.push_back(&echo);
        for (const ChannelEcho* from : ordered) {
            const ChannelEcho& echo = *from;
            probe::TransmitField::Arrival a;
            if (echo.lit) {
                a = {echo.lit->arrival_s, 1.0, echo.lit->transmit_sin_angle};
                particles = true;
            } else {
                a = field.at(echo.position);
            }
            if (!(a.amplitude > 0.0)) continue;
            const std::complex<double> amplitude = echo.strength * a.amplitude;
            lit.x.push_back(float(echo.position.x));
            lit.z.push_back(float(echo.position.y));
            lit.time.push_back(float(a.time_s + echo.extra_delay_s - c.start_s));
            lit.re.push_back(float(amplitude.real()));
            lit.im.push_back(float(amplitude.imag()));
            for (int q = 0; q < 3; ++q)
                lit.transmit[std::size_t(q)].push_back(
                    float(sinc(directivity_scale * (1.0 + nu[std::size_t(q)]) * a.sin_angle)));
            lit.family.push_back(echo.lit ? 1 : 0);
            if (echo.lit && echo.lit->facet_mm > 0.0) {
                const ChannelEcho::Lit& f = *echo.lit;
                lit.facet_scale.push_back(float(std::numbers::pi * f0 * f.facet_mm / kC0MmPerS));
                lit.facet_dt.push_back(float(glm::dot(f.incident, f.tangent)));
                lit.facet_tx.push_back(float(f.tangent.x));
                lit.facet_tz.push_back(float(f.tangent.y));
                ++lit.facets;
            }
        }
        tbb::parallel_for(0, c.elements, [&](int e) {
            // The three amplitude trains of this channel (header), per family.
            std::array<std::array<std::vector<std::complex<float>>, 3>, 2> trains;
            for (int family = 0; family < (particles ? 2 : 1); ++family)
                for (auto& v : trains[std::size_t(family)]) v.assign(std::size_t(S), 0.0f);
            PairConstants k = constants;
            const probe::ArrayPoint& element = c.element_points[std::size_t(e)];
            k.xe = float(element.position.x);
            k.ze = float(element.position.y);
            k.nx = float(element.normal.x);
            k.nz = float(element.normal.y);
            std::array<int32_t, kPairBlock> n0;
            std::array<float, 12 * kPairBlock> terms;
            // Blocks of facets, then of points (a block never mixes them).
            for (std::size_t from = 0; from < lit.size();) {
                const std::size_t end = from < lit.facets ? lit.facets : lit.size();
                const int count = int(std::min<std::size_t>(kPairBlock, end - from));
                if (from < lit.facets) {
                    const FacetColumns facets{
                        lit.facet_scale.data() + from, lit.facet_dt.data() + from,
                        lit.facet_tx.data() + from, lit.facet_tz.data() + from};
                    facet_pair_terms(count, lit.x.data() + from, lit.z.data() + from,
                                     lit.time.data() + from, lit.re.data() + from,
                                     lit.im.data() + from, lit.transmit[0].data() + from,
                                     lit.transmit[1].data() + from, lit.transmit[2].data() + from,
                                     facets, k, n0.data(), terms.data());
                } else {
                    pair_terms(count, lit.x.data() + from, lit.z.data() + from,
                               lit.time.data() + from, lit.re.data() + from, lit.im.data() + from,
                               lit.transmit[0].data() + from, lit.transmit[1].data() + from,
                               lit.transmit[2].data() + from, k, n0.data(), terms.data());
                }
                for (int i = 0; i < count; ++i) {
                    const int n = n0[std::size_t(i)];
                    if (n < 0 || n + 1 >= S) continue;
                    auto& train = trains[lit.family[from + std::size_t(i)]];
                    for (int j = 0; j < 3; ++j) {
                        const float* v = terms.data() + std::size_t(4 * j * kPairBlock + i);
                        train[std::size_t(j)][std::size_t(n)] +=
                            std::complex<float>(v[0], v[kPairBlock]);
                        train[std::size_t(j)][std::size_t(n + 1)] +=
                            std::complex<float>(v[2 * kPairBlock], v[3 * kPairBlock]);
                    }
                }
                from += std::size_t(count);
            }
            // RF = Re sum_j train_j (*) g_j.
            float* out = c.channel(w, e);
            for (int family = 0; family < (particles ? 2 : 1); ++family)
                for (int j = 0; j < 3; ++j) {
                    const Waveforms& g = waveforms[std::size_t(family)];
                    convolve_train(trains[std::size_t(family)][std::size_t(j)].data(), S,
                                   g.re[std::size_t(j)].data(), g.im[std::size_t(j)].data(), g.half,
                                   out);
                }
        });
    }
    return c;
}

}  // namespace sonotrace::imaging
