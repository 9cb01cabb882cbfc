#include "imaging/bmode.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <opencv2/core.hpp>
#include <optional>
#include <unordered_map>

#include "imaging/psf.h"
#include "imaging/receive_weights.h"
#include "probe/aperture.h"
#include "probe/pulse.h"
#include "simulator/interactions.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/hash.h"
#include "tissue/volume.h"

namespace sonotrace::imaging {

using base::kFwhmPerSigma;

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

constexpr double kC0 = tissue::kReferenceSpeed;  // m/s

using base::mix64;
using probe::ScanLine;

// out = in (*) kernel (centred), zero outside. The interior as a weighted sum of shifted
// rows (each sum adds its terms in tap order), the edges as they come.
void convolve(const float* in, int n, const std::vector<float>& kernel, float* out) {
    using T = float;
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
    // The interior: tap k's row is the input shifted by k - half, summed in tap order.
    std::vector<const float*> rows(static_cast<std::size_t>(taps));
    for (int k = 0; k < taps; ++k) rows[std::size_t(k)] = in + first + (k - half);
    tissue::weighted_sum_of_rows(rows.data(), kernel.data(), taps, std::size_t(last - first),
                                 out + first);
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
    const double smooth_sigma =
        std::max(0.5, settings.profile_smoothing * pulse.envelope_fwhm_s() * fs / kFwhmPerSigma);
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
    const double step_samples = 2.0 * profile.step_mm * 1e-3 / kC0 * fs;
    tbb::parallel_for(0, L, [&](int l) {
        const std::size_t row = std::size_t(l) * std::size_t(N);
        double* const light_row = light.get() + row;
        glm::dvec2* const mean_row = mean.get() + row;
        auto no_echo = [&] {
            std::fill_n(light_row, N, 0.0);
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
                light_row[i] = 0.0;
                mean_row[i] = glm::dvec2(0.0);
                continue;
            }
            const double inverse_v = 1.0 / v;
            const glm::dvec2 d(mi[1] * inverse_v, mi[2] * inverse_v);
            light_row[i] = v;
            mean_row[i] = (line.origin + line.direction * depth[std::size_t(i)]) + d;
            lattice[row + std::size_t(i)] = glm::vec3(to_lattice(mean_row[i]));
        }
    });

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
        std::max(cell, t.wavelength_mm() * std::max(t.rx_f_number, 0.5) / kFwhmPerSigma);
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

// out[n] += Re{amplitude (p + i q)((n - at) / fs)} for n in [lo, hi]: the pulse-echo
// waveform with the echo's phase.
void add_pulse(const probe::PulseEcho& pulse, double at, double fs, std::complex<double> amplitude,
               float* out, int n) {
    const double reach = pulse.half_length_s() * fs;
    const int lo = std::max(0, int(std::ceil(at - reach))),
              hi = std::min(n - 1, int(std::floor(at + reach)));
    for (int i = lo; i <= hi; ++i) {
        const std::complex<double> p = pulse.analytic((i - at) / fs);
        out[i] += float(amplitude.real() * p.real() - amplitude.imag() * p.imag());
    }
}

}  // namespace

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

namespace {
// 20 log10 x = (20 / ln 10) ln x, over the range; the gain shifts the range's top.
float compression_scale(double dynamic_range_db) {
    return float(20.0 / std::numbers::ln10 / dynamic_range_db);
}
float compression_offset(double gain_db, double dynamic_range_db) {
    return float((gain_db + dynamic_range_db) / dynamic_range_db);
}
}  // namespace

Compression::Compression(int samples, double fs_hz, const ImagingSettings& settings)
    : scale_(compression_scale(settings.dynamic_range_db)), offset_(std::size_t(samples)) {
    for (int i = 0; i < samples; ++i) {
        offset_[std::size_t(i)] = compression_offset(
            settings.gain_db + tgc_gain_db(settings.tgc, sample_depth_mm(i, fs_hz)),
            settings.dynamic_range_db);
    }
}

float log_compress(float envelope, double gain_db, double dynamic_range_db) {
    ImagingSettings settings;
    settings.gain_db = gain_db, settings.dynamic_range_db = dynamic_range_db;
    const Compression compression(1, 1.0, settings);  // no TGC: the one offset at every depth
    return compression(envelope, compression.offset(0));
}

double sample_depth_mm(int i, double fs_hz) {
    return 0.5 * kC0 * (double(i) / fs_hz) * 1e3;
}

double LineData::depth_mm(int i) const {
    return sample_depth_mm(i, fs_hz);
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
    // The way back lies twice the incidence from the mirror direction.
    return simulator::lobe_share(2.0 * std::acos(std::clamp(cos_incidence, -1.0, 1.0)),
                                 lobe_exponent, half_acceptance_rad);
}

LineData synthesize_rf(const probe::Transducer& t, const probe::Sources<2>& sources,
                       const std::vector<simulator::EchoEvent<2>>& events,
                       const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                       const ImagingSettings& settings, const std::vector<PointEcho>& points,
                       std::shared_ptr<const simulator::ReceiveWeights> receive,
                       const tissue::AcousticMap<2>* map) {
    LineData rf = rf_layout(t, settings);
    const int L = rf.lines, N = rf.samples;
    const double fs = rf.fs_hz;
    const probe::PulseEcho pulse(t);
    const probe::ScanGeometry geometry(t);

    // Particle (line, index within line) -> source, for launch points and energies.
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
                              profile.position.size() == profile.intensity.size();
    // The lines' PSF table, where speckle or reflections need it (computed once per probe
    // set-up).
    const std::shared_ptr<const PsfTable> psf =
        with_speckle || !event_order.empty() ? PsfTable::of(t) : nullptr;
    if (!receive && !event_order.empty())
        receive = receive_weights(t, sources, to_world.face_in_map);
    const std::size_t size = std::size_t(L) * std::size_t(N);
    const auto speckle_i = std::make_unique_for_overwrite<float[]>(with_speckle ? size : 0);
    const auto speckle_q = std::make_unique_for_overwrite<float[]>(with_speckle ? size : 0);
    if (with_speckle)
        speckle_lines(t, *psf, profile, to_world, settings, rf, map, speckle_i.get(),
                      speckle_q.get());

    // -- RF per line: speckle (*) pulse, plus a pulse at each reflection bin's echo time
    // and at each point target's. Convolution taps: kernel[m + half] = p(-m / fs).
    const int half = int(std::ceil(pulse.half_length_s() * fs));
    std::vector<float> taps_i(std::size_t(2 * half + 1)), taps_q(std::size_t(2 * half + 1));
    for (int m = -half; m <= half; ++m) {
        taps_i[std::size_t(m + half)] = float(pulse.in_phase(-m / fs));
        taps_q[std::size_t(m + half)] = float(-pulse.quadrature(-m / fs));  // Re{(a+ib)(p+iq)}
    }
    const double depth_to_samples = 2.0 * 1e-3 / kC0 * fs;
    const int echo_half_width = std::max(1, int(std::lround(0.5 * pulse.envelope_fwhm_s() * fs)));
    rf.values.resize(size);
    tbb::parallel_for(0, L, [&](int l) {
        // Reflections: per sample bin, the intensity that reached an interface and came
        // back (energy x R^2 x two-way loss) times the squared plane response of the line
        // at the reflector's depth and tilt, with the intensity-weighted echo time (the
        // pulse goes there exactly: a split between samples 1/(4 f0) apart would add two
        // pulses a quarter period out of phase) and the phase of the plane response.
        std::vector<double> reflected(std::size_t(N), 0.0), reflected_time(std::size_t(N), 0.0);
        std::vector<std::complex<double>> phase(std::size_t(N), 0.0);
        const auto& line = of_line[std::size_t(l)];
        const ScanLine axis = geometry.line(l);
        const glm::dvec2 across(axis.direction.y, -axis.direction.x);
        // The line's echo of an untilted plane by depth row, as diffuse echoes ask it
        // (NaN: not yet): most of a line's echoes, and few rows.
        std::vector<std::complex<double>> untilted(
            psf ? std::size_t(psf->depths()) : 0,
            std::complex<double>(std::numeric_limits<double>::quiet_NaN(), 0.0));
        const uint32_t events_end = event_start[std::size_t(l) + 1];
        for (uint32_t n = event_start[std::size_t(l)]; n < events_end; ++n) {
            // The receive weight of an event a few ahead, fetched now: the weights are
            // megabytes, read at random, and the wait for each was half of this loop.
            if (receive && n + 6 < events_end) {
                const auto& ahead = events[event_order[n + 6]];
                if (const float* w = receive->row(uint32_t(l), ahead.particle))
                    __builtin_prefetch(w + receive->column(ahead.time_s));
            }
            const auto& e = events[event_order[n]];
            if (e.particle >= line.size()) continue;
            const auto& source = sources[line[e.particle]];
            double intensity = double(e.energy) * e.weight;
            double echo_time = e.time_s;  // the particle came back itself: the full round trip
            std::complex<double> response = 1.0;
            if (e.kind != simulator::EchoKind::returned_to_probe) {
                intensity *= double(e.energy) / std::max(double(source.energy), 1e-30) *
                             double(e.return_weight);
                // The apparent reflector: where the particle's path, unfolded at every
                // mirror and timed at c0, puts the event, measured along the line (the
                // depth of its image point: a mirrored path images at the mirror position;
                // a direct one at the event's own depth, whatever the particle's slant),
                // tilted from the line by the interface's normal (the image's receive sees
                // the echo come back the way the particle left, by reciprocity). The
                // aperture's plane echo there is the echo of every particle of the beam
                // that meets the plane: one pulse at 2 range / c0, not one per slant path
                // (which would smear the focusing delays over the echo). A rough
                // interface scatters its lobe, of which the receive aperture takes its
                // share.
                const glm::dvec2 launch =
                    glm::dvec2(source.position) - to_world.face_in_map - axis.origin;
                const double flight_mm = double(e.time_s - source.time_s) * kC0 * 1e3;
                const double range_mm =
                    std::max(glm::dot(launch, axis.direction) +
                                 flight_mm * glm::dot(glm::dvec2(source.direction), axis.direction),
                             1e-3);
                echo_time = 2.0 * range_mm * 1e-3 / kC0;
                // The plane's tilt as the aperture sees it. A direct echo (no reflection
                // before it): the plane's normal against the way the particle arrives,
                // carried to the line's frame by the angle it was launched at; the plane
                // sends the particle's piece of the wavefront back the way it came, and by
                // reciprocity to the aperture, only if it faces it. For an unturned beam
                // this is the plane's tilt from the line; a piece turned by refraction
                // (the skull) echoes from the planes that face it, not from those that
                // face the probe. Echoes after reflections keep the plane's tilt from the
                // line: judged in the particle's frame, paths between a mirror and a wire
                // outshone the mirror image (mirror_image, seed 3: 6.7 mm off).
                const bool direct = e.bounces == 0 && glm::dot(e.direction, e.direction) > 0.0f;
                const glm::dvec2 arriving = direct ? glm::dvec2(e.direction) : axis.direction;
                glm::dvec2 away = -glm::dvec2(e.normal);
                if (glm::dot(away, arriving) < 0.0) away = -away;
                auto angle_from = [](const glm::dvec2& v, const glm::dvec2& from) {
                    return std::atan2(glm::dot(v, glm::dvec2(from.y, -from.x)), glm::dot(v, from));
                };
                // Only where it is used (not by a direct diffuse echo, most of them).
                auto tilt = [&] {
                    return glm::dot(away, away) > 0.0
                               ? angle_from(away, arriving) +
                                     (direct
                                          ? angle_from(glm::dvec2(source.direction), axis.direction)
                                          : 0.0)
                               : 0.0;
                };
                // The amplitude share of the reflector's lobe that heads back the way the
                // particle came, within the receive's half-angle at this range.
                auto heads_back = [&] {
                    const double half_angle =
                        std::atan(0.5 * t.receive_aperture_mm(range_mm) / range_mm);
                    return std::sqrt(reflection_back_fraction(double(e.cos_incidence),
                                                              e.lobe_exponent, half_angle));
                };
                if (e.kind == simulator::EchoKind::diffuse) {
                    // The share of the lobe that heads back the way the particle came (by
                    // reciprocity, to the aperture), by the particle's own incidence, so a
                    // piece of the beam meeting a rough surface at grazing incidence sends
                    // next to nothing back, whatever the plane's tilt to the line; after
                    // reflections too (bone met at grazing incidence after a bounce lit the
                    // temporal view's ventricles 37 dB above the brain).
                    std::complex<double>& plane = untilted[std::size_t(psf->depth_index(range_mm))];
                    if (std::isnan(plane.real())) plane = psf->plane_echo(l, range_mm, 0.0);
                    response = plane * heads_back();
                } else {
                    response = psf->plane_echo(l, range_mm, std::sin(tilt()));
                    // After reflections the plane is judged from the line (above), but the
                    // echo still returns along the particle's path reversed only if the
                    // mirror sends it back the way it came: a mirror met obliquely sends
                    // it on (gel or bone met at 30 degrees after a bounce lit a far line
                    // 47 dB above the brain at 100 mm).
                    if (!direct) response *= heads_back();
                }
                // Receive, once (receive_weights): a reflector across the whole beam
                // averages it to 1, so its plane echo above stays exact; a target smaller
                // than the beam echoes on the lines whose receive sees it.
                if (receive) intensity *= receive->at(uint32_t(l), e.particle, e.time_s);
            }
            const double position = echo_time * fs;
            if (!(position >= 0.0) || position >= double(N - 1)) continue;
            const double weighted = intensity * std::norm(response);
            if (!(weighted > 0.0)) continue;
            reflected[std::size_t(position)] += weighted;
            reflected_time[std::size_t(position)] += weighted * position;
            phase[std::size_t(position)] += intensity * response;
        }

        const std::size_t row = std::size_t(l) * std::size_t(N);
        float* out = rf.values.data() + row;
        if (with_speckle) {
            std::vector<float> quadrature(static_cast<std::size_t>(N));
            convolve(speckle_i.get() + row, N, taps_i, out);
            convolve(speckle_q.get() + row, N, taps_q, quadrature.data());
            for (int i = 0; i < N; ++i) out[i] += quadrature[std::size_t(i)];
        } else {
            std::fill_n(out, N, 0.0f);
        }
        // One wavefront meeting one interface is one echo of amplitude sqrt(sum of its
        // intensities), however its particles fall into bins: bin i's pulse gets I_i /
        // sqrt(sum of I within the pulse's half width of i), which sums to sqrt(I) over an
        // isolated echo split across neighbouring bins (sqrt per bin would add up to
        // sqrt(bins) times too much).
        for (int i = 0; i < N; ++i) {
            const double intensity = reflected[std::size_t(i)];
            if (!(intensity > 0.0)) continue;
            const double at = reflected_time[std::size_t(i)] / intensity;  // samples
            double local = 0.0;  // summed directly: prefix sums would cancel catastrophically
            for (int j = std::max(0, i - echo_half_width);
                 j <= std::min(N - 1, i + echo_half_width); ++j)
                local += reflected[std::size_t(j)];
            const std::complex<double> p = phase[std::size_t(i)];
            const double magnitude = std::abs(p);
            const std::complex<double> unit = magnitude > 0.0 ? p / magnitude : 1.0;
            add_pulse(pulse, at, fs, intensity / std::sqrt(local) * unit, out, N);
        }
        if (!points.empty()) {  // through the line's exact fields (few targets: no table)
            const probe::LineFields f(t, probe::line_array(t, l));
            // The receive aperture by depth: targets often share depths (a grid's rows).
            std::map<double, probe::LineFields::Receive> apertures;
            auto receive_at = [&](double z) -> const probe::LineFields::Receive& {
                auto it = apertures.find(z);
                if (it == apertures.end()) it = apertures.emplace(z, f.receive_aperture(z)).first;
                return it->second;
            };
            for (const PointEcho& p : points) {
                const glm::dvec2 d = p.position - to_world.face_in_map - axis.origin;
                const glm::dvec2 q(glm::dot(d, across), glm::dot(d, axis.direction));
                if (!(q.y > 0.0) || q.y > t.depth_mm) continue;
                // Beyond its reach nothing: its echo there is 45 dB and more below its
                // peak (test: BroadbandFields.PointEchoesFadeBeforeTheirReach).
                if (std::abs(q.x) > PsfTable::point_reach_mm(t, q.y)) continue;
                const std::complex<double> h = f.broadband(q, receive_at(q.y)).two_way.echo;
                add_pulse(pulse, (q.y + p.delay_mm) * depth_to_samples, fs, p.amplitude * h, out,
                          N);
            }
        }
    });
    return rf;
}

}  // namespace sonotrace::imaging
