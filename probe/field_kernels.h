#pragma once
// The vectorised element loops the aperture's field sums share (probe/aperture.cpp: one
// aperture at a point; probe/aperture_terms.cpp: many apertures on one array at once).
// Float and branch-free, built for AVX2 and the baseline with no FMA in either, so both
// give the same numbers.
#include <cstddef>
#include <cstring>

namespace sonotrace::probe::kernels {

// Per element, what a field's spectrum needs: the gain w cos(theta)+ / sqrt(r) without
// the sinc, 1 / (2 pi u) of the sinc's argument u at f0, and the phasors at the band's
// first frequency and of one step of it: exp(-i 2 pi path f / c0) for the phase and
// exp(i 2 pi u f / f0) whose imaginary part is the sinc's numerator.
struct SpectrumTerms {
    float *gain, *inverse_u, *p_re, *p_im, *ps_re, *ps_im, *d_re, *d_im, *ds_re, *ds_im;
    float *turns, *u;  // scratch: the path in wavelengths at f0 and the sinc's argument
};

// re + i im = exp(i 2 pi sign a ratio), element by element (a loop of its own: it
// vectorises, as the whole of spectrum_terms' work in one loop did not).
void phasors(std::size_t n, const float* a, float ratio, float sign, float* re, float* im);

// SpectrumTerms of the elements (x, y) with normals (nx, ny) and weights at q, the path
// measured as |q - e| - |f - e| + f_y - q_y (the focusing delays to f, the phase against
// the echo time 2 q_y / c0).
void spectrum_terms(std::size_t n, const float* x, const float* y, const float* nx, const float* ny,
                    const float* weight, float qx, float qy, float fx, float fy,
                    float inverse_lambda, float half_width, float first_ratio, float step_ratio,
                    const SpectrumTerms& out);

// Eight elements side by side (GCC's vector extension: AVX2 registers in the AVX2 clone,
// pairs of SSE ones in the baseline; the same operations, so the same numbers).
constexpr std::size_t kLanes = 8;
using Lanes = float __attribute__((vector_size(kLanes * sizeof(float))));
// Through a reference, not a return value: a 32-byte vector returned without AVX changes
// the ABI (clang refuses it in the baseline clone).
[[gnu::always_inline]] inline void load(Lanes& v, const float* p) {
    std::memcpy(&v, p, sizeof v);
}
[[gnu::always_inline]] inline void store(float* p, const Lanes& v) {
    std::memcpy(p, &v, sizeof v);
}
constexpr std::size_t padded(std::size_t n) {
    return (n + kLanes - 1) / kLanes * kLanes;
}

// Eight elements' SpectrumTerms walked through the band's frequencies: amplitude() is
// gain sinc at the current one (ratio f0 / f_m scales the sinc's 1 / u), p its phasor
// exp(-i k_m path), next() steps both phasors to the following frequency.
struct SpectrumLanes {
    Lanes gain, p_re, p_im, ps_re, ps_im, d_re, d_im, ds_re, ds_im;
    [[gnu::always_inline]] SpectrumLanes(const SpectrumTerms& t, std::size_t e) {
        Lanes inverse_u;
        load(gain, t.gain + e), load(inverse_u, t.inverse_u + e);
        load(p_re, t.p_re + e), load(p_im, t.p_im + e);
        load(ps_re, t.ps_re + e), load(ps_im, t.ps_im + e);
        load(d_re, t.d_re + e), load(d_im, t.d_im + e);
        load(ds_re, t.ds_re + e), load(ds_im, t.ds_im + e);
        gain *= inverse_u;
    }
    [[gnu::always_inline]] void amplitude(float ratio, Lanes& out) const {
        out = gain * d_im * ratio;
    }
    [[gnu::always_inline]] void next() {
        const Lanes pr = p_re * ps_re - p_im * ps_im;
        p_im = p_re * ps_im + p_im * ps_re, p_re = pr;
        const Lanes dr = d_re * ds_re - d_im * ds_im;
        d_im = d_re * ds_im + d_im * ds_re, d_re = dr;
    }
};

}  // namespace sonotrace::probe::kernels
