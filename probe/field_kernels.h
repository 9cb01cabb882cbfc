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

}  // namespace sonotrace::probe::kernels
