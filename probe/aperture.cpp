#include "probe/aperture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <mutex>
#include <numbers>

#include "probe/array_geometry.h"
#include "probe/field_kernels.h"
#include "tissue/base/fast_math.h"

#include <vector>

namespace sonotrace::probe {

LineArray line_array(const Transducer& t, int l, double snap_along) {
    const ScanGeometry geometry(t);
    const ArrayGeometry& array = geometry.array();
    const ScanLine line = geometry.line(l);
    LineArray a;
    a.pitch_mm = t.pitch_mm;
    const double length = t.array_length_mm(), half = 0.5 * length;
    // The line's centre on the array (mm along it); steered lines use the whole array.
    const std::optional<double> aperture_centre = array.aperture_centre(line);
    double centre = aperture_centre.value_or(0.0);
    if (snap_along > 0.0 && aperture_centre) {
        const double first = -half + 0.5 * t.pitch_mm;  // the first element's centre
        centre = first + std::round((centre - first) / snap_along) * snap_along;
    }
    a.position.reserve(std::size_t(t.elements)), a.normal.reserve(std::size_t(t.elements));
    a.along.reserve(std::size_t(t.elements));
    for (int e = 0; e < t.elements; ++e) {
        const double s = -half + (e + 0.5) * t.pitch_mm;  // along the array
        double along = s - centre;
        if (array.closed()) along -= length * std::floor((along + half) / length);  // [-L/2, L/2)
        const ArrayPoint p = array.seen_from_line(s, along, line);
        a.position.push_back(p.position);
        a.normal.push_back(p.normal);
        a.along.push_back(along);
    }
    const auto [lowest, highest] = std::minmax_element(a.along.begin(), a.along.end());
    if (lowest != a.along.end()) a.lowest = *lowest, a.highest = *highest;
    return a;
}

namespace {
// The span [lo, hi] (mm along the array) an aperture of width_mm centred on the line
// occupies: at least two pitches, so that it holds an element wherever it sits, clipped
// by the array's ends (a ring's elements are numbered from anywhere along it).
std::pair<double, double> aperture_window(const LineArray& array, double width_mm) {
    const double half = 0.5 * std::max(width_mm, 2.0 * array.pitch_mm);
    const double first = array.lowest - 0.5 * array.pitch_mm,
                 last = array.highest + 0.5 * array.pitch_mm;
    return {std::max(-half, first), std::min(half, last)};
}

std::size_t nearest_element(const LineArray& array) {
    std::size_t nearest = 0;
    for (std::size_t e = 1; e < array.along.size(); ++e)
        if (std::abs(array.along[e]) < std::abs(array.along[nearest])) nearest = e;
    return nearest;
}
}  // namespace

std::vector<double> aperture_weights(const LineArray& array, double width_mm, Apodization a) {
    const std::size_t n = array.along.size();
    std::vector<double> w(n, 0.0);
    if (n == 0) return w;
    const auto [lo, hi] = aperture_window(array, width_mm);
    double total = 0.0;
    for (std::size_t e = 0; e < n; ++e) {
        const double s = array.along[e];
        if (s < lo || s > hi) continue;
        w[e] = apodization_weight(a, (s - lo) / std::max(hi - lo, 1e-12));
        total += w[e];
    }
    // A window whose only elements sit on its zero edges.
    if (!(total > 0.0)) w[nearest_element(array)] = 1.0;
    return w;
}

std::pair<int, int> aperture_span(const LineArray& array, double width_mm, Apodization a) {
    const int n = int(array.along.size());
    if (n == 0) return {0, 0};
    const auto window = aperture_window(array, width_mm);
    const double lo = window.first, hi = window.second;  // not a binding: lambdas take these
    auto weighted = [&](int e) {
        const double s = array.along[std::size_t(e)];
        return s >= lo && s <= hi &&
               apodization_weight(a, (s - lo) / std::max(hi - lo, 1e-12)) > 0.0;
    };
    int first = 0, last = n;
    // Elements in order along the array (all but a ring whose numbering wraps inside it):
    // the window's ends found by bisection, the table asks here for every row it computes.
    if (array.along.front() == array.lowest && array.along.back() == array.highest) {
        first =
            int(std::lower_bound(array.along.begin(), array.along.end(), lo) - array.along.begin());
        last =
            int(std::upper_bound(array.along.begin(), array.along.end(), hi) - array.along.begin());
    }
    while (first < last && !weighted(first)) ++first;
    while (last > first && !weighted(last - 1)) --last;
    if (first == last) first = int(nearest_element(array)), last = first + 1;
    return {first, last};
}

std::shared_ptr<const PulseEcho::Band> pulse_band(const Transducer& t, BandUse use) {
    const std::array<double, 5> key{t.frequency_mhz, t.bandwidth, t.band_shape, t.cycles,
                                    double(int(use))};
    static std::mutex mutex;
    static std::vector<std::pair<std::array<double, 5>, std::shared_ptr<const PulseEcho::Band>>>
        kept;
    const std::lock_guard<std::mutex> lock(mutex);
    for (const auto& [k, band] : kept)
        if (k == key) return band;
    const PulseEcho pulse(t);
    auto band = std::make_shared<const PulseEcho::Band>(
        use == BandUse::echo ? pulse.band(kBandSpreadPeriods / pulse.frequency_hz())
                             : pulse.band(0.0, kEnergyFloor));
    kept.emplace_back(key, band);
    if (kept.size() > 8) kept.erase(kept.begin());
    return band;
}

BroadbandEcho broadband_echo(const PulseEcho::Band& band, const std::complex<double>* h) {
    const int M = band.count();
    BroadbandEcho out;
    // c_m = s_m H_m; the envelope |e(t)| is that of the baseband sum b(t) = sum_m c_m
    // w(t)^m, w = exp(i 2 pi step t): |b|^2 on the band's search grid, the peak refined by
    // a parabola through the largest and its neighbours, b there by Horner's rule.
    thread_local std::vector<std::complex<double>> c;
    c.resize(std::size_t(M));
    double energy = 0.0;
    for (int m = 0; m < M; ++m) {
        c[std::size_t(m)] = band.weight[std::size_t(m)] * h[m];
        energy += std::norm(c[std::size_t(m)]);
    }
    out.power = energy / band.power;
    if (!(energy > 0.0)) return out;
    const double dt = band.search_dt;
    const int half = band.search_half;
    auto baseband = [&](double t) {
        const std::complex<double> w = std::polar(1.0, 2.0 * std::numbers::pi * band.step_hz * t);
        std::complex<double> b = 0.0;
        for (int m = M - 1; m >= 0; --m) b = b * w + c[std::size_t(m)];
        return b;
    };
    // |b|^2 on the grid from the band's phasors (real arithmetic: it vectorises).
    thread_local std::vector<double> c_re, c_im, norms;
    c_re.resize(std::size_t(M)), c_im.resize(std::size_t(M));
    for (int m = 0; m < M; ++m)
        c_re[std::size_t(m)] = c[std::size_t(m)].real(),
        c_im[std::size_t(m)] = c[std::size_t(m)].imag();
    norms.resize(std::size_t(2 * half + 1));
    const double* grid = reinterpret_cast<const double*>(band.search.data());
    for (int k = 0; k <= 2 * half; ++k) {
        const double* w = grid + 2 * std::size_t(k) * std::size_t(M);
        double re = 0.0, im = 0.0;
        for (int m = 0; m < M; ++m) {
            const double wr = w[2 * m], wi = w[2 * m + 1];
            re += c_re[std::size_t(m)] * wr - c_im[std::size_t(m)] * wi;
            im += c_re[std::size_t(m)] * wi + c_im[std::size_t(m)] * wr;
        }
        norms[std::size_t(k)] = re * re + im * im;
    }
    int best = 0;
    double best_norm = -1.0;
    for (int k = -half; k <= half; ++k)
        if (norms[std::size_t(k + half)] > best_norm)
            best_norm = norms[std::size_t(k + half)], best = k;
    const double left = norms[std::size_t(std::max(best - 1 + half, 0))];
    const double right = norms[std::size_t(std::min(best + 1 + half, 2 * half))];
    const double curvature = left - 2.0 * best_norm + right;
    const double shift =
        curvature < 0.0 ? std::clamp(0.5 * (left - right) / curvature, -0.5, 0.5) : 0.0;
    const double t = (best + shift) * dt;
    // e(t*) with the carrier exp(i 2 pi f0 t*) taken out: the phase an echo placed at t = 0
    // with the pulse's carrier must have to match the true echo at its peak.
    const std::complex<double> e =
        baseband(t) *
        std::polar(1.0, 2.0 * std::numbers::pi * (band.first_hz - band.centre_hz) * t);
    out.echo = e;
    return out;
}

LineFields::LineFields(const Transducer& t, LineArray array) : t_(t), array_(std::move(array)) {
    tx_weights_ = aperture_weights(array_, t.active_aperture_mm(), t.tx_apodization);
    double sum2 = 0.0;
    for (double w : tx_weights_) sum2 += w * w;
    tx_norm_ = 1.0 / std::sqrt(t.wavelength_mm() / t.pitch_mm * sum2);
    k_ = 2.0 * std::numbers::pi / t.wavelength_mm();
    element_width_ = t.element_width_mm;
    const std::size_t n = array_.position.size();
    x_.reserve(n), y_.reserve(n), nx_.reserve(n), ny_.reserve(n);
    for (std::size_t e = 0; e < n; ++e) {
        x_.push_back(float(array_.position[e].x)), y_.push_back(float(array_.position[e].y));
        nx_.push_back(float(array_.normal[e].x)), ny_.push_back(float(array_.normal[e].y));
    }
    tx_elements_ = pack(tx_weights_);
    echo_ = line_spectrum(t, BandUse::echo);
    energy_ = line_spectrum(t, BandUse::energy);
}

std::shared_ptr<const LineFields::Spectrum> LineFields::line_spectrum(const Transducer& t,
                                                                      BandUse use) {
    // Kept per band, as pulse_band keeps the bands: every line of a probe shares them.
    const std::shared_ptr<const PulseEcho::Band> band = pulse_band(t, use);
    static std::mutex mutex;
    static std::vector<std::shared_ptr<const Spectrum>> kept;
    const std::lock_guard<std::mutex> lock(mutex);
    for (const auto& spectrum : kept)
        if (spectrum->band == band) return spectrum;
    auto spectrum = std::make_shared<Spectrum>();
    spectrum->band = band;
    const PulseEcho::Band& b = *band;
    for (int m = 0; m < b.count(); ++m)
        spectrum->inverse_ratio.push_back(float(b.centre_hz / b.frequency_hz(m)));
    for (const float inverse : spectrum->inverse_ratio)
        spectrum->root_ratio.push_back(std::sqrt(1.0 / double(inverse)));
    spectrum->centre = int(std::lround((b.centre_hz - b.first_hz) / b.step_hz));
    kept.push_back(spectrum);
    if (kept.size() > 16) kept.erase(kept.begin());
    return spectrum;
}

namespace {

using kernels::kLanes;
using kernels::Lanes;
using kernels::load;
using kernels::phasors;
using kernels::spectrum_terms;
using kernels::SpectrumTerms;
// At most this many frequencies per pass (the sums' accumulators live on the stack).
constexpr int kMaxFrequencies = 64;

// An element of width w seen at angle theta from its normal: sinc(pi w sin theta /
// lambda) cos theta, 0 behind it. The sinc as sin(2 pi u) / (2 pi u) at u = (w / 2 lambda)
// |sin theta| + 1e-9 (even, and defined at 0 without a branch: loops over it vectorise).
inline float directivity(float sin_theta, float cos_theta, float half_width_in_lambdas) {
    const float u = half_width_in_lambdas * std::abs(sin_theta) + 1e-9f;
    float s, c;
    base::sincos_turns(u, s, c);
    return s / (6.28318531f * u) * std::max(cos_theta, 0.0f);
}

// The terms of a field sum (LineFields::sum), element by element: re + i im =
// w D exp(-i 2 pi path / lambda) / sqrt(r). Float and branch-free (an element behind q
// gets D = 0) so that the loop vectorises; built for AVX2 and the baseline, with no FMA
// in either, so both give the same numbers.
[[gnu::target_clones("avx2", "default")]] void field_terms(
    std::size_t n, const float* __restrict x, const float* __restrict y, const float* __restrict nx,
    const float* __restrict ny, const float* __restrict weight, float qx, float qy, float fx,
    float fy, float inverse_lambda, float half_width, float* __restrict re, float* __restrict im) {
    for (std::size_t e = 0; e < n; ++e) {
        const float dx = qx - x[e], dy = qy - y[e];
        const float r = std::max(std::sqrt(dx * dx + dy * dy), 1e-6f), inverse = 1.0f / r;
        const float cos_theta = (dx * nx[e] + dy * ny[e]) * inverse;
        const float sin_theta = (dx * ny[e] - dy * nx[e]) * inverse;
        float s, c;
        const float gain = weight[e] *
                           directivity(sin_theta, cos_theta, half_width * inverse_lambda) /
                           std::sqrt(r);
        const float fdx = fx - x[e], fdy = fy - y[e];
        const float path = r - std::sqrt(fdx * fdx + fdy * fdy) + fy - qy;
        base::sincos_turns(path * inverse_lambda, s, c);
        re[e] = gain * c, im[e] = -gain * s;  // exp(-i k path)
    }
}

// The sums of spectrum_terms' elements at each frequency m: sum_e gain sinc p, with the
// phasors stepped from one frequency to the next; eight elements at a time, their partial
// sums added in double in a fixed order at the end (n a multiple of 8).
[[gnu::target_clones("avx2", "default")]] void spectrum_sums(std::size_t n, int frequencies,
                                                             const float* __restrict inverse_ratio,
                                                             const SpectrumTerms& t,
                                                             std::complex<double>* out) {
    Lanes re[kMaxFrequencies] = {}, im[kMaxFrequencies] = {};
    for (std::size_t e = 0; e < n; e += kLanes) {
        kernels::SpectrumLanes s(t, e);
        for (int m = 0; m < frequencies; ++m, s.next()) {
            Lanes g;
            s.amplitude(inverse_ratio[m], g);
            re[m] += g * s.p_re, im[m] += g * s.p_im;
        }
    }
    for (int m = 0; m < frequencies; ++m) {
        double sum_re = 0.0, sum_im = 0.0;
        for (std::size_t k = 0; k < kLanes; ++k) sum_re += re[m][k], sum_im += im[m][k];
        out[m] = {sum_re, sum_im};
    }
}

}  // namespace

LineFields::Elements LineFields::pack(const std::vector<double>& weights) const {
    std::size_t first = 0, last = weights.size();
    while (first < last && weights[first] == 0.0) ++first;
    while (last > first && weights[last - 1] == 0.0) --last;
    const std::size_t n = last - first, padded = (n + kLanes - 1) / kLanes * kLanes;
    Elements p;
    p.w.assign(padded, 0.0f), p.x.assign(padded, 0.0f), p.y.assign(padded, 1.0f);
    p.nx.assign(padded, 0.0f), p.ny.assign(padded, 1.0f);
    for (std::size_t e = 0; e < n; ++e) {
        p.w[e] = float(weights[first + e]);
        p.x[e] = x_[first + e], p.y[e] = y_[first + e];
        p.nx[e] = nx_[first + e], p.ny[e] = ny_[first + e];
    }
    return p;
}

void LineFields::sum_spectrum(const glm::dvec2& q, const Elements& elements,
                              const glm::dvec2& focus, const Spectrum& spectrum,
                              std::complex<double>* out) const {
    const PulseEcho::Band& band = *spectrum.band;
    const std::size_t padded = elements.w.size();
    const Elements& p = elements;
    thread_local std::vector<float> scratch;  // per thread
    scratch.resize(12 * padded);
    float* base = scratch.data();
    const SpectrumTerms terms{base,
                              base + padded,
                              base + 2 * padded,
                              base + 3 * padded,
                              base + 4 * padded,
                              base + 5 * padded,
                              base + 6 * padded,
                              base + 7 * padded,
                              base + 8 * padded,
                              base + 9 * padded,
                              base + 10 * padded,
                              base + 11 * padded};
    const double f0 = band.centre_hz;
    // In chunks of at most kMaxFrequencies (a long-skirted band of a long pulse has more).
    for (int m0 = 0; m0 < band.count(); m0 += kMaxFrequencies) {
        spectrum_terms(padded, p.x.data(), p.y.data(), p.nx.data(), p.ny.data(), p.w.data(),
                       float(q.x), float(q.y), float(focus.x), float(focus.y),
                       float(1.0 / t_.wavelength_mm()), float(0.5 * element_width_),
                       float(band.frequency_hz(m0) / f0), float(band.step_hz / f0), terms);
        spectrum_sums(padded, std::min(kMaxFrequencies, band.count() - m0),
                      spectrum.inverse_ratio.data() + m0, terms, out + m0);
    }
}

double LineFields::two_way_spectrum(const glm::dvec2& q, const Receive& aperture,
                                    const Spectrum& spectrum, std::complex<double>* out) const {
    const PulseEcho::Band& band = *spectrum.band;
    const int M = band.count();
    thread_local std::vector<std::complex<double>> rx;
    rx.resize(std::size_t(M));
    sum_spectrum(q, tx_elements_, {0.0, t_.focus_mm}, spectrum, out);
    sum_spectrum(q, aperture.elements, {0.0, aperture.focus_mm}, spectrum, rx.data());
    double receive_energy = 0.0;
    for (int m = 0; m < M; ++m) {
        const double ratio = 1.0 / double(spectrum.inverse_ratio[std::size_t(m)]);
        const std::complex<double> r = aperture.norm * std::sqrt(ratio) * rx[std::size_t(m)];
        out[m] *= tx_norm_ * std::sqrt(ratio) * r;
        receive_energy += std::norm(band.weight[std::size_t(m)] * r);
    }
    return receive_energy / band.power;
}

LineFields::Broadband LineFields::broadband(const glm::dvec2& q, const Receive& aperture) const {
    thread_local std::vector<std::complex<double>> h;
    h.resize(std::size_t(echo_->band->count()));
    Broadband b;
    b.receive_power = two_way_spectrum(q, aperture, *echo_, h.data());
    b.two_way = broadband_echo(*echo_->band, h.data());
    return b;
}

LineFields::Speckle LineFields::speckle(const glm::dvec2& q, const Receive& aperture) const {
    const int M = energy_->band->count();
    thread_local std::vector<std::complex<double>> tx, rx;
    tx.resize(std::size_t(M)), rx.resize(std::size_t(M));
    sum_spectrum(q, tx_elements_, {0.0, t_.focus_mm}, *energy_, tx.data());
    sum_spectrum(q, aperture.elements, {0.0, aperture.focus_mm}, *energy_, rx.data());
    return speckle_of_sums(tx.data(), rx.data(), tx_norm_, aperture.norm);
}

LineFields::Speckle LineFields::speckle_of_sums(const std::complex<double>* transmit_sums,
                                                const std::complex<double>* receive_sums,
                                                double transmit_norm, double receive_norm) const {
    // In real arithmetic: the table's rows ask here for every sample of every aperture.
    const PulseEcho::Band& band = *energy_->band;
    Speckle s;
    double centre_re = 0.0, centre_im = 0.0;
    for (int m = 0; m < band.count(); ++m) {
        // Each field normalised at f_m: the norms scale as sqrt(f_m / f0).
        const double root = energy_->root_ratio[std::size_t(m)];
        const double w2 = std::norm(band.weight[std::size_t(m)]);
        const double rn = receive_norm * root, tn = transmit_norm * root;
        const double r_re = rn * receive_sums[m].real(), r_im = rn * receive_sums[m].imag();
        const double t_re = tn * transmit_sums[m].real(), t_im = tn * transmit_sums[m].imag();
        const double h_re = t_re * r_re - t_im * r_im, h_im = t_re * r_im + t_im * r_re;
        s.receive_power += w2 * (r_re * r_re + r_im * r_im);
        s.power += w2 * (h_re * h_re + h_im * h_im);
        if (m == energy_->centre) centre_re = h_re, centre_im = h_im;
    }
    s.receive_power /= band.power;
    s.power /= band.power;
    const double magnitude = std::sqrt(centre_re * centre_re + centre_im * centre_im);
    s.weight = magnitude > 0.0
                   ? std::sqrt(s.power) / magnitude * std::complex<double>(centre_re, centre_im)
                   : std::complex<double>(std::sqrt(s.power), 0.0);
    return s;
}

std::complex<double> LineFields::sum(const glm::dvec2& q, const std::vector<double>& weights,
                                     const glm::dvec2& focus) const {
    // An aperture narrower than the array (F-number, the dynamic receive's growth) leaves
    // zero weights at its ends, whose terms are +-0 and change no sum: the span between
    // them is all that is summed. The PSF table's build was half these sums, over every
    // element. Scratch per thread: a call per table sample allocated three vectors.
    std::size_t first = 0, last = weights.size();
    while (first < last && weights[first] == 0.0) ++first;
    while (last > first && weights[last - 1] == 0.0) --last;
    const std::size_t n = last - first;
    thread_local std::vector<float> w, re, im;
    w.resize(n), re.resize(n), im.resize(n);
    for (std::size_t e = 0; e < n; ++e) w[e] = float(weights[first + e]);
    field_terms(n, x_.data() + first, y_.data() + first, nx_.data() + first, ny_.data() + first,
                w.data(), float(q.x), float(q.y), float(focus.x), float(focus.y),
                float(1.0 / t_.wavelength_mm()), float(0.5 * element_width_), re.data(), im.data());
    double sum_re = 0.0, sum_im = 0.0;  // in order, in double: the same on every build
    for (std::size_t e = 0; e < n; ++e) sum_re += re[e], sum_im += im[e];
    return {sum_re, sum_im};
}

std::complex<double> LineFields::transmit(const glm::dvec2& q) const {
    return tx_norm_ * sum(q, tx_weights_, {0.0, t_.focus_mm});
}

LineFields::Receive LineFields::receive_weights(double focus_mm) const {
    Receive r;
    r.focus_mm = focus_mm;
    r.weights = aperture_weights(array_, t_.receive_aperture_mm(focus_mm), t_.rx_apodization);
    double sum2 = 0.0;
    for (double v : r.weights) sum2 += v * v;
    r.norm = 1.0 / std::sqrt(t_.wavelength_mm() / t_.pitch_mm * sum2);
    return r;
}

LineFields::Receive LineFields::receive_aperture(double focus_mm) const {
    Receive r = receive_weights(focus_mm);
    r.elements = pack(r.weights);
    return r;
}

std::complex<double> LineFields::receive(const glm::dvec2& q, const Receive& aperture) const {
    return aperture.norm * sum(q, aperture.weights, {0.0, aperture.focus_mm});
}

namespace {

// The receive elements of a plane echo (LineFields::plane_echo), in float arrays relative
// to the plane's point.
struct ReceiveElements {
    const float *x, *y, *nx, *ny, *image_x, *image_y, *weight, *delay;
};

// What image_source_terms (below) fills.
struct PairTerms {
    float *gain, *inverse_u, *p_re, *p_im, *ps_re, *ps_im;
    float *de_re, *de_im, *des_re, *des_im, *dr_re, *dr_im, *drs_re, *drs_im;
    float *turns, *u_e, *u_r;  // scratch: the phase in wavelengths at f0, the sincs' arguments
};

[[gnu::target_clones("avx2", "default")]] void image_source_geometry(
    const ReceiveElements& rx, std::size_t n, float ex, float ey, float px, float py, float enx,
    float eny, float mx, float my, float inverse_lambda, float half_width, float offset,
    float* __restrict gain, float* __restrict inverse_u, float* __restrict turns,
    float* __restrict u_e, float* __restrict u_r) {
    const float* __restrict rx_x = rx.x;
    const float* __restrict rx_y = rx.y;
    const float* __restrict rx_nx = rx.nx;
    const float* __restrict rx_ny = rx.ny;
    const float* __restrict image_x = rx.image_x;
    const float* __restrict image_y = rx.image_y;
    const float* __restrict weight = rx.weight;
    const float* __restrict delay = rx.delay;
    const float half_width_in_lambdas = half_width * inverse_lambda;
    for (std::size_t r = 0; r < n; ++r) {
        // Mirrored path e' -> r; the same length from e to r's mirror image.
        const float dx = rx_x[r] - ex, dy = rx_y[r] - ey;
        const float length = std::sqrt(dx * dx + dy * dy), inverse = 1.0f / length;
        // Arrival at r from e' and departure from e towards r', against each normal.
        const float cos_r = -(dx * rx_nx[r] + dy * rx_ny[r]) * inverse;
        const float sin_r = (dx * rx_ny[r] - dy * rx_nx[r]) * inverse;
        const float ux = image_x[r] - px, uy = image_y[r] - py;
        const float cos_e = (ux * enx + uy * eny) * inverse;
        const float sin_e = (ux * eny - uy * enx) * inverse;
        const float cos_beta = std::max(std::abs(dx * mx + dy * my) * inverse, 0.05f);
        u_e[r] = half_width_in_lambdas * std::abs(sin_e) + 1e-9f;
        u_r[r] = half_width_in_lambdas * std::abs(sin_r) + 1e-9f;
        gain[r] = weight[r] * std::max(cos_e, 0.0f) * std::max(cos_r, 0.0f) /
                  (std::sqrt(length) * cos_beta);
        inverse_u[r] = 1.0f / (39.4784176f * u_e[r] * u_r[r]);
        turns[r] = length * inverse_lambda - delay[r] * inverse_lambda - offset;
    }
}

// One transmit element's terms over the receive elements, for their spectrum: the gain
// w_r / (sqrt(L) cos beta) cos(theta_e)+ cos(theta_r)+ without the sincs, 1 / (4 pi^2
// u_e u_r) of their arguments at f0, and the phasors at the band's first frequency and
// of one step: exp(-i 2 pi phase f / f0) for the phase (L - delay_r) / lambda - offset
// in wavelengths at f0, and exp(i 2 pi u f / f0) for each sinc's numerator.
void image_source_terms(const ReceiveElements& rx, std::size_t n, float ex, float ey, float px,
                        float py, float enx, float eny, float mx, float my, float inverse_lambda,
                        float half_width, float offset, float first_ratio, float step_ratio,
                        const PairTerms& out) {
    image_source_geometry(rx, n, ex, ey, px, py, enx, eny, mx, my, inverse_lambda, half_width,
                          offset, out.gain, out.inverse_u, out.turns, out.u_e, out.u_r);
    phasors(n, out.turns, first_ratio, -1.0f, out.p_re, out.p_im);
    phasors(n, out.turns, step_ratio, -1.0f, out.ps_re, out.ps_im);
    phasors(n, out.u_e, first_ratio, 1.0f, out.de_re, out.de_im);
    phasors(n, out.u_e, step_ratio, 1.0f, out.des_re, out.des_im);
    phasors(n, out.u_r, first_ratio, 1.0f, out.dr_re, out.dr_im);
    phasors(n, out.u_r, step_ratio, 1.0f, out.drs_re, out.drs_im);
}

// image_source_terms' sums at each frequency m, added to out[m] times the transmit
// weight, the phasors stepped from one frequency to the next (as spectrum_sums).
[[gnu::target_clones("avx2", "default")]] void image_source_sums(
    std::size_t n, int frequencies, const float* __restrict inverse_ratio, const PairTerms& t,
    double tx_weight, std::complex<double>* out) {
    Lanes re[kMaxFrequencies] = {}, im[kMaxFrequencies] = {};
    for (std::size_t e = 0; e < n; e += kLanes) {
        Lanes gain, inverse_u, p_re, p_im, ps_re, ps_im, de_re, de_im, des_re, des_im;
        Lanes dr_re, dr_im, drs_re, drs_im;
        load(gain, t.gain + e), load(inverse_u, t.inverse_u + e);
        load(p_re, t.p_re + e), load(p_im, t.p_im + e);
        load(ps_re, t.ps_re + e), load(ps_im, t.ps_im + e);
        load(de_re, t.de_re + e), load(de_im, t.de_im + e);
        load(des_re, t.des_re + e), load(des_im, t.des_im + e);
        load(dr_re, t.dr_re + e), load(dr_im, t.dr_im + e);
        load(drs_re, t.drs_re + e), load(drs_im, t.drs_im + e);
        gain *= inverse_u;
        for (int m = 0; m < frequencies; ++m) {
            const Lanes g = gain * de_im * dr_im * (inverse_ratio[m] * inverse_ratio[m]);
            re[m] += g * p_re, im[m] += g * p_im;
            const Lanes pr = p_re * ps_re - p_im * ps_im;
            p_im = p_re * ps_im + p_im * ps_re, p_re = pr;
            const Lanes er = de_re * des_re - de_im * des_im;
            de_im = de_re * des_im + de_im * des_re, de_re = er;
            const Lanes rr = dr_re * drs_re - dr_im * drs_im;
            dr_im = dr_re * drs_im + dr_im * drs_re, dr_re = rr;
        }
    }
    for (int m = 0; m < frequencies; ++m) {
        double sum_re = 0.0, sum_im = 0.0;
        for (std::size_t k = 0; k < kLanes; ++k) sum_re += re[m][k], sum_im += im[m][k];
        out[m] += tx_weight * std::complex<double>(sum_re, sum_im);
    }
}

}  // namespace

std::complex<double> LineFields::plane_echo(double z, double sin_tilt) const {
    const Receive aperture = receive_aperture(z);
    sin_tilt = std::clamp(sin_tilt, -1.0, 1.0);
    const glm::dvec2 m(sin_tilt, std::sqrt(1.0 - sin_tilt * sin_tilt)), c(0.0, z);
    auto mirror = [&](const glm::dvec2& p) { return p - 2.0 * glm::dot(p - c, m) * m; };
    // Receive elements in float arrays (positions relative to the plane's point c, so
    // that float keeps a ~1e-6 mm path resolution), the inner loop over them vectorises.
    const double lambda = t_.wavelength_mm();
    std::vector<float> rx_x, rx_y, rx_nx, rx_ny, image_x, image_y, weight, delay;
    for (std::size_t r = 0; r < aperture.weights.size(); ++r) {
        if (aperture.weights[r] == 0.0) continue;
        const glm::dvec2 p = array_.position[r];
        const glm::dvec2 image = mirror(p);
        rx_x.push_back(float(p.x - c.x)), rx_y.push_back(float(p.y - c.y));
        rx_nx.push_back(float(array_.normal[r].x)), rx_ny.push_back(float(array_.normal[r].y));
        image_x.push_back(float(image.x - c.x)), image_y.push_back(float(image.y - c.y));
        weight.push_back(float(aperture.weights[r]));
        delay.push_back(float(glm::length(c - p) - z));  // dynamic receive focus at z
    }
    // Padded to whole lanes: the padding has no weight.
    const std::size_t n = weight.size(), padded = (n + kLanes - 1) / kLanes * kLanes;
    for (auto* v : {&rx_x, &rx_y, &rx_nx, &image_x, &image_y, &weight, &delay})
        v->resize(padded, 0.0f);
    rx_ny.resize(padded, 1.0f);
    const ReceiveElements rx{rx_x.data(),    rx_y.data(),    rx_nx.data(),  rx_ny.data(),
                             image_x.data(), image_y.data(), weight.data(), delay.data()};
    const float inverse_lambda = float(1.0 / lambda), half_width = float(0.5 * element_width_);
    const float mx = float(m.x), my = float(m.y);
    const PulseEcho::Band& band = *echo_->band;
    const int M = band.count();
    const double f0 = band.centre_hz;
    std::vector<std::complex<double>> total(std::size_t(M), 0.0);
    std::vector<float> scratch(17 * padded);
    float* b = scratch.data();
    const PairTerms terms{b,
                          b + padded,
                          b + 2 * padded,
                          b + 3 * padded,
                          b + 4 * padded,
                          b + 5 * padded,
                          b + 6 * padded,
                          b + 7 * padded,
                          b + 8 * padded,
                          b + 9 * padded,
                          b + 10 * padded,
                          b + 11 * padded,
                          b + 12 * padded,
                          b + 13 * padded,
                          b + 14 * padded,
                          b + 15 * padded,
                          b + 16 * padded};
    for (std::size_t e = 0; e < tx_weights_.size(); ++e) {
        if (tx_weights_[e] == 0.0) continue;
        const glm::dvec2 p = array_.position[e];
        const glm::dvec2 image = mirror(p) - c, from = p - c;
        const float ex = float(image.x), ey = float(image.y), px = float(from.x),
                    py = float(from.y);
        const float enx = float(array_.normal[e].x), eny = float(array_.normal[e].y);
        // Transmit delay and the reference 2z, in wavelengths.
        const float offset =
            float((glm::length(glm::dvec2(0.0, t_.focus_mm) - p) - t_.focus_mm + 2.0 * z) / lambda);
        for (int m0 = 0; m0 < M; m0 += kMaxFrequencies) {  // as sum_spectrum
            image_source_terms(rx, padded, ex, ey, px, py, enx, eny, mx, my, inverse_lambda,
                               half_width, offset, float(band.frequency_hz(m0) / f0),
                               float(band.step_hz / f0), terms);
            image_source_sums(padded, std::min(kMaxFrequencies, M - m0),
                              echo_->inverse_ratio.data() + m0, terms, tx_weights_[e],
                              total.data() + m0);
        }
    }
    // Normalised at each f_m: the norms scale as sqrt(f_m / f0) each, sqrt(lambda) as
    // 1 / sqrt(f_m / f0).
    const std::complex<double> scale =
        tx_norm_ * aperture.norm * std::sqrt(lambda) * std::polar(1.0, -0.25 * std::numbers::pi);
    for (int k = 0; k < M; ++k)
        total[std::size_t(k)] *= scale / std::sqrt(double(echo_->inverse_ratio[std::size_t(k)]));
    return broadband_echo(band, total.data()).echo;
}

}  // namespace sonotrace::probe
