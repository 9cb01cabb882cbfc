// tissue/fast_math.h against libm: floor and ceil over integers, halves and negatives; exp over
// its whole range within the stated relative error. The half-maximum helper against the
// Gaussian's FWHM.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "tissue/base/fast_math.h"
#include "tissue/base/half_maximum.h"

namespace sonotrace::tissue {
namespace {

TEST(FastMath, FloorAndCeilToIntMatchLibm) {
    for (float x : {-3.0f, -2.5f, -1.0f, -0.75f, -1e-7f, 0.0f, 1e-7f, 0.5f, 1.0f, 2.999f, 1e6f,
                    -1e6f - 0.5f}) {
        EXPECT_EQ(base::floor_to_int(x), int32_t(std::floor(x))) << x;
        EXPECT_EQ(base::ceil_to_int(x), int32_t(std::ceil(x))) << x;
    }
    for (int i = -4000; i <= 4000; ++i) {
        const float x = float(i) * 0.37f;
        ASSERT_EQ(base::floor_to_int(x), int32_t(std::floor(x))) << x;
        ASSERT_EQ(base::ceil_to_int(x), int32_t(std::ceil(x))) << x;
        const double d = double(i) * 0.37 + 1e-12;  // doubles too, just off the integers
        ASSERT_EQ(base::floor_to_int(d), int32_t(std::floor(d))) << d;
        ASSERT_EQ(base::ceil_to_int(d), int32_t(std::ceil(d))) << d;
    }
}

TEST(FastMath, PowerOfTwoMatchesLdexp) {
    for (int k = -126; k <= 127; ++k) EXPECT_EQ(base::power_of_two(k), std::ldexp(1.0f, k)) << k;
}

TEST(FastMath, ExpWithinStatedRelativeError) {
    double worst = 0.0;
    for (int i = 0; i <= 200000; ++i) {
        const float x = -87.0f + 175.0f * float(i) / 200000.0f;
        const double exact = std::exp(double(x));
        worst = std::max(worst, std::abs(double(base::exp_float(x)) - exact) / exact);
    }
    EXPECT_LT(worst, 2e-7);
    EXPECT_EQ(base::exp_float(0.0f), 1.0f);
    // Clamped outside [-87, 88]: finite and positive, no overflow into infinity.
    EXPECT_GT(base::exp_float(-1000.0f), 0.0f);
    EXPECT_TRUE(std::isfinite(base::exp_float(1000.0f)));
}

TEST(FastMath, LogWithinStatedError) {
    // Geometric steps (a factor no power of two divides) over the normal floats, and
    // densely around 1 where ln x -> 0; the error relative to max(1, |ln x|).
    double worst = 0.0;
    auto check = [&](float x) {
        const double exact = std::log(double(x));
        worst = std::max(
            worst, std::abs(double(base::log_float(x)) - exact) / std::max(1.0, std::abs(exact)));
    };
    for (double x = 1.2e-38; x < 3e38; x *= 1.00044) check(float(x));
    for (int i = -10000; i <= 10000; ++i) check(1.0f + float(i) * 3e-5f);
    EXPECT_LT(worst, 1.2e-7);
    EXPECT_EQ(base::log_float(1.0f), 0.0f);
    // Below the normal range: the smallest normal's logarithm, finite.
    EXPECT_NEAR(base::log_float(1e-40f), std::log(1.17549435e-38), 1e-5);
}

TEST(FastMath, SinCosOfTurnsWithinStatedError) {
    // Against libm in double on a grid finer than the polynomials' structure across
    // [-3, 3] turns (both reductions, all quadrants), within 1e-6; far out the error may
    // add the 2 pi ulp(t) of the argument itself.
    double worst = 0.0;
    for (int i = -300000; i <= 300000; ++i) {
        const float t = float(i) * 1e-5f;
        float s = 0.0f, c = 0.0f;
        base::sincos_turns(t, s, c);
        const double x = 2.0 * std::numbers::pi * double(t);
        worst = std::max({worst, std::abs(s - std::sin(x)), std::abs(c - std::cos(x))});
    }
    EXPECT_LT(worst, 1e-6);
    for (float t : {1234.567f, -98765.4f, 3.0e6f}) {
        float s = 0.0f, c = 0.0f;
        base::sincos_turns(t, s, c);
        const double x = 2.0 * std::numbers::pi * double(t);
        const double ulp = std::abs(double(std::nextafter(t, 2.0f * t)) - double(t));
        const double bound = 1e-6 + 2.0 * std::numbers::pi * ulp;
        EXPECT_LT(std::abs(s - std::sin(x)), bound) << t;
        EXPECT_LT(std::abs(c - std::cos(x)), bound) << t;
    }
}

// A Gaussian of sigma s sampled at unit spacing: FWHM 2 sqrt(2 ln 2) s. Linear
// interpolation between samples errs by at most h^2 |f''| / 8 in value, which at the
// half-maximum point (|f''| = 0.0019, slope 0.059 per sample at s = 10) moves
// each crossing by at most 0.004 samples: the width within 0.1 %, the midpoint within
// 0.004, on the grid and off it (centre 50.3). On positions x = 0.25 i the width scales by
// 0.25. A side that stays above half has no crossing.
TEST(HalfMaximum, GaussianWidthFromItsSamples) {
    const double s = 10.0, expected = 2.0 * std::sqrt(2.0 * std::log(2.0)) * s;
    for (const double centre : {50.0, 50.3}) {
        auto g = [&](int i) { return std::exp(-0.5 * (i - centre) * (i - centre) / (s * s)); };
        const int peak = int(std::lround(centre));
        const base::HalfMaximum h = base::half_maximum(101, peak, g);
        EXPECT_NEAR(h.width(), expected, 1e-3 * expected) << centre;
        EXPECT_NEAR(0.5 * (h.left + h.right), centre, 4e-3) << centre;
        const base::HalfMaximum x =
            base::half_maximum_at(101, peak, g, [](int i) { return 0.25 * i; });
        EXPECT_NEAR(x.width(), 0.25 * h.width(), 1e-12) << centre;
    }
    auto edge = [](int i) { return std::exp(-0.01 * i * i); };  // peak at sample 0
    const base::HalfMaximum h = base::half_maximum(50, 0, edge);
    EXPECT_TRUE(std::isnan(h.left));
    EXPECT_NEAR(h.right, std::sqrt(std::log(2.0) / 0.01), 0.05);
}

}  // namespace
}  // namespace sonotrace::tissue
