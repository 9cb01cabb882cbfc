#include "probe/aperture_terms.h"

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
        Lanes gain, inverse_u, p_re, p_im, ps_re, ps_im, d_re, d_im, ds_re, ds_im;
        load(gain, t.gain + e), load(inverse_u, t.inverse_u + e);
        load(p_re, t.p_re + e), load(p_im, t.p_im + e);
        load(ps_re, t.ps_re + e), load(ps_im, t.ps_im + e);
        load(d_re, t.d_re + e), load(d_im, t.d_im + e);
        load(ds_re, t.ds_re + e), load(ds_im, t.ds_im + e);
        gain *= inverse_u;
        for (int m = 0; m < frequencies; ++m) {
            const std::size_t at = std::size_t(m) * stride + e;
            const Lanes g = gain * d_im * inverse_ratio[m];
            const Lanes b_re = g * p_re, b_im = g * p_im;
            Lanes f_re, f_im;
            load(f_re, tx_re + at), load(f_im, tx_im + at);
            store(out[0] + at, b_re * f_re - b_im * f_im);
            store(out[1] + at, b_re * f_im + b_im * f_re);
            load(f_re, rx_re + at), load(f_im, rx_im + at);
            store(out[2] + at, b_re * f_re - b_im * f_im);
            store(out[3] + at, b_re * f_im + b_im * f_re);
            const Lanes pr = p_re * ps_re - p_im * ps_im;
            p_im = p_re * ps_im + p_im * ps_re, p_re = pr;
            const Lanes dr = d_re * ds_re - d_im * ds_im;
            d_im = d_re * ds_im + d_im * ds_re, d_re = dr;
        }
    }
}

// out[m] = sum_e w_e (re + i im)[m * stride + e] over n elements (a multiple of eight),
// eight at a time, the partial sums added in double in a fixed order.
[[gnu::target_clones("avx2", "default")]] void weighted_sums(
    std::size_t n, int frequencies, std::size_t stride, const float* __restrict w,
    const float* __restrict re, const float* __restrict im, std::complex<double>* out) {
    for (int m = 0; m < frequencies; ++m) {
        Lanes sum_re = {}, sum_im = {};
        for (std::size_t e = 0; e < n; e += kLanes) {
            Lanes weight, a, b;
            load(weight, w + e), load(a, re + std::size_t(m) * stride + e);
            load(b, im + std::size_t(m) * stride + e);
            sum_re += weight * a, sum_im += weight * b;
        }
        double total_re = 0.0, total_im = 0.0;
        for (std::size_t k = 0; k < kLanes; ++k) total_re += sum_re[k], total_im += sum_im[k];
        out[m] = {total_re, total_im};
    }
}

}  // namespace

ApertureTerms::ApertureTerms(const LineFields& fields, int first, int last, double receive_focus_mm)
    : fields_(fields), first_(first), count_(last - first) {
    const LineFields::Spectrum& spectrum = fields.energy_;
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
            turns[e] = float((std::hypot(px, py) - std::hypot(px, focus_mm - py) + focus_mm) *
                             inverse_lambda);
        }
        re.resize(std::size_t(frequencies_) * n), im.resize(re.size());
        for (int m = 0; m < frequencies_; ++m)
            kernels::phasors(n, turns.data(), float(band.frequency_hz(m) / band.centre_hz), -1.0f,
                             re.data() + std::size_t(m) * n, im.data() + std::size_t(m) * n);
    };
    focusing(fields.t_.focus_mm, tx_re_, tx_im_);
    focusing(receive_focus_mm, rx_re_, rx_im_);
    for (auto& terms : terms_) terms.resize(tx_re_.size());
    tx_sums_.resize(std::size_t(frequencies_)), rx_sums_.resize(std::size_t(frequencies_));
}

ApertureTerms::Aperture ApertureTerms::aperture(const std::vector<double>& weights,
                                                double norm) const {
    int a = 0, b = int(weights.size());
    while (a < b && weights[std::size_t(a)] == 0.0) ++a;
    while (b > a && weights[std::size_t(b) - 1] == 0.0) --b;
    if (a < first_ || b > first_ + count_)
        throw std::logic_error("ApertureTerms: an aperture beyond the terms' elements");
    Aperture out;
    out.first = a - first_;
    out.norm = norm;
    out.w.assign(kernels::padded(std::size_t(b - a)), 0.0f);
    for (int e = a; e < b; ++e) out.w[std::size_t(e - a)] = float(weights[std::size_t(e)]);
    return out;
}

void ApertureTerms::at(const glm::dvec2& q) {
    const auto n = std::size_t(stride_);
    thread_local std::vector<float> scratch;
    scratch.resize(12 * n);
    float* s = scratch.data();
    const kernels::SpectrumTerms terms{s,         s + n,     s + 2 * n,  s + 3 * n,
                                       s + 4 * n, s + 5 * n, s + 6 * n,  s + 7 * n,
                                       s + 8 * n, s + 9 * n, s + 10 * n, s + 11 * n};
    const LineFields::Spectrum& spectrum = fields_.energy_;
    const PulseEcho::Band& band = *spectrum.band;
    // The path |q - p_e| - |p_e| - q_y: LineFields::sum's with the focus at the origin.
    kernels::spectrum_terms(
        n, x_.data(), y_.data(), nx_.data(), ny_.data(), ones_.data(), float(q.x), float(q.y), 0.0f,
        0.0f, float(1.0 / fields_.t_.wavelength_mm()), float(0.5 * fields_.element_width_),
        float(band.frequency_hz(0) / band.centre_hz), float(band.step_hz / band.centre_hz), terms);
    float* const out[4] = {terms_[0].data(), terms_[1].data(), terms_[2].data(), terms_[3].data()};
    focused_terms(n, frequencies_, n, spectrum.inverse_ratio.data(), terms, tx_re_.data(),
                  tx_im_.data(), rx_re_.data(), rx_im_.data(), out);
}

LineFields::Speckle ApertureTerms::speckle(const Aperture& transmit,
                                           const Aperture& receive) const {
    const auto n = std::size_t(stride_);
    weighted_sums(transmit.w.size(), frequencies_, n, transmit.w.data(),
                  terms_[0].data() + transmit.first, terms_[1].data() + transmit.first,
                  tx_sums_.data());
    weighted_sums(receive.w.size(), frequencies_, n, receive.w.data(),
                  terms_[2].data() + receive.first, terms_[3].data() + receive.first,
                  rx_sums_.data());
    return fields_.speckle_of_sums(tx_sums_.data(), rx_sums_.data(), transmit.norm, receive.norm);
}

}  // namespace sonotrace::probe
