#pragma once
// Elementary functions in plain float and int32 arithmetic, so that loops over them
// vectorise (libm's calls and std::floor do not without -ffast-math or
// -fno-trapping-math). Same numbers whichever instruction set runs them: no FMA.
#include <algorithm>
#include <bit>
#include <cstdint>

namespace sonotrace::tissue {

// floor(x) as an integer, by truncation and a correction; |x| < 2^31.
inline int32_t floor_to_int(float x) {
    const int32_t t = int32_t(x);
    return t - int32_t(x < float(t));
}

// ceil(x) as an integer; |x| < 2^31.
inline int32_t ceil_to_int(float x) {
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

}  // namespace sonotrace::tissue
