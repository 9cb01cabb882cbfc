// Interaction primitives: Snell's law, total reflection, eq. 10 with its limits and
// reciprocity, and chi-square tests of the cos^c lobe samplers in 2D and 3D.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <vector>

#include "simulator/interactions.h"
#include "simulator/rng.h"
#include "tests/test_util.h"

namespace sonotrace::simulator {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

TEST(Refract, SnellHoldsIn2DAnd3D) {
    for (float eta : {0.6f, 0.9f, 1.0f, 1.3f}) {
        for (int a = 0; a < 18; ++a) {
            const float theta = glm::radians(5.0f * a);
            // 2D: normal +y, incoming towards -y.
            const Vec<2> r2(std::sin(theta), -std::cos(theta));
            const auto t2 = refract<2>(r2, Vec<2>(0, 1), eta);
            const float sin_i = std::sin(theta);
            if (eta * sin_i >= 1.0f) {
                EXPECT_TRUE(t2.total_reflection);
                EXPECT_NEAR(t2.direction.y, std::cos(theta), 1e-5f);  // mirrored
                continue;
            }
            EXPECT_FALSE(t2.total_reflection);
            EXPECT_NEAR(t2.direction.x, eta * sin_i, 1e-5f) << "sin(theta_t) = eta sin(theta_i)";
            EXPECT_LT(t2.direction.y, 0.0f);  // still travelling forward
            // 3D, with the normal given in the opposite orientation and a tilted plane of
            // incidence.
            const Vec<3> n3 = glm::normalize(Vec<3>(0.2f, -1.0f, 0.3f));
            Vec<3> b1, b2;
            orthonormal_basis(n3, &b1, &b2);
            const Vec<3> r3 = glm::normalize(std::sin(theta) * b1 + std::cos(theta) * n3);
            const auto t3 = refract<3>(r3, n3, eta);
            const float sin_t = glm::length(glm::cross(t3.direction, n3));
            EXPECT_NEAR(sin_t, eta * sin_i, 1e-5f);
            EXPECT_NEAR(glm::dot(glm::cross(r3, n3), t3.direction), 0.0f, 1e-5f) << "coplanar";
        }
    }
}

// A particle refracts at every step in textured tissue: the direction must stay a unit
// vector over a long path (refract() renormalises by a Newton step, not a root), here
// 10^5 refractions with indices within 5 % and random normals.
TEST(Refract, DirectionStaysUnitOverManyRefractions) {
    for (int dim : {2, 3}) {
        ParticleRng rng(7, 0, uint32_t(dim));
        Vec<3> r = glm::normalize(Vec<3>(0.3f, -1.0f, dim == 3 ? 0.2f : 0.0f));
        float worst = 0.0f;
        for (int i = 0; i < 100000; ++i) {
            const auto u = rng.draw4();
            const float eta = 0.95f + 0.1f * u[0];
            Vec<3> n(u[1] - 0.5f, u[2] - 0.5f, dim == 3 ? u[3] - 0.5f : 0.0f);
            n = glm::normalize(n + Vec<3>(0.0f, 1e-3f, 0.0f));
            if (dim == 2) {
                r = Vec<3>(refract<2>(Vec<2>(r), Vec<2>(n), eta).direction, 0.0f);
            } else {
                r = refract<3>(r, n, eta).direction;
            }
            worst = std::max(worst, std::abs(glm::length(r) - 1.0f));
        }
        EXPECT_LT(worst, 1e-6f) << dim << "D";
    }
}

// The step's attenuation exp(-x): the two Taylor series below 0.5 and the library beyond.
// The truncation bounds are the series' next terms, x^5/5! below 0.03 and x^8/8! below
// 0.5 (Lagrange remainder, alternating series), plus float rounding of the Horner sums
// (a few ulp); the reference is std::exp in double.
TEST(ExpMinus, MatchesExpWithinTheSeriesRemainder) {
    int checked = 0;
    for (double x = 0.0; x < 3.0; x += 1e-4) {
        const float xf = float(x);
        const double exact = std::exp(-double(xf));
        const double remainder = xf < kExpSeries4Below    ? std::pow(double(xf), 5) / 120.0
                                 : xf <= kExpSeries7Below ? std::pow(double(xf), 8) / 40320.0
                                                          : 0.0;
        const double allowed = remainder + 4.0 * double(std::numeric_limits<float>::epsilon());
        ASSERT_NEAR(double(exp_minus(xf)), exact, allowed * exact) << "x = " << xf;
        ++checked;
    }
    EXPECT_GT(checked, 29000);
    // The series alone below 0.5 (as the vector stage evaluates them): the same bits.
    for (const float x : {0.0f, 0.01f, 0.029f, 0.03f, 0.2f, 0.4999f})
        EXPECT_EQ(exp_minus(x), exp_minus_series(x)) << x;
}

TEST(Reflect, AngleOfReflectionEqualsIncidence) {
    const Vec<3> n = glm::normalize(Vec<3>(1, 2, 3));
    const Vec<3> r = glm::normalize(Vec<3>(-0.3f, 0.1f, -1.0f));
    const Vec<3> m = reflect<3>(r, n);
    EXPECT_NEAR(glm::dot(m, n), -glm::dot(r, n), 1e-6f);
    EXPECT_NEAR(glm::length(m), 1.0f, 1e-6f);
}

TEST(ReflectedFraction, LimitsAndReciprocity) {
    // Normal incidence: ((Z2 - Z1) / (Z2 + Z1))^2.
    EXPECT_NEAR(reflected_fraction(1.5f, 6.0f, 1.0f, 1.0f), std::pow(4.5 / 7.5, 2), 1e-6);
    EXPECT_EQ(reflected_fraction(1.5f, 1.5f, 0.8f, 0.8f), 0.0f);
    EXPECT_EQ(reflected_fraction(1.5f, 6.0f, 0.3f, 0.0f), 1.0f);  // past the critical angle
    // Reciprocity: the same interface seen from either side reflects the same fraction.
    const float z1 = 1.4f, z2 = 2.9f, n1 = 1.0f, n2 = 0.8f;
    for (int a = 1; a < 9; ++a) {
        const float ti = glm::radians(6.0f * a);
        const float tt = std::asin(std::sin(ti) * n1 / n2);
        EXPECT_NEAR(reflected_fraction(z1, z2, std::cos(ti), std::cos(tt)),
                    reflected_fraction(z2, z1, std::cos(tt), std::cos(ti)), 1e-6);
    }
}

// A fluid onto a solid (fluid_solid_fractions). Soft tissue (1060 kg/m^3, 1540 m/s) onto
// cortical bone (1900 kg/m^3, 3500 m/s, shear 0.53 x 3500 m/s); critical angles 26.1
// (longitudinal) and 56.1 degrees (shear).
TEST(FluidSolid, LimitsConservationAndTheWindowBetweenTheCriticalAngles) {
    const double rho1 = 1060.0, c1 = 1540.0, rho2 = 1900.0, c_l = 3500.0, c_s = 0.53 * 3500.0;
    // Normal incidence: no shear, the fluid's ((Z2 - Z1) / (Z2 + Z1))^2.
    const SolidFractions normal = fluid_solid_fractions(rho1, c1, rho2, c_l, c_s, 0.0);
    const double z1 = rho1 * c1, z2 = rho2 * c_l;
    EXPECT_NEAR(normal.reflected, std::pow((z2 - z1) / (z2 + z1), 2), 1e-12);
    EXPECT_NEAR(normal.shear, 0.0, 1e-12);
    // The three shares are separate formulas: their sum is 1 at every angle only if each
    // is right (the energy fluxes across the interface balance).
    for (int degrees = 0; degrees < 90; ++degrees) {
        const double sin1 = std::sin(degrees * std::numbers::pi / 180.0);
        const SolidFractions f = fluid_solid_fractions(rho1, c1, rho2, c_l, c_s, sin1);
        EXPECT_NEAR(f.reflected + f.longitudinal + f.shear, 1.0, 1e-9) << degrees;
        // Past the longitudinal critical angle the solid's longitudinal wave carries
        // nothing; past the shear one, everything reflects.
        if (degrees > 27) {
            EXPECT_NEAR(f.longitudinal, 0.0, 1e-12) << degrees;
        }
        if (degrees > 57) {
            EXPECT_NEAR(f.reflected, 1.0, 1e-9) << degrees;
        }
    }
    // Between them, most goes into shear: at 40 degrees 0.186 reflects and 0.814 converts
    // (the same formulas evaluated separately in Python's complex arithmetic).
    const SolidFractions window =
        fluid_solid_fractions(rho1, c1, rho2, c_l, c_s, std::sin(40.0 * std::numbers::pi / 180.0));
    EXPECT_NEAR(window.reflected, 0.18596, 1e-4);
    EXPECT_NEAR(window.shear, 0.81404, 1e-4);
    // A solid without rigidity (c_s -> 0) is a fluid: the fluid interface's R^2 before
    // the critical angle, total reflection after it.
    for (int degrees = 0; degrees < 90; degrees += 3) {
        const double t1 = degrees * std::numbers::pi / 180.0, sin_t = std::sin(t1) * c_l / c1;
        const SolidFractions f = fluid_solid_fractions(rho1, c1, rho2, c_l, 1e-6, std::sin(t1));
        const double expected =
            sin_t >= 1.0 ? 1.0
                         : double(reflected_fraction(float(z1), float(z2), float(std::cos(t1)),
                                                     float(std::sqrt(1.0 - sin_t * sin_t))));
        EXPECT_NEAR(f.reflected, expected, 1e-5) << degrees;
    }
}

using test::chi_square;

class Lobe2D : public ::testing::TestWithParam<float> {};

TEST_P(Lobe2D, AnglesFollowCosPowerDensity) {
    // 200k angles in 40 bins over [-pi/2, pi/2]; expected bin probabilities by Simpson
    // integration of cos^c. Critical chi-square, 39 dof, p = 0.001: 72.05.
    const float c = GetParam();
    constexpr int kBins = 40, kSamples = 200000;
    std::vector<double> p(kBins);
    double total = 0.0;
    for (int b = 0; b < kBins; ++b) {
        const double lo = -kPi / 2 + kPi * b / kBins, hi = lo + kPi / kBins;
        double sum = 0.0;
        for (int i = 0; i <= 200; ++i) {
            const double x = lo + (hi - lo) * i / 200.0;
            const double w = (i == 0 || i == 200) ? 1 : (i % 2 ? 4 : 2);
            sum += w * std::pow(std::cos(x), double(c));
        }
        p[b] = sum * (hi - lo) / 600.0;
        total += p[b];
    }
    for (double& v : p) v /= total;
    std::vector<int> counts(kBins, 0);
    ParticleRng rng(99, 0, 0);
    std::array<float, 4> block{};
    int used = 4;
    auto uniform = [&] {
        if (used == 4) block = rng.draw4(), used = 0;
        return block[used++];
    };
    for (int s = 0; s < kSamples; ++s) {
        const float phi = sample_cos_power_angle_2d(c, uniform);
        ASSERT_LE(std::abs(phi), kPi / 2);
        counts[std::min(kBins - 1, int((phi + kPi / 2) / kPi * kBins))]++;
    }
    // Bins with tiny expectation (large c) are merged into their neighbours by skipping
    // them: chi-square needs expected counts >= 5.
    std::vector<int> kept_counts;
    std::vector<double> kept_p;
    for (int b = 0; b < kBins; ++b) {
        if (p[b] * kSamples >= 5) kept_counts.push_back(counts[b]), kept_p.push_back(p[b]);
    }
    const int kept_n = std::accumulate(kept_counts.begin(), kept_counts.end(), 0);
    double kept_total = std::accumulate(kept_p.begin(), kept_p.end(), 0.0);
    for (double& v : kept_p) v /= kept_total;
    EXPECT_LT(chi_square(kept_counts, kept_p, kept_n), 72.05) << "c = " << c;
}

INSTANTIATE_TEST_SUITE_P(Exponents, Lobe2D,
                         ::testing::Values(0.0f, 0.5f, 1.0f, 4.0f, 30.0f, 400.0f));

class Lobe3D : public ::testing::TestWithParam<float> {};

TEST_P(Lobe3D, CosThetaFollowsCosPowerAndAzimuthIsUniform) {
    // P(cos theta <= x) = x^(c+1): 20 equal-probability bins in cos theta, 20 in azimuth.
    // Critical chi-square, 19 dof, p = 0.001: 43.82.
    const float c = GetParam();
    const Vec<3> axis = glm::normalize(Vec<3>(0.3f, -0.4f, 0.8f));
    Vec<3> b1, b2;
    orthonormal_basis(axis, &b1, &b2);
    constexpr int kBins = 20, kSamples = 100000;
    std::vector<int> polar(kBins, 0), azimuth(kBins, 0);
    ParticleRng rng(5, 1, 2);
    for (int s = 0; s < kSamples; ++s) {
        const auto u = rng.draw4();
        const Vec<3> d = sample_cos_power_direction_3d(axis, c, u[0], u[1]);
        const float cos_t = glm::dot(d, axis);
        ASSERT_GE(cos_t, -1e-6f);
        polar[std::min(kBins - 1, int(std::pow(std::max(cos_t, 0.0f), c + 1.0f) * kBins))]++;
        const float phi = std::atan2(glm::dot(d, b2), glm::dot(d, b1)) + kPi;
        if (cos_t < 0.9999f) azimuth[std::min(kBins - 1, int(phi / (2 * kPi) * kBins))]++;
    }
    const std::vector<double> equal(kBins, 1.0 / kBins);
    EXPECT_LT(chi_square(polar, equal, kSamples), 43.82);
    EXPECT_LT(chi_square(azimuth, equal, std::accumulate(azimuth.begin(), azimuth.end(), 0)),
              43.82);
}

INSTANTIATE_TEST_SUITE_P(Exponents, Lobe3D, ::testing::Values(0.0f, 1.0f, 10.0f, 100.0f));

}  // namespace
}  // namespace sonotrace::simulator
