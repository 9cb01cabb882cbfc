#include "imaging/bmode.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <numbers>
#include <opencv2/core.hpp>

#include "tissue/acoustic_map.h"
#include "tissue/fast_math.h"
#include "tissue/hash.h"

namespace sonotrace::imaging {

namespace {

constexpr double kFwhmPerSigma = 2.3548200450309493;  // 2 sqrt(2 ln 2)
constexpr double kC0 = tissue::kReferenceSpeed;       // m/s

using probe::ScanLine;
using tissue::mix64;

// out = in (*) kernel (centred), zero outside. The interior tap by tap over all samples
// (a loop that vectorises; each sum still adds its terms in tap order), the edges as
// they come.
template <typename T>
void convolve(const T* in, int n, const std::vector<float>& kernel, T* out) {
    const int half = int(kernel.size() / 2), taps = int(kernel.size());
    auto edge = [&](int i) {
        const int lo = std::max(0, i - half), hi = std::min(n - 1, i + half);
        T sum = 0;
        for (int j = lo; j <= hi; ++j) sum += in[j] * kernel[std::size_t(j - i + half)];
        out[i] = sum;
    };
    const int first = std::min(half, n),
              last = std::max(first, n - half);  // interior [first, last)
    for (int i = 0; i < first; ++i) edge(i);
    for (int i = first; i < last; ++i) out[i] = 0;
    for (int k = 0; k < taps; ++k) {
        const T tap = kernel[std::size_t(k)];
        const T* shifted = in + (k - half);
        for (int i = first; i < last; ++i) out[i] += shifted[i] * tap;
    }
    for (int i = last; i < n; ++i) edge(i);
}

// Sum over k of the correlation of the scatterer field between points k u cells apart
// along a lattice axis: linear interpolation of white values has the cubic B-spline
// autocorrelation B3(x) (phase-averaged), normalised by B3(0) = 2/3.
double lattice_correlation_sum(double u) {
    auto rho = [](double x) {
        x = std::abs(x);
        const double b = x < 1.0 ? 2.0 / 3.0 - x * x + 0.5 * x * x * x
                                 : (x < 2.0 ? (2.0 - x) * (2.0 - x) * (2.0 - x) / 6.0 : 0.0);
        return b * 1.5;
    };
    double sum = 1.0;
    for (int k = 1; k * u < 2.0; ++k) sum += 2.0 * rho(k * u);
    return sum;
}

// Three passes of a centred box of odd width b = 2r + 1 approximate a Gaussian of
// variance (b^2 - 1) / 4 to within a few per cent (zero outside, sum 1), in O(n)
// whatever the width. The r of a Gaussian of `sigma` samples:
int box3_radius(double sigma) {
    int b = int(std::lround(std::sqrt(4.0 * sigma * sigma + 1.0)));
    b += 1 - b % 2;
    return b / 2;
}

// The four moments of a sample (speckle_lines), smoothed together.
using Moments = std::array<double, 4>;

// The three passes over n samples of the interleaved moments (one pass serves all four).
// `v` and `scratch` each hold r zero samples, the n samples, r zero samples: the windows
// read the padding beyond the ends, with no branch per sample. Returns where the
// result's sample 0 is. Built for AVX2 too (a sample's four moments in one register; no
// FMA, so the same numbers either way).
[[gnu::target_clones("avx2", "default")]] const Moments* smooth_box3(Moments* v, Moments* scratch,
                                                                     int n, int r) {
    // A sample's moments as one vector (GCC vector extensions: one AVX register, or two
    // SSE2 ones); left to itself GCC kept the four channels scalar.
    typedef double v4d __attribute__((vector_size(32)));
    static_assert(sizeof(v4d) == sizeof(Moments));
    const double inverse_b = 1.0 / double(2 * r + 1);  // a multiply per sample, not a division
    Moments *in = v + r, *out = scratch + r;
    for (int pass = 0; pass < 3 && r > 0; ++pass) {
        v4d sum = {0.0, 0.0, 0.0, 0.0}, entering, leaving;
        for (int i = 0; i < r; ++i) {  // the window of sample 0 but its entering sample r
            std::memcpy(&entering, &in[i], sizeof entering);
            sum += entering;
        }
        // The sample entering and the one leaving are combined first, so the running sum
        // waits for one add per sample, not two.
        for (int i = 0; i < n; ++i) {
            std::memcpy(&entering, &in[i + r], sizeof entering);
            std::memcpy(&leaving, &in[i - r], sizeof leaving);
            const v4d smoothed = (sum + entering) * inverse_b;
            std::memcpy(&out[i], &smoothed, sizeof smoothed);
            sum += entering - leaving;
        }
        std::swap(in, out);
    }
    return in;
}

// One sub-line of the speckle: the point a fraction f of the way from line a's mean
// position to line b's (lattice units), lit by the blend of their intensities;
// out[i] = sqrt(lit) * the field there. The hot loop of the speckle: built for AVX2 and
// for the baseline, picked at load time (IEEE operations in the same order, no FMA in
// either: the same numbers either way).
struct SubLineEnds {
    const float *ax, *ay, *az, *bx, *by, *bz;  // lattice positions on lines a and b
    const float *lit_a, *lit_b;                // intensities of lines a and b
};
[[gnu::target_clones("avx2", "default")]] void field_values(uint32_t seed, const SubLineEnds& e,
                                                            float f, int n, float* __restrict out) {
    // Restrict-qualified locals: with eight inputs GCC gives up checking overlaps at run
    // time and leaves the loop scalar.
    const float* __restrict ax = e.ax;
    const float* __restrict ay = e.ay;
    const float* __restrict az = e.az;
    const float* __restrict bx = e.bx;
    const float* __restrict by = e.by;
    const float* __restrict bz = e.bz;
    const float* __restrict lit_a = e.lit_a;
    const float* __restrict lit_b = e.lit_b;
    for (int i = 0; i < n; ++i) {
        const float x = ax[i] + f * (bx[i] - ax[i]);
        const float y = ay[i] + f * (by[i] - ay[i]);
        const float z = az[i] + f * (bz[i] - az[i]);
        const float amplitude = std::sqrt((1.0f - f) * lit_a[i] + f * lit_b[i]);
        out[i] = amplitude * ScattererField::at_lattice_float(seed, x, y, z);
    }
}

// One line's Gaussian sums across its sub-lines, for every sample i at once:
// sums[i] = sum over |j| <= reach[i] of g_i(j) sub[centre + j][i], norms[i] = sum of
// g_i(j)^2, with g_i(j) = ratio[i]^(j^2) by recurrence. Sub-line rows outer, samples
// inner: contiguous rows, loops that vectorise (per sample, an inner loop over j waited
// for each multiply and add in turn). Terms are added in the same order as one sample at
// a time would (j = 1, 2, ...; left, then right), so the sums are the same numbers.
[[gnu::target_clones("avx2", "default")]] void gaussian_sums(
    const float* __restrict sub, int n, int sub_lines, int centre, const int* __restrict reach,
    const double* __restrict ratio, double* __restrict sums, double* __restrict norms,
    double* __restrict g, double* __restrict q) {
    int max_reach = 0;
    const float* __restrict middle = sub + std::size_t(centre) * std::size_t(n);
    for (int i = 0; i < n; ++i) {
        sums[i] = double(middle[i]), norms[i] = 1.0, g[i] = 1.0, q[i] = ratio[i];
        max_reach = std::max(max_reach, reach[i]);
    }
    for (int j = 1; j <= max_reach; ++j) {
        const bool has_left = centre - j >= 0, has_right = centre + j < sub_lines;
        const float* __restrict left =
            sub + std::size_t(has_left ? centre - j : 0) * std::size_t(n);
        const float* __restrict right =
            sub + std::size_t(has_right ? centre + j : 0) * std::size_t(n);
        for (int i = 0; i < n; ++i) {
            const double gi = g[i] * q[i];
            g[i] = gi, q[i] *= ratio[i] * ratio[i];
            const double on = j <= reach[i] ? gi : 0.0;  // past the reach: adds +0
            double sum = sums[i], norm = norms[i];
            if (has_left) sum += on * double(left[i]), norm += on * on;
            if (has_right) sum += on * double(right[i]), norm += on * on;
            sums[i] = sum, norms[i] = norm;
        }
    }
}

// What depends on depth only (speckle_lines): the receive PSF's sigma and the sub-line
// spacing (mm), once per sample rather than per line and sample.
struct AtDepth {
    double receive_sigma, d_sub, inverse_d_sub;
};

// Per sample of a line: the beam's amplitude sigma from its intensity variance across
// the line, bounded by the receive PSF and the lattice cell; its reach in sub-lines
// (3 sigma, at most max_reach) and the log of its Gaussian ratio between neighbouring
// sub-lines. Built for AVX2, where it vectorises (on the SSE2 baseline GCC does not
// vectorise the three-double records), and the baseline: the same numbers (no FMA).
// Selects by value, not std::min/max, whose references keep loops scalar.
[[gnu::target_clones("avx2", "default")]] void beam_terms(const double* __restrict variance,
                                                          const AtDepth* __restrict at_depth,
                                                          double cell, int max_reach, int n,
                                                          int* __restrict reach,
                                                          double* __restrict log_ratio) {
    for (int i = 0; i < n; ++i) {
        const AtDepth& a = at_depth[i];
        const double width = std::sqrt(2.0 * variance[i]);
        const double bounded = a.receive_sigma < width ? a.receive_sigma : width;  // min
        const double sigma_g = bounded < cell ? cell : bounded;                    // max
        const double span = 3.0 * sigma_g * a.inverse_d_sub;                       // > 0
        const int whole = int(span);
        const int ceiling = whole + int(double(whole) < span);
        reach[i] = max_reach < ceiling ? max_reach : ceiling;
        log_ratio[i] = -0.5 * (a.d_sub / sigma_g) * (a.d_sub / sigma_g);
    }
}

// The speckle term of every line (see the header): the scatter profile smoothed over a
// pulse length, the scatterer field on sub-lines between the lines' mean positions, and
// each line's Gaussian sum across its beam.
void speckle_lines(const probe::Transducer& t, const simulator::EchoProfile<2>& profile,
                   const MapToWorld& to_world, const ImagingSettings& settings, const LineData& rf,
                   float* speckle) {
    const int L = rf.lines, N = rf.samples;
    const double fs = rf.fs_hz;
    const Pulse pulse{t.frequency_mhz * 1e6, t.bandwidth};
    const probe::ScanGeometry geometry(t);
    const double cell =
        settings.speckle_cell_mm > 0.0 ? settings.speckle_cell_mm : t.wavelength_mm() / 8.0;
    const ScattererField field(settings.seed, cell);
    // The field in lattice units straight from map coordinates (one affine map).
    const MapToWorld to_lattice{to_world.origin / cell, to_world.x_axis / cell,
                                to_world.y_axis / cell};
    const double smooth_sigma =
        std::max(0.5, settings.profile_smoothing * pulse.envelope_fwhm_s() * fs / kFwhmPerSigma);
    std::vector<double> depth(static_cast<std::size_t>(N));  // mm per sample
    for (int i = 0; i < N; ++i) depth[std::size_t(i)] = rf.depth_mm(i);

    // Per line and sample: intensity w, mean position, variance across the line, from
    // moments S0 = w, S1 = w d, S2 = w (var + d_across^2) smoothed along the line, with
    // d the offset from the nominal point (small numbers: no cancellation).
    // Uninitialised: each line's task writes its whole row (zero-filling ~6 MB first
    // was a serial millisecond per frame).
    const std::size_t size = std::size_t(L) * std::size_t(N);
    const auto w = std::make_unique_for_overwrite<double[]>(size);
    const auto across_var = std::make_unique_for_overwrite<double[]>(size);
    const auto mean = std::make_unique_for_overwrite<glm::dvec2[]>(size);
    // The mean positions in lattice units, where w > 0 (each is an end of two gaps below).
    const auto lattice = std::make_unique_for_overwrite<glm::vec3[]>(size);
    const int profile_lines = std::min(L, profile.lines);
    const int r = box3_radius(smooth_sigma);
    tbb::parallel_for(0, L, [&](int l) {
        const std::size_t row = std::size_t(l) * std::size_t(N);
        double* const w_row = w.get() + row;
        double* const var_row = across_var.get() + row;
        glm::dvec2* const mean_row = mean.get() + row;
        auto no_echo = [&] {
            std::fill_n(w_row, N, 0.0);
            std::fill_n(var_row, N, 0.0);
            std::fill_n(mean_row, N, glm::dvec2(0.0));
        };
        if (l >= profile_lines) return no_echo();
        const ScanLine line = geometry.line(l);
        const glm::dvec2 across(-line.direction.y, line.direction.x);
        // The moments and the smoothing's scratch, each padded by r zeros at both ends.
        const std::size_t padded = std::size_t(N + 2 * r);
        const auto buffer = std::make_unique_for_overwrite<Moments[]>(2 * padded);
        Moments* const m = buffer.get() + r;
        Moments* const scratch = buffer.get() + padded;
        for (Moments* padding : {buffer.get(), m + N, scratch, scratch + N + r})
            std::fill_n(padding, r, Moments{});
        double peak = 0.0;
        for (int i = 0; i < N; ++i) {
            const std::size_t at = row + std::size_t(i);
            const double wi = profile.intensity[at];
            if (!(wi > 0.0)) {
                m[i] = Moments{};
                continue;
            }
            const glm::dvec2 d = glm::dvec2(profile.position[at]) -
                                 (line.origin + line.direction * depth[std::size_t(i)]);
            const double da = glm::dot(d, across);
            const double var = glm::dot(across, glm::dmat2(profile.covariance[at]) * across);
            m[i] = {wi, wi * d.x, wi * d.y, wi * (std::max(var, 0.0) + da * da)};
            peak = std::max(peak, wi);
        }
        if (!(peak > 0.0)) return no_echo();  // a line without echo
        const Moments* smoothed = smooth_box3(m - r, scratch, N, r);
        for (int i = 0; i < N; ++i) {
            const Moments& mi = smoothed[i];
            const double s0 = mi[0];
            // Running sums leave rounding residues where there was nothing.
            if (!(s0 > 1e-9 * peak)) {
                w_row[i] = var_row[i] = 0.0;
                mean_row[i] = glm::dvec2(0.0);
                continue;
            }
            const double inverse_s0 = 1.0 / s0;
            const glm::dvec2 d(mi[1] * inverse_s0, mi[2] * inverse_s0);
            const double da = glm::dot(d, across);
            w_row[i] = s0;
            mean_row[i] = (line.origin + line.direction * depth[std::size_t(i)]) + d;
            lattice[row + std::size_t(i)] = glm::vec3(to_lattice(mean_row[i]));
            var_row[i] = std::max(0.0, mi[3] * inverse_s0 - da * da);
        }
    });

    // The scatterer field on K sub-lines per gap between lines, interpolated between the
    // lines' mean positions (the nominal line spacing where a line has no echo), so that
    // neighbouring lines see the same scatterers where their beams overlap; each scaled by
    // the square root of the intensity that lights it. Sub-lines at most the narrowest
    // beam's sigma (the receive PSF at the F-number) apart: every line sums >= 7 of them.
    double widest_gap = 0.0;
    for (double d : {0.0, 0.5 * t.depth_mm, t.depth_mm})
        widest_gap = std::max(widest_gap, geometry.line_spacing_mm(d));
    const double narrowest_sigma = std::max(cell, t.wavelength_mm() * t.f_number / kFwhmPerSigma);
    const int K = std::clamp(
        int(std::ceil(widest_gap / (narrowest_sigma * settings.sub_line_sigmas))), 1, 32);
    const int sub_lines = std::max(L - 1, 0) * K + 1;
    // Every sub-line is written whole by its gap's task below.
    const auto sub =
        std::make_unique_for_overwrite<float[]>(std::size_t(sub_lines) * std::size_t(N));
    // Per gap between lines l and l + 1: both ends in lattice units and their intensities
    // (once; to_lattice is affine, so each sub-line is a linear blend of the ends), then
    // per sub-line the blend, the amplitude and the field in loops that vectorise.
    const int gaps = std::max(L - 1, 1);
    tbb::parallel_for(0, gaps, [&](int l) {
        const std::size_t n = std::size_t(N);
        std::vector<float> ends[6];  // x, y, z at line l, then at line l + 1
        for (auto& e : ends) e.assign(n, 0.0f);
        std::vector<float> lit_a(n, 0.0f), lit_b(n, 0.0f);
        const int other = L == 1 ? l : l + 1;
        for (int i = 0; i < N; ++i) {
            const std::size_t at = std::size_t(l) * n + std::size_t(i);
            const std::size_t next = std::size_t(other) * n + std::size_t(i);
            if (!(w[at] > 0.0) && !(w[next] > 0.0)) continue;
            glm::vec3 pa, pb;
            if (w[at] > 0.0 && w[next] > 0.0) {
                pa = lattice[at], pb = lattice[next];
            } else {  // a line without echo: the nominal gap from the other end
                glm::dvec2 a = mean[at], b = mean[next];
                const glm::dvec2 nominal = geometry.point(other, depth[std::size_t(i)]) -
                                           geometry.point(l, depth[std::size_t(i)]);
                if (!(w[at] > 0.0)) a = b - nominal;
                if (!(w[next] > 0.0)) b = a + nominal;
                pa = glm::vec3(to_lattice(a)), pb = glm::vec3(to_lattice(b));
            }
            const std::size_t u = std::size_t(i);
            ends[0][u] = pa.x, ends[1][u] = pa.y, ends[2][u] = pa.z;
            ends[3][u] = pb.x, ends[4][u] = pb.y, ends[5][u] = pb.z;
            lit_a[u] = float(w[at]), lit_b[u] = float(w[next]);
        }
        const SubLineEnds sub_line_ends{ends[0].data(), ends[1].data(), ends[2].data(),
                                        ends[3].data(), ends[4].data(), ends[5].data(),
                                        lit_a.data(),   lit_b.data()};
        // The last gap ends on the last line; a single line is its own one sub-line.
        const int last_k = L == 1 ? 0 : (l == gaps - 1 ? K : K - 1);
        for (int k = 0; k <= last_k; ++k) {
            const int s = std::min(l * K + k, sub_lines - 1);
            const float f = float(k) / float(K);
            field_values(field.seed(), sub_line_ends, f, N, sub.get() + std::size_t(s) * n);
        }
    });

    // Each line sums the sub-lines under its two-way beam, amplitude weights g. The
    // particles give the transmit beam (intensity variance v, so amplitude variance 2v; at
    // the focus already two-way through the receive weights); dynamic receive focusing
    // bounds it by the receive PSF, FWHM lambda * max(F, depth / array). Normalised by the
    // field's mean square over the sum (lattice correlation along the sub-lines and along
    // the samples included), the mean speckle intensity is the profile's, averaged over
    // the beam.
    const double axial_correlation =
        lattice_correlation_sum((rf.depth_mm(1) - rf.depth_mm(0)) / cell);
    // What depends on depth only, once per sample rather than per line and sample.
    std::vector<AtDepth> at_depth(static_cast<std::size_t>(N));
    std::vector<float> inverse_correlation(static_cast<std::size_t>(N));
    for (int i = 0; i < N; ++i) {
        const double d = depth[std::size_t(i)];
        AtDepth& a = at_depth[std::size_t(i)];
        a.receive_sigma =
            t.wavelength_mm() * std::max(t.f_number, d / t.array_length_mm()) / kFwhmPerSigma;
        a.d_sub = std::max(geometry.line_spacing_mm(d), 1e-6) / K;
        a.inverse_d_sub = 1.0 / a.d_sub;
        inverse_correlation[std::size_t(i)] =
            float(1.0 / (lattice_correlation_sum(a.d_sub / cell) * axial_correlation));
    }
    tbb::parallel_for(0, L, [&](int l) {
        // Per sample: the beam's width, reach and Gaussian ratio in loops without
        // branches (they vectorise; inline, each sample waited for its root, division and
        // exponential in turn), then the sums, then the normalisation.
        const std::size_t n = std::size_t(N), row = std::size_t(l) * n;
        std::vector<double> sums(n), norms(n), ratio(n), g(n), q(n);
        std::vector<int> reach(n);
        beam_terms(across_var.get() + row, at_depth.data(), cell, 8 * K, N, reach.data(),
                   ratio.data());
        for (std::size_t i = 0; i < n; ++i) ratio[i] = double(tissue::exp_float(float(ratio[i])));
        gaussian_sums(sub.get(), N, sub_lines, l * K, reach.data(), ratio.data(), sums.data(),
                      norms.data(), g.data(), q.data());
        float* out = speckle + row;
        for (std::size_t i = 0; i < n; ++i) {  // nothing where the line has no echo
            // Computed for every sample (norms >= 1), selected after: the loop vectorises.
            const float value =
                float(sums[i]) * std::sqrt(inverse_correlation[i] / float(norms[i]));
            out[i] = w[row + i] > 0.0 ? value : 0.0f;
        }
    });
}

// out[n] += amplitude * pulse((n - at) / fs) for n in [lo, hi], the pulse by recurrences
// on the uniform sample grid (Gaussian ratio, rotating phasor: a multiply each instead of
// exp and cos per sample; rounding after 30 taps ~1e-14).
void add_pulse(const Pulse& pulse, double at, double fs, double amplitude, int lo, int hi,
               float* out) {
    if (hi < lo) return;
    const double s = pulse.sigma_s(), w = 2.0 * std::numbers::pi * pulse.frequency_hz;
    const double dt = 1.0 / fs, t0 = (lo - at) * dt;
    const double dc = std::exp(-0.5 * w * w * s * s);  // the DC the pulse does not pass
    const double k = 0.5 / (s * s);
    double gauss = amplitude * std::exp(-k * t0 * t0);
    double ratio = std::exp(-k * (2.0 * t0 * dt + dt * dt));  // gauss(n + 1) / gauss(n)
    const double ratio_step = std::exp(-2.0 * k * dt * dt);
    double re = std::cos(w * t0), im = std::sin(w * t0);
    const double rot_re = std::cos(w * dt), rot_im = std::sin(w * dt);
    for (int n = lo; n <= hi; ++n) {
        out[n] += float(gauss * (re - dc));
        gauss *= ratio;
        ratio *= ratio_step;
        const double next_re = re * rot_re - im * rot_im;
        im = re * rot_im + im * rot_re;
        re = next_re;
    }
}

// Log compression with the dB scale folded in: clamp(scale ln(envelope) + offset, 0, 1).
// tissue::log_float rather than std::log: the loop over a line vectorises (the call was
// most of the stage). Infinite envelopes clamp to the largest float first.
inline float compressed(float envelope, float scale, float offset) {
    const float level = scale * tissue::log_float(std::min(envelope, 3.4e38f)) + offset;
    return envelope > 0.0f ? std::clamp(level, 0.0f, 1.0f) : 0.0f;
}
float compression_scale(double dynamic_range_db) {
    return float(20.0 / std::numbers::ln10 / dynamic_range_db);  // 20 log10 x = (20 / ln 10) ln x
}
float compression_offset(double gain_db, double dynamic_range_db) {
    return float((gain_db + dynamic_range_db) / dynamic_range_db);
}

}  // namespace

double Pulse::sigma_s() const {
    const double sigma_f = bandwidth * frequency_hz / kFwhmPerSigma;
    return 1.0 / (2.0 * std::numbers::pi * sigma_f);
}
double Pulse::envelope_fwhm_s() const {
    return kFwhmPerSigma * sigma_s();
}
double Pulse::axial_fwhm_mm() const {
    return 0.5 * kC0 * envelope_fwhm_s() * 1e3;
}
double Pulse::operator()(double t) const {
    // Zero mean, as a transducer's pulse is (it passes no DC): the Gaussian-modulated
    // cosine minus its DC, exp(-(w sigma)^2 / 2) times the Gaussian (Morlet's correction,
    // 1.3 % at B = 0.8). With DC, the Hilbert envelope grows 1/t tails: a grey haze tens
    // of dB under a strong echo but over its whole line.
    const double s = sigma_s(), w = 2.0 * std::numbers::pi * frequency_hz;
    return std::exp(-0.5 * t * t / (s * s)) * (std::cos(w * t) - std::exp(-0.5 * w * w * s * s));
}

double tgc_gain_db(const std::vector<TgcPoint>& curve, double depth_mm) {
    if (curve.empty()) return 0.0;
    if (depth_mm <= curve.front().depth_mm) return curve.front().gain_db;
    for (std::size_t i = 1; i < curve.size(); ++i) {
        if (depth_mm <= curve[i].depth_mm) {
            const TgcPoint &a = curve[i - 1], &b = curve[i];
            const double t = (depth_mm - a.depth_mm) / std::max(b.depth_mm - a.depth_mm, 1e-12);
            return a.gain_db + t * (b.gain_db - a.gain_db);
        }
    }
    return curve.back().gain_db;
}

float log_compress(float envelope, double gain_db, double dynamic_range_db) {
    return compressed(envelope, compression_scale(dynamic_range_db),
                      compression_offset(gain_db, dynamic_range_db));
}

double LineData::depth_mm(int i) const {
    return 0.5 * kC0 * (double(i) / fs_hz) * 1e3;
}

LineData rf_layout(const probe::Transducer& t, const ImagingSettings& settings) {
    LineData d;
    d.lines = t.lines;
    // 4 f0, as research scanners sample RF: the pulse spectrum at 2 f0 is 37 dB down at
    // B = 0.8; the envelope and scan conversion interpolate between samples.
    d.fs_hz = (settings.sampling_mhz > 0.0 ? settings.sampling_mhz : 4.0 * t.frequency_mhz) * 1e6;
    d.samples = int(std::ceil(2.0 * t.depth_mm * 1e-3 / kC0 * d.fs_hz)) + 1;
    return d;
}

ScattererField::ScattererField(uint64_t seed, double cell_mm)
    : seed_(uint32_t(mix64(seed ^ 0x73636174ull))), inverse_cell_(1.0 / cell_mm) {}

double reflection_back_fraction(double cos_incidence, double lobe_exponent,
                                double half_acceptance_rad) {
    const double off_axis = 2.0 * std::acos(std::clamp(cos_incidence, -1.0, 1.0));
    const double sigma = 1.0 / std::sqrt(std::max(lobe_exponent, 1.0));
    auto cdf = [](double z) { return 0.5 * std::erfc(-z / std::numbers::sqrt2); };
    return cdf((half_acceptance_rad - off_axis) / sigma) -
           cdf((-half_acceptance_rad - off_axis) / sigma);
}

LineData synthesize_rf(const probe::Transducer& t, const probe::Sources<2>& sources,
                       const std::vector<simulator::EchoEvent<2>>& events,
                       const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                       const ImagingSettings& settings) {
    LineData rf = rf_layout(t, settings);
    const int L = rf.lines, N = rf.samples;
    const double fs = rf.fs_hz;
    const Pulse pulse{t.frequency_mhz * 1e6, t.bandwidth};
    const probe::ScanGeometry geometry(t);

    // Particle (line, index within line) -> source, for energies and receive weights.
    std::vector<std::vector<uint32_t>> of_line(static_cast<std::size_t>(L));
    for (std::size_t s = 0; s < sources.size(); ++s) {
        if (sources[s].line < uint32_t(L)) of_line[sources[s].line].push_back(uint32_t(s));
    }
    // The reflection events of each line, in their order (a counting sort): lines are
    // then independent, and run in parallel.
    auto is_reflection = [L](const simulator::EchoEvent<2>& e) {
        return e.kind != simulator::EchoKind::scatter && e.line < uint32_t(L);
    };
    std::vector<uint32_t> event_start(std::size_t(L) + 1, 0), event_order;
    for (const auto& e : events) {
        if (is_reflection(e)) event_start[e.line + 1]++;
    }
    for (int l = 0; l < L; ++l) event_start[std::size_t(l) + 1] += event_start[std::size_t(l)];
    event_order.resize(event_start.back());
    {
        std::vector<uint32_t> next(event_start.begin(), event_start.end() - 1);
        for (std::size_t n = 0; n < events.size(); ++n) {
            if (is_reflection(events[n])) event_order[next[events[n].line]++] = uint32_t(n);
        }
    }

    // -- speckle (header)
    const bool with_speckle = settings.speckle && profile.lines > 0 && profile.bins == N &&
                              profile.covariance.size() == profile.intensity.size();
    const std::size_t size = std::size_t(L) * std::size_t(N);
    const auto speckle = std::make_unique_for_overwrite<float[]>(with_speckle ? size : 0);
    if (with_speckle) speckle_lines(t, profile, to_world, settings, rf, speckle.get());

    // -- RF per line: speckle (*) pulse, plus a pulse at each reflection bin's echo time
    const int half = int(std::ceil(4.0 * pulse.sigma_s() * fs));
    std::vector<float> taps(std::size_t(2 * half + 1));
    for (int i = -half; i <= half; ++i) taps[std::size_t(i + half)] = float(pulse(i / fs));
    rf.values.resize(size);
    tbb::parallel_for(0, L, [&](int l) {
        // Reflections: intensity per sample bin, with its intensity-weighted echo time
        // (the pulse goes there exactly: a split between samples 1/(4 f0) apart would add
        // two pulses a quarter period out of phase).
        std::vector<double> reflected(std::size_t(N), 0.0), reflected_time(std::size_t(N), 0.0);
        const auto& line = of_line[std::size_t(l)];
        const ScanLine axis = geometry.line(l);
        for (uint32_t n = event_start[std::size_t(l)]; n < event_start[std::size_t(l) + 1]; ++n) {
            const auto& e = events[event_order[n]];
            if (e.particle >= line.size()) continue;
            const auto& source = sources[line[e.particle]];
            double intensity = double(e.energy) * e.weight * source.receive_weight;
            double echo_time = e.time_s;  // the particle came back itself: the full round trip
            if (e.kind != simulator::EchoKind::returned_to_probe) {
                echo_time = 2.0 * e.time_s;  // monostatic estimate: twice the one-way time
                intensity *= double(e.energy) / std::max(double(source.energy), 1e-30) *
                             double(e.return_weight);
                // Of the reflected energy, the share that returns into the receive aperture
                // (dynamic receive at the F-number, at most the array) seen from the event.
                const double range_mm = std::max(e.time_s * kC0 * 1e3, 1e-3);
                const double aperture = std::min(t.array_length_mm(), range_mm / t.f_number);
                intensity *= reflection_back_fraction(e.cos_incidence, e.lobe_exponent,
                                                      std::atan(0.5 * aperture / range_mm));
                // Dynamic receive focusing: the receive beam of the line at the event's
                // range (intensity FWHM lambda F#_rx, as the speckle's) weights an echo by
                // how far the event lies across the beam. Without it every line whose wide
                // transmit beam grazes a strong target would show it: streaks beyond the
                // focus. By reciprocity the receive beam bends as the transmit beam does,
                // so it is centred on the transmit beam's centroid at that echo time (the
                // scatter profile), or on the straight line where the profile is empty.
                const double bin = echo_time * fs;
                glm::dvec2 centre = to_world.face_in_map + axis.origin + axis.direction * range_mm;
                if (l < profile.lines && bin >= 0.0 && bin < double(profile.bins)) {
                    const std::size_t at =
                        std::size_t(l) * std::size_t(profile.bins) + std::size_t(bin);
                    if (profile.intensity[at] > 0.0f) centre = glm::dvec2(profile.position[at]);
                }
                const glm::dvec2 q = glm::dvec2(e.position) - centre;
                const double across = q.x * axis.direction.y - q.y * axis.direction.x;
                const double sigma = t.wavelength_mm() * (range_mm / aperture) / kFwhmPerSigma;
                intensity *= std::exp(-0.5 * across * across / (sigma * sigma));
            }
            const double position = echo_time * fs;
            if (!(position >= 0.0) || position >= double(N - 1)) continue;
            reflected[std::size_t(position)] += intensity;
            reflected_time[std::size_t(position)] += intensity * position;
        }

        const std::size_t row = std::size_t(l) * std::size_t(N);
        float* out = rf.values.data() + row;
        if (with_speckle)
            convolve(speckle.get() + row, N, taps, out);
        else
            std::fill_n(out, N, 0.0f);
        for (int i = 0; i < N; ++i) {
            const double intensity = reflected[std::size_t(i)];
            if (!(intensity > 0.0)) continue;
            const double at = reflected_time[std::size_t(i)] / intensity;  // samples
            const double amplitude = std::sqrt(intensity);
            const int lo = std::max(0, int(std::ceil(at - half))),
                      hi = std::min(N - 1, int(std::floor(at + half)));
            add_pulse(pulse, at, fs, amplitude, lo, hi, out);
        }
    });
    return rf;
}

LineData envelope(const LineData& rf) {
    LineData env = rf;
    const int n = cv::getOptimalDFTSize(rf.samples + 64);  // padding: no wrap-around
    // The analytic signal's real part is the RF itself; only its imaginary part, the
    // Hilbert transform, is computed: -i times the positive frequencies (+i the negative),
    // DC and Nyquist dropped. Its spectrum stays Hermitian, so both transforms are real
    // (OpenCV's packed CCS rows), half the work of the complex pair.
    // Blocks of lines on the worker threads (cv::dft of DFT_ROWS runs on one).
    constexpr int kBlock = 16;
    tbb::parallel_for(0, (rf.lines + kBlock - 1) / kBlock, [&](int block) {
        const int first = block * kBlock, count = std::min(kBlock, rf.lines - first);
        cv::Mat lines(count, n, CV_32F, cv::Scalar(0));
        for (int l = 0; l < count; ++l)
            std::copy_n(rf.values.data() + std::size_t(first + l) * std::size_t(rf.samples),
                        rf.samples, lines.ptr<float>(l));
        cv::Mat spectrum;
        cv::dft(lines, spectrum, cv::DFT_ROWS);
        // CCS row: Re0, (Re_k, Im_k) for k = 1 .. (n - 1) / 2, then Re_{n/2} if n is even.
        for (int l = 0; l < count; ++l) {
            float* sp = spectrum.ptr<float>(l);
            sp[0] = 0.0f;
            for (int k = 1; k + 1 < n; k += 2) {  // (a + ib)(-i) = b - ia
                const float re = sp[k];
                sp[k] = sp[k + 1], sp[k + 1] = -re;
            }
            if (n % 2 == 0) sp[n - 1] = 0.0f;
        }
        cv::Mat hilbert;
        cv::dft(spectrum, hilbert,
                cv::DFT_ROWS | cv::DFT_INVERSE | cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
        for (int l = 0; l < count; ++l) {
            const float* x = lines.ptr<float>(l);
            const float* h = hilbert.ptr<float>(l);
            float* out = env.values.data() + std::size_t(first + l) * std::size_t(rf.samples);
            for (int i = 0; i < rf.samples; ++i) out[i] = std::sqrt(x[i] * x[i] + h[i] * h[i]);
        }
    });
    return env;
}

LineData compress(const LineData& envelope, const ImagingSettings& settings) {
    LineData out = envelope;
    const float scale = compression_scale(settings.dynamic_range_db);
    std::vector<float> offset(std::size_t(envelope.samples));
    for (int i = 0; i < envelope.samples; ++i)
        offset[std::size_t(i)] =
            compression_offset(settings.gain_db + tgc_gain_db(settings.tgc, envelope.depth_mm(i)),
                               settings.dynamic_range_db);
    tbb::parallel_for(0, envelope.lines, [&](int l) {
        const std::size_t row = std::size_t(l) * std::size_t(envelope.samples);
        const float* __restrict in = envelope.values.data() + row;
        float* __restrict to = out.values.data() + row;
        const float* __restrict level = offset.data();
        for (int i = 0; i < envelope.samples; ++i) to[i] = compressed(in[i], scale, level[i]);
    });
    return out;
}

namespace {

// Where each pixel of a scan conversion reads the line data. The arctangent per pixel of
// a fan costs as much as the rest of the conversion, so the table is kept for the next
// frames of the same geometry (a sweep, the GUI).
struct ScanTable {
    std::array<double, 8> key{};
    int rows = 0, cols = 0;
    glm::dvec2 origin{0.0};
    std::vector<int32_t> first;      // l0 * samples + s0, -1 outside the scanned region
    std::vector<int32_t> next_line;  // offset to line l0 + 1 (0 with one line)
    std::vector<float> line_frac, sample_frac;
};

std::shared_ptr<const ScanTable> scan_table(const LineData& data, const probe::Transducer& t,
                                            double pixel_mm) {
    const probe::ScanGeometry geometry(t);
    const auto [lo, hi] = geometry.bounds();
    const std::array<double, 8> key{double(t.is_fan()),
                                    double(data.lines),
                                    double(data.samples),
                                    data.fs_hz,
                                    pixel_mm,
                                    t.depth_mm,
                                    t.radius_of_lines(),
                                    t.is_fan() ? t.fov_deg : t.array_length_mm()};
    static std::mutex mutex;
    static std::vector<std::shared_ptr<const ScanTable>> cache;  // most recent last
    {
        const std::lock_guard<std::mutex> lock(mutex);
        for (const auto& table : cache)
            if (table->key == key) return table;
    }
    auto table = std::make_shared<ScanTable>();
    table->key = key;
    table->origin = lo;
    table->cols = int(std::floor((hi.x - lo.x) / pixel_mm)) + 1;
    table->rows = int(std::floor((hi.y - lo.y) / pixel_mm)) + 1;
    const std::size_t pixels = std::size_t(table->rows) * std::size_t(table->cols);
    table->first.assign(pixels, -1);
    table->next_line.assign(pixels, 0);
    table->line_frac.assign(pixels, 0.0f);
    table->sample_frac.assign(pixels, 0.0f);
    const double samples_per_mm = 2.0 * 1e-3 / kC0 * data.fs_hz;
    tbb::parallel_for(0, table->rows, [&](int r) {
        for (int c = 0; c < table->cols; ++c) {
            const glm::dvec2 p = lo + glm::dvec2(c, r) * pixel_mm;
            const glm::dvec2 ld = geometry.line_and_depth(p);
            if (!(ld.x >= -0.5 && ld.x <= data.lines - 0.5 && ld.y >= 0.0 && ld.y <= t.depth_mm))
                continue;
            const double l = std::clamp(ld.x, 0.0, double(data.lines - 1));
            const double sm = std::clamp(ld.y * samples_per_mm, 0.0, double(data.samples - 1));
            const int l0 = std::min(int(l), std::max(data.lines - 2, 0)),
                      s0 = std::min(int(sm), data.samples - 2);
            const std::size_t at = std::size_t(r) * std::size_t(table->cols) + std::size_t(c);
            table->first[at] = l0 * data.samples + s0;
            table->next_line[at] = std::min(l0 + 1, data.lines - 1) == l0 ? 0 : data.samples;
            table->line_frac[at] = float(l - l0);
            table->sample_frac[at] = float(sm - s0);
        }
    });
    const std::lock_guard<std::mutex> lock(mutex);
    cache.push_back(table);
    if (cache.size() > 4) cache.erase(cache.begin());
    return table;
}

}  // namespace

ScanConverted scan_convert(const LineData& data, const probe::Transducer& t, double pixel_mm,
                           float outside) {
    const auto table = scan_table(data, t, pixel_mm);
    ScanConverted out;
    out.pixel_mm = pixel_mm;
    out.origin = table->origin;
    out.image = cv::Mat(table->rows, table->cols, CV_32F, cv::Scalar(outside));
    out.inside = cv::Mat(table->rows, table->cols, CV_8U, cv::Scalar(0));
    tbb::parallel_for(0, table->rows, [&](int r) {
        float* image = out.image.ptr<float>(r);
        uint8_t* inside = out.inside.ptr<uint8_t>(r);
        for (int c = 0; c < table->cols; ++c) {
            const std::size_t at = std::size_t(r) * std::size_t(table->cols) + std::size_t(c);
            if (table->first[at] < 0) continue;
            // Bilinear between the two samples of the two lines around the pixel.
            const float* a = data.values.data() + table->first[at];
            const float* b = a + table->next_line[at];
            const float fl = table->line_frac[at], fsm = table->sample_frac[at];
            const float va = a[0] * (1 - fsm) + a[1] * fsm, vb = b[0] * (1 - fsm) + b[1] * fsm;
            image[c] = va * (1 - fl) + vb * fl;
            inside[c] = 255;
        }
    });
    return out;
}

}  // namespace sonotrace::imaging
