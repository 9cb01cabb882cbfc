#include "probe/aperture_terms.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "probe/field_kernels.h"

namespace sonotrace::probe {

namespace {

using kernels::kLanes;
using kernels::Lanes;
using kernels::load;
using kernels::store;

// The terms at each frequency m from spectrum_terms' per-element values (as LineFields'
// spectrum sums take them, the phasors stepped from one frequency to the next), times
// the transmit's and the receive's focusing phasors: out[k][m * stride + e], k = transmit
// re, im, receive re, im.
[[gnu::target_clones("avx2", "default")]] void focused_terms(
    std::size_t n, int frequencies, std::size_t stride, const float* __restrict inverse_ratio,
    const kernels::SpectrumTerms& t, const float* __restrict tx_re, const float* __restrict tx_im,
    const float* __restrict rx_re, const float* __restrict rx_im, float* const* out) {
    for (std::size_t e = 0; e < n; e += kLanes) {
        kernels::SpectrumLanes s(t, e);
        for (int m = 0; m < frequencies; ++m, s.next()) {
            const std::size_t at = std::size_t(m) * stride + e;
            Lanes g;
            s.amplitude(inverse_ratio[m], g);
            const Lanes b_re = g * s.p_re, b_im = g * s.p_im;
            Lanes f_re, f_im;
            load(f_re, tx_re + at), load(f_im, tx_im + at);
            store(out[0] + at, b_re * f_re - b_im * f_im);
            store(out[1] + at, b_re * f_im + b_im * f_re);
            load(f_re, rx_re + at), load(f_im, rx_im + at);
            store(out[2] + at, b_re * f_re - b_im * f_im);
            store(out[3] + at, b_re * f_im + b_im * f_re);
        }
    }
}

// r[k] = the sum of v[perm(k)]'s lanes for eight vectors at once (21 operations where
// eight reductions one lane at a time took 56 additions and as many extractions); the
// sums come out in the order a, e, c, g, b, f, d, h of v[0..7].
// (Through a reference: a returned 32-byte vector changes the ABI without AVX.)
// __builtin_shufflevector: GCC 12 and clang both have it (the fuzz build is clang's).
[[gnu::always_inline]] inline void reduce8(const Lanes* v, Lanes& r) {
    Lanes p[4];
    for (int k = 0; k < 4; ++k)
        p[k] = __builtin_shufflevector(v[2 * k], v[2 * k + 1], 0, 1, 2, 3, 8, 9, 10, 11) +
               __builtin_shufflevector(v[2 * k], v[2 * k + 1], 4, 5, 6, 7, 12, 13, 14, 15);
    const Lanes q0 = __builtin_shufflevector(p[0], p[1], 0, 1, 8, 9, 4, 5, 12, 13) +
                     __builtin_shufflevector(p[0], p[1], 2, 3, 10, 11, 6, 7, 14, 15);
    const Lanes q1 = __builtin_shufflevector(p[2], p[3], 0, 1, 8, 9, 4, 5, 12, 13) +
                     __builtin_shufflevector(p[2], p[3], 2, 3, 10, 11, 6, 7, 14, 15);
    r = __builtin_shufflevector(q0, q1, 0, 8, 2, 10, 4, 12, 6, 14) +
        __builtin_shufflevector(q0, q1, 1, 9, 3, 11, 5, 13, 7, 15);
}
// Where reduce8 puts the sum of v[k].
constexpr int kReduced[8] = {0, 4, 2, 6, 1, 5, 3, 7};

// The lanes' sums for R = 3 or 4 frequencies (rows `stride` apart) of sum_e w_e (re + i im),
// eight elements at a time, the weights loaded once for them: sums[2 k], sums[2 k + 1] =
// frequency k's real and imaginary parts (zeros past R). Accumulators by name: an array of
// them was cleared through memory at every call.
template <int R>
[[gnu::always_inline]] inline void weighted_lanes(std::size_t n, std::size_t stride,
                                                  const float* __restrict w,
                                                  const float* __restrict r,
                                                  const float* __restrict i, Lanes* sums) {
    static_assert(R == 3 || R == 4);
    Lanes s0 = {}, s1 = {}, s2 = {}, s3 = {}, s4 = {}, s5 = {}, s6 = {}, s7 = {};
    for (std::size_t e = 0; e < n; e += kLanes) {
        Lanes weight, a, b, c, d, f, g;
        load(weight, w + e);
        load(a, r + e), load(b, i + e), load(c, r + stride + e), load(d, i + stride + e);
        load(f, r + 2 * stride + e), load(g, i + 2 * stride + e);
        s0 += weight * a, s1 += weight * b, s2 += weight * c, s3 += weight * d;
        s4 += weight * f, s5 += weight * g;
        if constexpr (R == 4) {
            Lanes h, k;
            load(h, r + 3 * stride + e), load(k, i + 3 * stride + e);
            s6 += weight * h, s7 += weight * k;
        }
    }
    sums[0] = s0, sums[1] = s1, sums[2] = s2, sums[3] = s3;
    sums[4] = s4, sums[5] = s5, sums[6] = s6, sums[7] = s7;
}

// out[m] = sum_e w_e (re + i im)[m * stride + e] over n elements (a multiple of eight),
// four frequencies at a time (three in a last pass of three; other passes past the last
// frequency read the zero rows after it), the lanes' partial sums added in a fixed order.
[[gnu::target_clones("avx2", "default")]] void weighted_sums(
    std::size_t n, int frequencies, std::size_t stride, const float* __restrict w,
    const float* __restrict re, const float* __restrict im, std::complex<double>* out) {
    for (int m0 = 0; m0 < frequencies; m0 += 4) {
        const float* r = re + std::size_t(m0) * stride;
        const float* i = im + std::size_t(m0) * stride;
        Lanes sums[8];
        if (frequencies - m0 == 3)
            weighted_lanes<3>(n, stride, w, r, i, sums);
        else
            weighted_lanes<4>(n, stride, w, r, i, sums);
        Lanes total;
        reduce8(sums, total);
        for (int m = m0; m < std::min(m0 + 4, frequencies); ++m)
            out[m] = {double(total[kReduced[2 * (m - m0)]]),
                      double(total[kReduced[2 * (m - m0) + 1]])};
    }
}

}  // namespace

ApertureTerms::ApertureTerms(const LineFields& fields, int first, int last, double receive_focus_mm)
    : fields_(fields), first_(first), count_(last - first) {
    const LineFields::Spectrum& spectrum = *fields.energy_;
    frequencies_ = spectrum.band->count();
    // Room for an aperture starting anywhere in the span, padded to whole lanes.
    stride_ = int(kernels::padded(std::size_t(count_)) + kLanes);
    const auto n = std::size_t(stride_);
    // Elements past the span: weightless stand-ins where the sums' padding has them.
    x_.assign(n, 0.0f), y_.assign(n, 1.0f), nx_.assign(n, 0.0f), ny_.assign(n, 1.0f);
    ones_.assign(n, 1.0f);
    for (int e = 0; e < count_; ++e) {
        const auto a = std::size_t(first + e);
        x_[std::size_t(e)] = fields.x_[a], y_[std::size_t(e)] = fields.y_[a];
        nx_[std::size_t(e)] = fields.nx_[a], ny_[std::size_t(e)] = fields.ny_[a];
    }
    // The focusing phasors exp(-i k_m (|p_e| - |f - p_e| + f_y)) at each frequency.
    const double inverse_lambda = 1.0 / fields.t_.wavelength_mm();
    const PulseEcho::Band& band = *spectrum.band;
    std::vector<float> turns(n);
    auto focusing = [&](double focus_mm, std::vector<float>& re, std::vector<float>& im) {
        for (std::size_t e = 0; e < n; ++e) {
            const double px = x_[e], py = y_[e];
            const double fy = focus_mm - py;
            turns[e] =
                float((std::sqrt(px * px + py * py) - std::sqrt(px * px + fy * fy) + focus_mm) *
                      inverse_lambda);
        }
        re.resize(std::size_t(frequencies_) * n), im.resize(re.size());
        for (int m = 0; m < frequencies_; ++m)
            kernels::phasors(n, turns.data(), float(band.frequency_hz(m) / band.centre_hz), -1.0f,
                             re.data() + std::size_t(m) * n, im.data() + std::size_t(m) * n);
    };
    focusing(fields.t_.focus_mm, tx_re_, tx_im_);
    focusing(receive_focus_mm, rx_re_, rx_im_);
    // Zeros past the last frequency, up to a multiple of four (weighted_sums reads them).
    for (auto& terms : terms_) terms.assign(std::size_t((frequencies_ + 3) / 4 * 4) * n, 0.0f);
}

int ApertureTerms::add(std::vector<Aperture>& apertures, const std::vector<double>& weights,
                       double norm) {
    int a = 0, b = int(weights.size());
    while (a < b && weights[std::size_t(a)] == 0.0) ++a;
    while (b > a && weights[std::size_t(b) - 1] == 0.0) --b;
    if (a < first_ || b > first_ + count_)
        throw std::logic_error("ApertureTerms: an aperture beyond the terms' elements");
    // An equal one is found before a new one is made (most apertures of a group are).
    const std::size_t size = kernels::padded(std::size_t(b - a));
    auto equal = [&](const Aperture& x) {
        if (x.first != a - first_ || x.norm != norm || x.w.size() != size) return false;
        for (int e = a; e < b; ++e)
            if (x.w[std::size_t(e - a)] != float(weights[std::size_t(e)])) return false;
        return true;  // the padding is zeros in both
    };
    for (std::size_t k = 0; k < apertures.size(); ++k)
        if (equal(apertures[k])) return int(k);
    Aperture out;
    out.first = a - first_;
    out.norm = norm;
    out.w.assign(size, 0.0f);
    for (int e = a; e < b; ++e) out.w[std::size_t(e - a)] = float(weights[std::size_t(e)]);
    apertures.push_back(std::move(out));
    return int(apertures.size()) - 1;
}

int ApertureTerms::add_transmit(const std::vector<double>& weights, double norm) {
    return add(transmits_, weights, norm);
}

int ApertureTerms::add_receive(const std::vector<double>& weights, double norm) {
    return add(receives_, weights, norm);
}

void ApertureTerms::at(const glm::dvec2& q) {
    // The span's elements, to whole lanes; the terms past them stay the zeros they were
    // made (weighted only by the zero padding of apertures that end there).
    const auto n = kernels::padded(std::size_t(count_));
    thread_local std::vector<float> scratch;
    scratch.resize(12 * n);
    float* s = scratch.data();
    const kernels::SpectrumTerms terms{s,         s + n,     s + 2 * n,  s + 3 * n,
                                       s + 4 * n, s + 5 * n, s + 6 * n,  s + 7 * n,
                                       s + 8 * n, s + 9 * n, s + 10 * n, s + 11 * n};
    const LineFields::Spectrum& spectrum = *fields_.energy_;
    const PulseEcho::Band& band = *spectrum.band;
    // The path |q - p_e| - |p_e| - q_y: LineFields::sum's with the focus at the origin.
    kernels::spectrum_terms(
        n, x_.data(), y_.data(), nx_.data(), ny_.data(), ones_.data(), float(q.x), float(q.y), 0.0f,
        0.0f, float(1.0 / fields_.t_.wavelength_mm()), float(0.5 * fields_.element_width_),
        float(band.frequency_hz(0) / band.centre_hz), float(band.step_hz / band.centre_hz), terms);
    float* const out[4] = {terms_[0].data(), terms_[1].data(), terms_[2].data(), terms_[3].data()};
    focused_terms(n, frequencies_, std::size_t(stride_), spectrum.inverse_ratio.data(), terms,
                  tx_re_.data(), tx_im_.data(), rx_re_.data(), rx_im_.data(), out);
    const auto M = std::size_t(frequencies_);
    for (const int k : {0, 1}) {
        const std::vector<Aperture>& apertures = k == 0 ? transmits_ : receives_;
        sums_[k].resize(apertures.size() * M);
        for (std::size_t a = 0; a < apertures.size(); ++a) {
            const Aperture& each = apertures[a];
            weighted_sums(each.w.size(), frequencies_, std::size_t(stride_), each.w.data(),
                          terms_[2 * k].data() + each.first, terms_[2 * k + 1].data() + each.first,
                          sums_[k].data() + a * M);
        }
    }
}

LineFields::Speckle ApertureTerms::speckle(int transmit, int receive) const {
    const auto M = std::size_t(frequencies_);
    return fields_.speckle_of_sums(
        sums_[0].data() + std::size_t(transmit) * M, sums_[1].data() + std::size_t(receive) * M,
        transmits_[std::size_t(transmit)].norm, receives_[std::size_t(receive)].norm);
}

}  // namespace sonotrace::probe
