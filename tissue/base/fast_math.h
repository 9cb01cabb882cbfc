#pragma once
// Elementary functions in plain float and int32 arithmetic, so that loops over them
// vectorise (libm's calls do not; the project builds with -fno-trapping-math, without
// which float selects such as the clamps below block vectorisation too). Same numbers
// whichever instruction set runs them: no FMA.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <type_traits>

namespace sonotrace::base {

// A Gaussian's full width at half maximum over its sigma: 2 sqrt(2 ln 2).
inline constexpr double kFwhmPerSigma = 2.3548200450309493;

// floor(x) as an integer, by truncation and a correction; |x| < 2^31.
template <typename Real>
inline int32_t floor_to_int(Real x) {
    static_assert(std::is_floating_point_v<Real>);
    const int32_t t = int32_t(x);
    return t - int32_t(x < Real(t));
}

// ceil(x) as an integer; |x| < 2^31.
template <typename Real>
inline int32_t ceil_to_int(Real x) {
    return -floor_to_int(-x);
}

// 2^k for k in [-126, 127] (a normal float) from the exponent bits, without a call.
inline float power_of_two(int32_t k) {
    return std::bit_cast<float>(uint32_t(k + 127) << 23);
}

// exp(x) in single precision, relative error < 2e-7 on [-87, 88] (clamped outside).
// x = k ln 2 + r with |r| <= ln 2 / 2 (ln 2 in two parts, Cody-Waite, so k ln 2 is
// exact), exp(r) by its Taylor polynomial to r^7 (remainder < 1.1e-8), 2^k from the
// exponent bits.
inline float exp_float(float x) {
    x = std::clamp(x, -87.0f, 88.0f);
    const int32_t k = floor_to_int(x * 1.44269504f + 0.5f);
    const float r = (x - float(k) * 0.693145752f) - float(k) * 1.42860677e-6f;
    float p = 1.0f / 5040.0f;
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    return p * power_of_two(k);
}

// ln(x) in single precision for x > 0: error below 1.2e-7 max(1, |ln x|), about an ulp
// of the result (x below the smallest normal float is taken as it; NaN and inf are not
// handled: callers filter them).
// x = 2^k m with m in [sqrt(1/2), sqrt(2)) from the bits; ln m = 2 atanh(s), s = (m - 1) /
// (m + 1), |s| <= 0.172, by its series to s^9 (remainder < 2e-9); k ln 2 in two parts.
inline float log_float(float x) {
    constexpr uint32_t kSqrtHalf = 0x3f3504f3;  // bits of sqrt(1/2)
    const uint32_t u = std::bit_cast<uint32_t>(std::max(x, 1.17549435e-38f)) - kSqrtHalf;
    const int32_t k = int32_t(u) >> 23;
    const float m = std::bit_cast<float>((u & 0x7fffff) + kSqrtHalf);
    const float f = m - 1.0f;
    const float s = f / (2.0f + f), z = s * s;
    float p = 1.0f / 9.0f;
    p = p * z + 1.0f / 7.0f;
    p = p * z + 1.0f / 5.0f;
    p = p * z + 1.0f / 3.0f;
    const float ln_m = f - s * (f - 2.0f * z * p);  // 2 s (1 + z p) = f - s (f - 2 z p)
    return float(k) * 1.42860677e-6f + ln_m + float(k) * 0.693145752f;
}

// sin and cos of 2 pi t (t in turns, |t| < 2^22), absolute error < 1e-6 beyond the
// 2 pi ulp(t) that t itself carries: t reduced to
// [-1/2, 1/2] by its nearest integer; sin and cos of the half angle y = pi t in
// [-pi/2, pi/2] by their Taylor polynomials to y^11 and y^12 (remainders < 6e-9, 5e-10),
// then the double-angle formulas. No branches: loops over it vectorise.
inline void sincos_turns(float t, float& sine, float& cosine) {
    const float r = t - float(floor_to_int(t + 0.5f));
    const float y = 3.14159265f * r, y2 = y * y;
    float s = -1.0f / 39916800.0f;
    s = s * y2 + 1.0f / 362880.0f;
    s = s * y2 - 1.0f / 5040.0f;
    s = s * y2 + 1.0f / 120.0f;
    s = s * y2 - 1.0f / 6.0f;
    s = (s * y2 + 1.0f) * y;
    float c = 1.0f / 479001600.0f;
    c = c * y2 - 1.0f / 3628800.0f;
    c = c * y2 + 1.0f / 40320.0f;
    c = c * y2 - 1.0f / 720.0f;
    c = c * y2 + 1.0f / 24.0f;
    c = c * y2 - 0.5f;
    c = c * y2 + 1.0f;
    sine = 2.0f * s * c;
    cosine = (c - s) * (c + s);
}

}  // namespace sonotrace::base
