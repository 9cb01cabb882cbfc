#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "imaging/bmode.h"
#include "imaging/box_filter.h"
#include "imaging/psf.h"
#include "imaging/receive_weights.h"
#include "probe/aperture.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/hash.h"

// The speckle of every line (imaging/bmode.h): the scatterer field on sub-lines between
// the lines, lit by the traced illumination, summed across each line's beam through the
// PSF table's rows. synthesize_rf (bmode.cpp) adds the pulse and the specular echoes.
namespace sonotrace::imaging {

namespace detail {

// One line's speckle sums over the samples [begin, end) between two table rows: for each
// sub-line j in [j_first, j_last] (offset from the line's own), sum += (h0_j + f (h1_j -
// h0_j)) v_j, in-phase and quadrature, in order of j. Four sub-lines per pass over the
// samples (each sample's sums stay in registers: the rows are ~16 samples, and one pass
// per sub-line was mostly loop overhead); the additions keep their order, so the sums are
// the same bits as one sub-line at a time. Built for AVX2 too (no FMA: the same numbers).
[[gnu::target_clones("avx2", "default")]] void add_weighted_sub_lines(
    const std::complex<float>* w0, const std::complex<float>* w1, int j_first, int j_last,
    const float* first_sub_line, int N, const float* __restrict f, int begin, int end,
    float* __restrict sum_i, float* __restrict sum_q) {
    auto sub_line = [&](int j) { return first_sub_line + std::ptrdiff_t(j) * N; };
    int j = j_first;
    for (; j + 3 <= j_last; j += 4) {
        float a_i[4], b_i[4], a_q[4], b_q[4];
        for (int u = 0; u < 4; ++u) {
            const std::complex<float> h0 = w0[j + u], h1 = w1[j + u];
            a_i[u] = h0.real(), b_i[u] = h1.real() - h0.real();
            a_q[u] = h0.imag(), b_q[u] = h1.imag() - h0.imag();
        }
        const float* __restrict v0 = sub_line(j);
        const float* __restrict v1 = sub_line(j + 1);
        const float* __restrict v2 = sub_line(j + 2);
        const float* __restrict v3 = sub_line(j + 3);
        for (int i = begin; i < end; ++i) {
            float si = sum_i[i], sq = sum_q[i];
            si += (a_i[0] + f[i] * b_i[0]) * v0[i];
            sq += (a_q[0] + f[i] * b_q[0]) * v0[i];
            si += (a_i[1] + f[i] * b_i[1]) * v1[i];
            sq += (a_q[1] + f[i] * b_q[1]) * v1[i];
            si += (a_i[2] + f[i] * b_i[2]) * v2[i];
            sq += (a_q[2] + f[i] * b_q[2]) * v2[i];
            si += (a_i[3] + f[i] * b_i[3]) * v3[i];
            sq += (a_q[3] + f[i] * b_q[3]) * v3[i];
            sum_i[i] = si, sum_q[i] = sq;
        }
    }
    for (; j <= j_last; ++j) {
        const std::complex<float> h0 = w0[j], h1 = w1[j];
        const float a_i = h0.real(), b_i = h1.real() - h0.real();
        const float a_q = h0.imag(), b_q = h1.imag() - h0.imag();
        const float* __restrict v = sub_line(j);
        for (int i = begin; i < end; ++i) {
            sum_i[i] += (a_i + f[i] * b_i) * v[i];
            sum_q[i] += (a_q + f[i] * b_q) * v[i];
        }
    }
}

}  // namespace detail

namespace {

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

// One sub-line of the speckle: the point a fraction f of the way from line a's mean
// position to line b's (lattice units), lit by the blend of their illuminations times
// the backscatter^2 there (`scatter`); out[i] = sqrt(lit) * the field there. The hot loop of the
// speckle: built for AVX2 and for the baseline, picked at load time (IEEE operations in the same
// order, no FMA in either: the same numbers either way).
struct SubLineEnds {
    const float *ax, *ay, *az, *bx, *by, *bz;  // lattice positions on lines a and b
    const float *lit_a, *lit_b;                // illuminations of lines a and b
};
[[gnu::target_clones("avx2", "default")]] void field_values(uint32_t seed, const SubLineEnds& e,
                                                            float f,
                                                            const float* __restrict scatter, int n,
                                                            float* __restrict out) {
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
        const float amplitude = std::sqrt(((1.0f - f) * lit_a[i] + f * lit_b[i]) * scatter[i]);
        out[i] = amplitude * ScattererField::at_lattice_float(seed, x, y, z);
    }
}

// The map's backscatter as one float per texel: the speckle reads it at every sample of
// every sub-line, and the map's records lie 32 bytes apart.
struct BackscatterGrid {
    int nx = 0, ny = 0;
    float inverse_hx = 0.0f, inverse_hy = 0.0f;
    std::vector<float> b;
    explicit BackscatterGrid(const tissue::AcousticMap<2>& map)
        : nx(map.dims().x),
          ny(map.dims().y),
          inverse_hx(map.inverse_spacing().x),
          inverse_hy(map.inverse_spacing().y),
          b(std::size_t(nx) * std::size_t(ny)) {
        for (std::size_t v = 0; v < b.size(); ++v) b[v] = map.texels()[v].backscatter;
    }
};

// The backscatter^2 along one sub-line: at the fraction f of the way from each sample's
// point on line a (ax, ay: texel units) to line b's, interpolated as AcousticMap::sample()
// interpolates (bilinear, clamped to the edge), squared. Built for AVX2 too (gathers); the
// same numbers either way.
[[gnu::target_clones("avx2", "default")]] void backscatter_squared(
    const BackscatterGrid& g, const float* __restrict ax, const float* __restrict ay,
    const float* __restrict bx, const float* __restrict by, float f, int n, float* __restrict out) {
    const float* __restrict b = g.b.data();
    const float x_max = float(g.nx - 1), y_max = float(g.ny - 1);
    for (int u = 0; u < n; ++u) {
        const float x = std::clamp(ax[u] + f * (bx[u] - ax[u]), 0.0f, x_max);
        const float y = std::clamp(ay[u] + f * (by[u] - ay[u]), 0.0f, y_max);
        const int i = std::min(int(x), g.nx - 2), j = std::min(int(y), g.ny - 2);
        const float fx = x - float(i), fy = y - float(j), gx = 1.0f - fx, gy = 1.0f - fy;
        const int at = j * g.nx + i;
        const float v = gx * gy * b[at] + fx * gy * b[at + 1] + gx * fy * b[at + g.nx] +
                        fx * fy * b[at + g.nx + 1];
        out[u] = v * v;
    }
}

}  // namespace

void spread_over_step(std::array<double, 4>* values, int n, double period) {
    if (!(period > 1.0) || n <= 0) return;
    const int whole = int(period);
    const double fraction = period - double(whole), inverse = 1.0 / period;
    const std::vector<std::array<double, 4>> in(values, values + n);
    std::array<double, 4> sum{};  // of in[i - whole + 1 .. i]
    for (int i = 0; i < n; ++i) {
        const std::array<double, 4>& entering = in[std::size_t(i)];
        const std::array<double, 4>* last = i >= whole ? &in[std::size_t(i - whole)] : nullptr;
        for (std::size_t c = 0; c < 4; ++c) {
            sum[c] += entering[c];
            if (last) sum[c] -= (*last)[c];
            values[i][c] = (sum[c] + (last ? fraction * (*last)[c] : 0.0)) * inverse;
        }
    }
}

namespace {

// What depends on depth only (speckle_lines): the sub-line spacing (mm) and its inverse.
struct AtDepth {
    double d_sub, inverse_d_sub;
};

}  // namespace

namespace detail {

// The widest pooling of a line's light (pool_across_lines): one particle's light, far above
// its neighbours', is spread over about +-30 mm (3 sigma) at most, across the lines and in
// depth. The beam's width alone left the temporal view's rare heavy paths as bright
// streaks and blocks; 20 mm spread them into more spots than 10 mm (41 against 23 on
// seeds 1-8).
constexpr double kWidestPoolingMm = 10.0;

void pool_across_lines(double* light, int lines, int samples, const double* sigma_lines,
                       const double* widest_lines, const double* line_spacing_samples) {
    // Blocks of samples, each copied line by line (the lines' rows are contiguous; a
    // column at a time was a strided read of every line per sample).
    constexpr int kBlock = 32;
    const int L = lines, N = samples;
    const std::size_t size = std::size_t(L) * std::size_t(N);
    // The light pooled from heavy lines (d > 1) and its kernels' sigma (lines) times it,
    // spread in depth afterwards; empty without line_spacing_samples.
    std::vector<double> heavy(line_spacing_samples ? size : 0),
        heavy_sigma(line_spacing_samples ? size : 0);
    tbb::parallel_for(0, (N + kBlock - 1) / kBlock, [&](int block) {
        const int i0 = block * kBlock, count = std::min(kBlock, N - i0);
        std::vector<double> rows(std::size_t(L) * kBlock), out(static_cast<std::size_t>(L));
        std::vector<double> out_heavy(heavy.empty() ? 0 : std::size_t(L)),
            out_sigma(heavy.empty() ? 0 : std::size_t(L));
        std::vector<std::vector<double>> kernels;
        for (int l = 0; l < L; ++l)
            std::copy_n(light + std::size_t(l) * std::size_t(N) + std::size_t(i0), count,
                        rows.begin() + std::ptrdiff_t(l) * kBlock);
        for (int b = 0; b < count; ++b) {
            const int i = i0 + b;
            // Near a phased array's apex the lines converge and the beam spans many of them:
            // wider than the frame, a kernel spreads evenly, so none is made wider.
            const double narrowest = std::min(sigma_lines[i], double(L)),
                         widest = std::clamp(widest_lines[i], narrowest, double(L));
            if (!(narrowest >= 0.3)) continue;
            auto at = [&](int l) { return rows[std::size_t(l) * kBlock + std::size_t(b)]; };
            // The kernels of this sample, by d (0: the widest), normalised, made on first use.
            const int longest = int(std::ceil(widest / narrowest));
            if (kernels.size() < std::size_t(longest + 1)) kernels.resize(std::size_t(longest + 1));
            for (std::vector<double>& kernel : kernels) kernel.clear();  // keeps its memory
            std::fill(out.begin(), out.end(), 0.0);
            std::fill(out_heavy.begin(), out_heavy.end(), 0.0);
            std::fill(out_sigma.begin(), out_sigma.end(), 0.0);
            for (int s = 0; s < L; ++s) {
                const double own = at(s);
                if (!(own > 0.0)) continue;
                // d: the lines within which the others hold at least this line's light.
                double around = 0.0;
                int kernel = 0;
                for (int d = 1; double(d) * narrowest < widest; ++d) {
                    if (s - d >= 0) around += at(s - d);
                    if (s + d < L) around += at(s + d);
                    if (around >= own) {
                        kernel = d;
                        break;
                    }
                }
                const double sigma = kernel > 0 ? double(kernel) * narrowest : widest;
                std::vector<double>& weight = kernels[std::size_t(kernel)];
                if (weight.empty()) {
                    const int reach = int(std::ceil(3.0 * sigma));
                    double total = 0.0;
                    for (int k = -reach; k <= reach; ++k)
                        total += weight.emplace_back(
                            std::exp(-0.5 * double(k) * double(k) / (sigma * sigma)));
                    for (double& w : weight) w /= total;
                }
                const bool spread_in_depth = !heavy.empty() && kernel != 1;
                std::vector<double>& to = spread_in_depth ? out_heavy : out;
                // What reaches past the frame's edges is folded back into it (mirrored at
                // them), so an even field stays even there and the light is kept.
                const int reach = int(weight.size() / 2);
                for (int k = -reach; k <= reach; ++k) {
                    int l = s + k;
                    if (l < 0 || l >= L) {
                        l %= 2 * L;
                        if (l < 0) l += 2 * L;
                        if (l >= L) l = 2 * L - 1 - l;
                    }
                    const double share = own * weight[std::size_t(k + reach)];
                    to[std::size_t(l)] += share;
                    if (spread_in_depth) out_sigma[std::size_t(l)] += share * sigma;
                }
            }
            for (int l = 0; l < L; ++l) {
                const std::size_t at_li = std::size_t(l) * std::size_t(N) + std::size_t(i);
                light[at_li] = out[std::size_t(l)];
                if (!heavy.empty())
                    heavy[at_li] = out_heavy[std::size_t(l)],
                    heavy_sigma[at_li] = out_sigma[std::size_t(l)];
            }
        }
    });
    if (heavy.empty()) return;
    // The heavy lines' light in depth, per line: a Gaussian of its kernels' mean sigma (the
    // light-weighted mean of those pooled into this sample), in samples, normalised over
    // the line's samples (so kept whole). Its taps by the recurrence g(k + 1) = g(k) a b^k,
    // a = exp(-1 / 2 s^2), b = exp(-1 / s^2).
    tbb::parallel_for(0, L, [&](int l) {
        const std::size_t row = std::size_t(l) * std::size_t(N);
        std::vector<double> taps;
        for (int i = 0; i < N; ++i) {
            const double part = heavy[row + std::size_t(i)];
            if (!(part > 0.0)) continue;
            const double s = heavy_sigma[row + std::size_t(i)] / part * line_spacing_samples[i];
            const int reach = int(std::ceil(std::min(3.0 * s, double(N))));
            if (!(s > 0.0) || reach < 1) {
                light[row + std::size_t(i)] += part;
                continue;
            }
            const int first = std::max(0, i - reach), last = std::min(N - 1, i + reach);
            taps.assign(std::size_t(last - first + 1), 0.0);
            const double a = std::exp(-0.5 / (s * s)), b = std::exp(-1.0 / (s * s));
            double g = 1.0, step = a, total = 1.0;
            taps[std::size_t(i - first)] = 1.0;
            for (int k = 1; k <= reach; ++k) {  // g = exp(-k^2 / 2 s^2)
                g *= step, step *= b;
                if (i + k <= last) taps[std::size_t(i + k - first)] = g, total += g;
                if (i - k >= first) taps[std::size_t(i - k - first)] = g, total += g;
            }
            const double scale = part / total;
            for (int j = first; j <= last; ++j)
                light[row + std::size_t(j)] += taps[std::size_t(j - first)] * scale;
        }
    });
}

// The speckle term of every line (see the header): the scatter profile smoothed over a
// pulse length, the scatterer field on sub-lines between the lines' mean positions, and
// each line's sum across its beam weighted by the two-way PSF (complex: in-phase and
// quadrature parts).
void speckle_lines(const probe::Transducer& t, const PsfTable& psf,
                   const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                   const ImagingSettings& settings, const LineData& rf,
                   const tissue::AcousticMap<2>* map, float* speckle_i, float* speckle_q) {
    const int L = rf.lines, N = rf.samples;
    const double fs = rf.fs_hz;
    const probe::PulseEcho pulse(t);
    const probe::ScanGeometry geometry(t);
    const double cell =
        settings.speckle_cell_mm > 0.0 ? settings.speckle_cell_mm : t.wavelength_mm() / 8.0;
    const ScattererField field(settings.seed, cell);
    // The field in lattice units straight from map coordinates (one affine map).
    const MapToWorld to_lattice{to_world.origin / cell, to_world.x_axis / cell,
                                to_world.y_axis / cell};
    const double smooth_sigma = std::max(
        0.5, settings.profile_smoothing * pulse.envelope_fwhm_s() * fs / base::kFwhmPerSigma);
    std::vector<double> depth(static_cast<std::size_t>(N));  // mm per sample
    for (int i = 0; i < N; ++i) depth[std::size_t(i)] = rf.depth_mm(i);

    // Per line and sample: the light v that lights the sub-lines and its mean position,
    // from moments S0 = v, S1 = v d smoothed along the line, with d the offset from the
    // nominal point (small numbers: no cancellation); the fourth slot is unused (kept: one
    // vector register). Lit point by point (the profile's illumination and the map): v is
    // the illumination, which the map's backscatter^2 at each point turns into scattered
    // intensity; otherwise v is the scattered intensity itself, d the scattering's mean.
    // Uninitialised: each line's task writes its whole row (zero-filling ~6 MB first
    // was a serial millisecond per frame).
    const bool lit_by_map = map != nullptr &&
                            profile.illumination.size() == profile.intensity.size() &&
                            profile.illuminated_position.size() == profile.intensity.size();
    const std::optional<BackscatterGrid> grid =
        lit_by_map ? std::optional<BackscatterGrid>(std::in_place, *map) : std::nullopt;
    const std::size_t size = std::size_t(L) * std::size_t(N);
    const auto light = std::make_unique_for_overwrite<double[]>(size);
    const auto mean = std::make_unique_for_overwrite<glm::dvec2[]>(size);
    // The mean positions in lattice units, where lit (each is an end of two gaps below).
    const auto lattice = std::make_unique_for_overwrite<glm::vec3[]>(size);
    const int profile_lines = std::min(L, profile.lines);
    const int r = box3_radius(smooth_sigma);
    const double step_samples = 2.0 * profile.step_mm * 1e-3 / tissue::kReferenceSpeed * fs;
    tbb::parallel_for(0, L, [&](int l) {
        const std::size_t row = std::size_t(l) * std::size_t(N);
        double* const light_row = light.get() + row;
        glm::dvec2* const mean_row = mean.get() + row;
        const probe::ScanLine line = geometry.line(l);
        // Where the line has no light of its own its mean position is its nominal point,
        // there for the light its neighbours may lend it (pool_across_lines).
        auto dark = [&](int i) {
            light_row[i] = 0.0;
            mean_row[i] = line.origin + line.direction * depth[std::size_t(i)];
            lattice[row + std::size_t(i)] = glm::vec3(to_lattice(mean_row[i]));
        };
        auto no_echo = [&] {
            for (int i = 0; i < N; ++i) dark(i);
        };
        if (l >= profile_lines) return no_echo();
        // The moments and the smoothing's scratch, each padded by r zeros at both ends.
        const std::size_t padded = std::size_t(N + 2 * r);
        const auto buffer = std::make_unique_for_overwrite<Moments[]>(2 * padded);
        Moments* const m = buffer.get() + r;
        Moments* const scratch = buffer.get() + padded;
        for (Moments* padding : {buffer.get(), m + N, scratch, scratch + N + r})
            std::fill_n(padding, r, Moments{});
        double peak = 0.0;  // of v
        for (int i = 0; i < N; ++i) {
            const std::size_t at = row + std::size_t(i);
            const double vi =
                lit_by_map ? double(profile.illumination[at]) : double(profile.intensity[at]);
            if (!(vi > 0.0)) {
                m[i] = Moments{};
                continue;
            }
            const glm::dvec2 d =
                glm::dvec2(lit_by_map ? profile.illuminated_position[at] : profile.position[at]) -
                (line.origin + line.direction * depth[std::size_t(i)]);
            m[i] = {vi, vi * d.x, vi * d.y, 0.0};
            peak = std::max(peak, vi);
        }
        if (!(peak > 0.0)) return no_echo();  // a line without echo
        spread_over_step(m, N, step_samples);
        const Moments* smoothed = smooth_box3(m - r, scratch, N, r);
        for (int i = 0; i < N; ++i) {
            const Moments& mi = smoothed[i];
            const double v = mi[0];
            // Running sums leave rounding residues where there was nothing.
            if (!(v > 1e-9 * peak)) {
                dark(i);
                continue;
            }
            const double inverse_v = 1.0 / v;
            const glm::dvec2 d(mi[1] * inverse_v, mi[2] * inverse_v);
            light_row[i] = v;
            mean_row[i] = (line.origin + line.direction * depth[std::size_t(i)]) + d;
            lattice[row + std::size_t(i)] = glm::vec3(to_lattice(mean_row[i]));
        }
    });

    // The illumination across lines (pool_across_lines): each line's is an estimate from
    // its own few particles of what lights its beam. Only where the map gives the tissue
    // its backscatter, so tissue edges stay sharp.
    if (lit_by_map && L > 1) {
        std::vector<double> sigma_lines(static_cast<std::size_t>(N)),
            widest(static_cast<std::size_t>(N)), line_spacing_samples(static_cast<std::size_t>(N));
        const double sample_mm = N > 1 ? depth[1] - depth[0] : 1.0;
        for (int i = 0; i < N; ++i) {
            const double d = depth[std::size_t(i)];
            const double spacing_mm = std::max(geometry.line_spacing_mm(d), 1e-6);
            sigma_lines[std::size_t(i)] = receive_beam_sigma_lines(t, geometry, d);
            widest[std::size_t(i)] = kWidestPoolingMm / spacing_mm;
            line_spacing_samples[std::size_t(i)] = spacing_mm / sample_mm;
        }
        pool_across_lines(light.get(), L, N, sigma_lines.data(), widest.data(),
                          line_spacing_samples.data());
    }
    // The scatterer field on K sub-lines per gap between lines, interpolated between the
    // lines' mean positions (the nominal line spacing where a line has no echo), so that
    // neighbouring lines see the same scatterers where their beams overlap; each scaled by
    // the square root of the intensity that lights it: the lines' illumination times the
    // map's backscatter^2 at the sub-line's point (so tissue lights only where it is, not
    // across the whole beam that reached it), or without a map the lines' intensity. Sub-lines at
    // most the narrowest beam's sigma (the receive PSF at the F-number) apart: every line sums >= 7
    // of them.
    double widest_gap = 0.0;
    for (double d : {0.0, 0.5 * t.depth_mm, t.depth_mm})
        widest_gap = std::max(widest_gap, geometry.line_spacing_mm(d));
    const double narrowest_sigma =
        std::max(cell, t.wavelength_mm() * std::max(t.rx_f_number, 0.5) / base::kFwhmPerSigma);
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
        std::vector<float> lit_a(n, 0.0f), lit_b(n, 0.0f), scatter(n, 1.0f);
        // Where the ends lie on the map (texel units), for the backscatter there.
        std::vector<float> texel_a[2], texel_b[2];
        for (auto* e : {&texel_a[0], &texel_a[1], &texel_b[0], &texel_b[1]})
            e->assign(lit_by_map ? n : 0, 0.0f);
        const int other = L == 1 ? l : l + 1;
        for (int i = 0; i < N; ++i) {
            const std::size_t at = std::size_t(l) * n + std::size_t(i);
            const std::size_t next = std::size_t(other) * n + std::size_t(i);
            const bool placed_a = light[at] > 0.0, placed_b = light[next] > 0.0;
            if (!placed_a && !placed_b) continue;
            glm::dvec2 a = mean[at], b = mean[next];
            glm::vec3 pa, pb;
            if (placed_a && placed_b) {
                pa = lattice[at], pb = lattice[next];
            } else {  // a line without echo: the nominal gap from the other end
                const glm::dvec2 nominal = geometry.point(other, depth[std::size_t(i)]) -
                                           geometry.point(l, depth[std::size_t(i)]);
                if (!placed_a) a = b - nominal;
                if (!placed_b) b = a + nominal;
                pa = glm::vec3(to_lattice(a)), pb = glm::vec3(to_lattice(b));
            }
            const std::size_t u = std::size_t(i);
            ends[0][u] = pa.x, ends[1][u] = pa.y, ends[2][u] = pa.z;
            ends[3][u] = pb.x, ends[4][u] = pb.y, ends[5][u] = pb.z;
            lit_a[u] = float(light[at]), lit_b[u] = float(light[next]);
            if (lit_by_map) {
                texel_a[0][u] = float(a.x) * grid->inverse_hx;
                texel_a[1][u] = float(a.y) * grid->inverse_hy;
                texel_b[0][u] = float(b.x) * grid->inverse_hx;
                texel_b[1][u] = float(b.y) * grid->inverse_hy;
            }
        }
        const SubLineEnds sub_line_ends{ends[0].data(), ends[1].data(), ends[2].data(),
                                        ends[3].data(), ends[4].data(), ends[5].data(),
                                        lit_a.data(),   lit_b.data()};
        // The last gap ends on the last line; a single line is its own one sub-line.
        const int last_k = L == 1 ? 0 : (l == gaps - 1 ? K : K - 1);
        for (int k = 0; k <= last_k; ++k) {
            const int s = std::min(l * K + k, sub_lines - 1);
            const float f = float(k) / float(K);
            if (lit_by_map)  // the backscatter^2 where this sub-line crosses each depth
                backscatter_squared(*grid, texel_a[0].data(), texel_a[1].data(), texel_b[0].data(),
                                    texel_b[1].data(), f, N, scatter.data());
            field_values(field.seed(), sub_line_ends, f, scatter.data(), N,
                         sub.get() + std::size_t(s) * n);
        }
    });

    // Each line sums the sub-lines under its two-way beam, weighted by the line's PSF
    // H(x, z) at their offsets x = j d_sub. With white field values (lattice correlation
    // along the sub-lines and the samples divided out), the mean square of the sum is
    // w sum |H_j|^2 d_sub = w integral |H|^2 dx: the profile's intensity times the lateral
    // power of the two-way beam, which peaks at the transmit focus. Divided by that power
    // on the central line at the focus, the level there is the profile's (the scatter
    // fraction is calibrated at the focus; elsewhere the aperture sets it).
    const double axial_correlation =
        lattice_correlation_sum((rf.depth_mm(1) - rf.depth_mm(0)) / cell);
    // What depends on depth only, once per sample rather than per line and sample.
    std::vector<AtDepth> at_depth(static_cast<std::size_t>(N));
    std::vector<double> scale(static_cast<std::size_t>(N));
    for (int i = 0; i < N; ++i) {
        const double d = depth[std::size_t(i)];
        AtDepth& a = at_depth[std::size_t(i)];
        a.d_sub = std::max(geometry.line_spacing_mm(d), 1e-6) / K;
        a.inverse_d_sub = 1.0 / a.d_sub;
        scale[std::size_t(i)] = std::sqrt(a.d_sub / (lattice_correlation_sum(a.d_sub / cell) *
                                                     axial_correlation * psf.focal_power()));
    }
    // H at the sub-lines' offsets, per table row (once per probe set-up and K).
    const std::shared_ptr<const PsfTable::SubLineWeights> weights = psf.sub_line_weights(K);
    const int max_reach = weights->reach;
    // Per line, the samples between two table rows share the rows' weights at the
    // sub-lines' offsets (evaluated once per row, at its depth's sub-line spacing, which
    // changes by under a per cent over a row): each sample then blends the two sums
    // linearly in depth, in loops over samples that vectorise.
    const double dz = psf.dz();
    std::vector<int> first_of_row(static_cast<std::size_t>(psf.depths()) + 1, N);
    for (int i = N - 1; i >= 0; --i) {
        const int last =
            std::clamp(int(std::floor(depth[std::size_t(i)] / dz)), 0, psf.depths() - 1);
        for (int q = 0; q <= last; ++q)
            first_of_row[std::size_t(q)] = std::min(first_of_row[std::size_t(q)], i);
    }
    tbb::parallel_for(0, L, [&](int l) {
        const std::size_t row = std::size_t(l) * std::size_t(N);
        const int centre = l * K;
        std::vector<float> sum_i(static_cast<std::size_t>(N), 0.0f),
            sum_q(static_cast<std::size_t>(N), 0.0f), f(static_cast<std::size_t>(N), 0.0f);
        for (int k = 0; k < psf.depths(); ++k) {
            const int begin = first_of_row[std::size_t(k)], end = first_of_row[std::size_t(k) + 1];
            if (begin >= end) continue;
            const double z0 = k * dz, z1 = (k + 1) * dz;
            for (int i = begin; i < end; ++i)
                f[std::size_t(i)] = float((depth[std::size_t(i)] - z0) / dz);
            const double d0 = std::max(geometry.line_spacing_mm(z0), 1e-6) / K,
                         d1 = std::max(geometry.line_spacing_mm(z1), 1e-6) / K;
            const PsfTable::Row& nearest = psf.row(l, k);
            // Sub-lines 50 dB below the peak weight at both rows add nothing visible.
            const int reach = std::min(
                {max_reach, int(std::ceil(nearest.half * nearest.dx / std::min(d0, d1))),
                 std::max(weights->significant_reach(l, k), weights->significant_reach(l, k + 1))});
            const std::complex<float>*w0 = weights->at(l, k), *w1 = weights->at(l, k + 1);
            const int j_first = std::max(-reach, -centre),
                      j_last = std::min(reach, sub_lines - 1 - centre);
            const float* first_sub_line = sub.get() + std::size_t(centre) * std::size_t(N);
            detail::add_weighted_sub_lines(w0, w1, j_first, j_last, first_sub_line, N, f.data(),
                                           begin, end, sum_i.data(), sum_q.data());
        }
        for (int i = 0; i < N; ++i) {
            const bool lit = light[row + std::size_t(i)] > 0.0;  // nothing where nothing is lit
            speckle_i[row + std::size_t(i)] =
                lit ? float(double(sum_i[std::size_t(i)]) * scale[std::size_t(i)]) : 0.0f;
            speckle_q[row + std::size_t(i)] =
                lit ? float(double(sum_q[std::size_t(i)]) * scale[std::size_t(i)]) : 0.0f;
        }
    });
}

}  // namespace detail

}  // namespace sonotrace::imaging
