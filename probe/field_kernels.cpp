#include "probe/field_kernels.h"

#include <algorithm>
#include <cmath>

#include "tissue/base/fast_math.h"

namespace sonotrace::probe::kernels {

namespace {
[[gnu::target_clones("avx2", "default")]] void spectrum_geometry(
    std::size_t n, const float* __restrict x, const float* __restrict y, const float* __restrict nx,
    const float* __restrict ny, const float* __restrict weight, float qx, float qy, float fx,
    float fy, float inverse_lambda, float half_width, float* __restrict gain,
    float* __restrict inverse_u, float* __restrict turns, float* __restrict u) {
    for (std::size_t e = 0; e < n; ++e) {
        const float dx = qx - x[e], dy = qy - y[e];
        const float r = std::max(std::sqrt(dx * dx + dy * dy), 1e-6f), inverse = 1.0f / r;
        const float cos_theta = (dx * nx[e] + dy * ny[e]) * inverse;
        const float sin_theta = (dx * ny[e] - dy * nx[e]) * inverse;
        u[e] = half_width * inverse_lambda * std::abs(sin_theta) + 1e-9f;
        gain[e] = weight[e] * std::max(cos_theta, 0.0f) / std::sqrt(r);
        inverse_u[e] = 1.0f / (6.28318531f * u[e]);
        const float fdx = fx - x[e], fdy = fy - y[e];
        turns[e] = (r - std::sqrt(fdx * fdx + fdy * fdy) + fy - qy) * inverse_lambda;
    }
}

}  // namespace

[[gnu::target_clones("avx2", "default")]] void phasors(std::size_t n, const float* __restrict a,
                                                       float ratio, float sign,
                                                       float* __restrict re, float* __restrict im) {
    for (std::size_t e = 0; e < n; ++e) {
        float s, c;
        base::sincos_turns(a[e] * ratio, s, c);
        re[e] = c, im[e] = sign * s;
    }
}

void spectrum_terms(std::size_t n, const float* x, const float* y, const float* nx, const float* ny,
                    const float* weight, float qx, float qy, float fx, float fy,
                    float inverse_lambda, float half_width, float first_ratio, float step_ratio,
                    const SpectrumTerms& out) {
    spectrum_geometry(n, x, y, nx, ny, weight, qx, qy, fx, fy, inverse_lambda, half_width, out.gain,
                      out.inverse_u, out.turns, out.u);
    phasors(n, out.turns, first_ratio, -1.0f, out.p_re, out.p_im);  // exp(-i k path)
    phasors(n, out.turns, step_ratio, -1.0f, out.ps_re, out.ps_im);
    phasors(n, out.u, first_ratio, 1.0f, out.d_re, out.d_im);
    phasors(n, out.u, step_ratio, 1.0f, out.ds_re, out.ds_im);
}

}  // namespace sonotrace::probe::kernels
