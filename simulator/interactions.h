#pragma once
// Interactions of a particle with the medium, as small pure functions shared by the 2D
// and 3D tracer and tested one by one. Directions are unit vectors; normals are unit
// vectors of either orientation unless stated.
//
// Corrections of Reis & Bertram's formulas, applied here:
//  - eq. 4 multiplies by the vector g where its magnitude is meant; the density beyond
//    the step is d1 = d0 + s * (g.r / |g||r|) * |g| = d0 + s * (g . r_hat).
//  - eq. 8 rotates the direction by the transmitted angle; Snell's law instead *sets*
//    the angle to the normal to alpha_t. We use the vector form of Snell's law, which
//    does that in 2D and 3D alike.
//  - eq. 9 reflects with g as if it were a unit vector; the normal must be normalised.
//  - eq. 10's R and T are amplitude coefficients; the intensity fractions are R^2 and
//    1 - R^2 (the paper modulates energy by R and T directly, which does not conserve it).
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <numbers>

#include <glm/glm.hpp>

#include "simulator/lanes.h"

namespace sonotrace::simulator {

template <int Dim>
using Vec = glm::vec<Dim, float>;

template <int Dim>
inline Vec<Dim> reflect(const Vec<Dim>& r, const Vec<Dim>& normal) {
    return r - 2.0f * glm::dot(r, normal) * normal;  // eq. 9, unit normal
}

// Snell's law n_from sin(theta_i) = n_to sin(theta_t) in vector form, with
// eta = n_from / n_to (refractive index n = c0 / c, or the paper's density), per lane
// (lanes.h): the direction transmitted, or past the critical angle the mirror direction.
template <class Lane, int Dim>
struct LaneRefraction {
    LaneVec<typename Lane::F, Dim> direction;
    typename Lane::Mask total_reflection;  // sin(theta_t) would exceed 1
    typename Lane::F cos_incident;         // |cos| of the angle between r and the normal
    typename Lane::F cos_transmitted;      // 0 on total reflection
};

template <class Lane, int Dim, class F = typename Lane::F>
SONOTRACE_LANE_INLINE LaneRefraction<Lane, Dim> refract(const LaneVec<F, Dim>& r,
                                                        const LaneVec<F, Dim>& normal,
                                                        const F& eta) {
    // Orient the normal against the travel direction (pointing back to the incident side).
    const F d = dot(r, normal);
    const auto away = d > 0.0f;
    LaneVec<F, Dim> facing;
    for (std::size_t a = 0; a < std::size_t(Dim); ++a)
        facing[a] = select(away, -normal[a], normal[a]);
    const F cos_i = select(away, d, -d);
    const F k = 1.0f - eta * eta * (1.0f - cos_i * cos_i);
    const auto total = k < 0.0f;
    const F cos_t = Lane::sqrt(k);  // NaN where total: not selected
    // Unit length for unit r and normal; one Newton step for 1/sqrt(|t|^2) about 1 keeps
    // the rounding of many steps from accumulating (error quadratic in |t|^2 - 1, where a
    // normalisation put a root and a division on every step's critical path).
    LaneVec<F, Dim> t;
    for (std::size_t a = 0; a < std::size_t(Dim); ++a)
        t[a] = eta * r[a] + (eta * cos_i - cos_t) * facing[a];
    const F renormalise = 1.5f - 0.5f * dot(t, t);
    const F twice = 2.0f * dot(r, facing);  // reflect(): the mirror direction
    LaneRefraction<Lane, Dim> out;
    for (std::size_t a = 0; a < std::size_t(Dim); ++a)
        out.direction[a] = select(total, r[a] - twice * facing[a], t[a] * renormalise);
    out.total_reflection = total;
    out.cos_incident = cos_i;
    out.cos_transmitted = select(total, F{}, cos_t);
    return out;
}

// refract() for one particle in glm vectors.
template <int Dim>
struct Refraction {
    Vec<Dim> direction;     // transmitted direction, or the mirror direction on total reflection
    bool total_reflection;  // sin(theta_t) would exceed 1
    float cos_incident;     // |cos| of the angle between r and the normal
    float cos_transmitted;  // 0 on total reflection
};

template <int Dim>
inline Refraction<Dim> refract(const Vec<Dim>& r, const Vec<Dim>& normal, float eta) {
    LaneVec<float, Dim> r_lanes, normal_lanes;
    for (int a = 0; a < Dim; ++a)
        r_lanes[std::size_t(a)] = r[a], normal_lanes[std::size_t(a)] = normal[a];
    const auto bent = refract<ScalarLane, Dim>(r_lanes, normal_lanes, eta);
    Vec<Dim> direction;
    for (int a = 0; a < Dim; ++a) direction[a] = bent.direction[std::size_t(a)];
    return {direction, bent.total_reflection, bent.cos_incident, bent.cos_transmitted};
}

// exp(-x) for the attenuation of one step, x >= 0, as two Taylor polynomials: per step
// x = alpha f s is small (0.005 in soft tissue, 0.2 in skull at 3.5 MHz and 0.125 mm
// steps). Below 0.03 degree 4 is exact to x^5/5! < 2.1e-10; up to 0.5 degree 7, to
// x^8/8! < 1.6e-7 relative. Beyond 0.5 the series' value is wrong and exp_minus() calls
// the library (the vector stage hands such a step to the scalar one). The libm call was
// 14 % of a step.
constexpr float kExpSeries4Below = 0.03f, kExpSeries7Below = 0.5f;
// Taylor polynomial of exp(-x) by Horner's rule: `inverse_factorials` from the highest
// degree down to 1/0!.
template <class F, std::size_t N>
SONOTRACE_LANE_INLINE F exp_minus_taylor(const F& x,
                                         const std::array<float, N>& inverse_factorials) {
    F p = F{} + inverse_factorials[0];
    for (std::size_t i = 1; i < N; ++i) p = p * -x + inverse_factorials[i];
    return p;
}
template <class F>
SONOTRACE_LANE_INLINE F exp_minus_series4(const F& x) {
    return exp_minus_taylor(x, std::array{1.0f / 24.0f, 1.0f / 6.0f, 0.5f, 1.0f, 1.0f});
}
template <class F>
SONOTRACE_LANE_INLINE F exp_minus_series7(const F& x) {
    return exp_minus_taylor(x, std::array{1.0f / 5040.0f, 1.0f / 720.0f, 1.0f / 120.0f,
                                          1.0f / 24.0f, 1.0f / 6.0f, 0.5f, 1.0f, 1.0f});
}
// Both series, x < kExpSeries7Below.
template <class F>
SONOTRACE_LANE_INLINE F exp_minus_series(const F& x) {
    return select(x < kExpSeries4Below, exp_minus_series4(x), exp_minus_series7(x));
}
// exp(-x), x >= 0, for one particle.
inline float exp_minus(float x) {
    return x > kExpSeries7Below ? std::exp(-x) : exp_minus_series(x);
}

// Intensity fraction reflected at an interface Z1 -> Z2 at oblique incidence (eq. 10):
// R = (Z2/cos_t - Z1/cos_i) / (Z2/cos_t + Z1/cos_i), returned as R^2; 1 past the
// critical angle (cos_t <= 0).
inline float reflected_fraction(float z1, float z2, float cos_i, float cos_t) {
    if (cos_t <= 0.0f) return 1.0f;
    cos_i = std::max(cos_i, 1e-6f);
    const float a = z2 / cos_t, b = z1 / cos_i;
    const float r = (a - b) / (a + b);
    return r * r;
}

// Media faster than this are solids (bone, nylon and metal wires) whose shear wave takes
// a share of the energy at their interfaces; soft tissues and liquids lie at 1400-1700 m/s
// and carry no shear wave at ultrasound frequencies.
inline constexpr double kSolidSpeedMin = 2000.0;  // m/s
// Media slower than this are gases (air outside the skin, in sinuses and bowel; 343 m/s).
// Their surfaces against tissue reflect as mirrors, whatever the tissue's roughness: the
// skin's relief (tens of micrometres) lies below the Rayleigh criterion lambda / (8 cos
// theta), 70 um at 2.7 MHz, and a gas takes the shape of the surface it meets. (Rough
// lobes at the skin sent the transtemporal view's scalp-guided paths back from the skin
// beside the probe: the lone spots at the fan's edges, docs/guide/simulate.md.)
inline constexpr double kGasSpeedMax = 1000.0;  // m/s
// A solid's shear speed over its longitudinal speed: 1500 / 2820 m/s measured through ex
// vivo human skull (White, Clement & Hynynen 2006, Ultrasound Med. Biol. 32:1085); steel
// and aluminium lie at 0.54 and 0.49.
inline constexpr double kShearToLongitudinalSpeed = 0.53;

// Energy fractions of a longitudinal wave meeting an isotropic solid from a fluid.
struct SolidFractions {
    double reflected;     // back into the fluid: |R|^2
    double longitudinal;  // on as the solid's longitudinal wave
    double shear;         // converted into the solid's shear wave
};
// A plane wave from a fluid (density rho1, speed c1) onto an isotropic solid (rho2,
// longitudinal c_l, shear c_s) at sin(theta1) = sin1 (Brekhovskikh & Godin, "Acoustics of
// Layered Media I", 1990, sec. 4.2): with Z1 = rho1 c1 / cos theta1, Z_l = rho2 c_l /
// cos theta_l and Z_s = rho2 c_s / cos theta_s (Snell's law for both waves), and
// Z = Z_l cos^2 2 theta_s + Z_s sin^2 2 theta_s, R = (Z - Z1) / (Z + Z1), and each
// wave's energy share is 4 Z1 Re(its term of Z) / |Z + Z1|^2. Past a wave's critical
// angle its cosine is imaginary and it carries no energy. At normal incidence this is
// the fluid's (Z2 - Z1) / (Z2 + Z1); between the two critical angles (26 and 56 degrees
// from soft tissue onto bone) most of the energy goes into shear, not back.
inline SolidFractions fluid_solid_fractions(double rho1, double c1, double rho2, double c_l,
                                            double c_s, double sin1) {
    using C = std::complex<double>;
    sin1 = std::clamp(sin1, 0.0, 1.0);
    // A wave's cosine, imaginary beyond its critical angle; kept off 0 (grazing: its
    // impedance is then huge, not infinite, and the fractions stay finite).
    auto cosine = [](double sine) {
        return sine <= 1.0 ? C(std::max(std::sqrt(1.0 - sine * sine), 1e-12), 0.0)
                           : C(0.0, std::max(std::sqrt(sine * sine - 1.0), 1e-12));
    };
    const double cos1 = std::max(std::sqrt(1.0 - sin1 * sin1), 1e-9);
    const double sin_l = c_l / c1 * sin1, sin_s = c_s / c1 * sin1;
    const C cos_l = cosine(sin_l), cos_s = cosine(sin_s);
    const double z1 = rho1 * c1 / cos1;
    const C z_l = rho2 * c_l / cos_l, z_s = rho2 * c_s / cos_s;
    const double cos_2s = 1.0 - 2.0 * sin_s * sin_s;
    const C sin_2s = 2.0 * sin_s * cos_s;
    const C longitudinal_term = z_l * cos_2s * cos_2s, shear_term = z_s * sin_2s * sin_2s;
    const C z = longitudinal_term + shear_term;
    const double denominator = std::norm(z + z1);
    SolidFractions f;
    f.reflected = std::norm(z - z1) / denominator;
    f.longitudinal = std::max(0.0, 4.0 * z1 * longitudinal_term.real() / denominator);
    f.shear = std::max(0.0, 4.0 * z1 * shear_term.real() / denominator);
    return f;
}

// A direction at angle phi from `axis`, turned within the plane (2D) .
inline Vec<2> rotate(const Vec<2>& axis, float phi) {
    const float c = std::cos(phi), s = std::sin(phi);
    return {c * axis.x - s * axis.y, s * axis.x + c * axis.y};
}

// Any two unit vectors completing `axis` to an orthonormal basis (Duff et al. 2017).
inline void orthonormal_basis(const Vec<3>& n, Vec<3>* b1, Vec<3>* b2) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    *b1 = {1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
    *b2 = {b, sign + n.y * n.y * a, -n.y};
}

// Angle phi in [-pi/2, pi/2] with density proportional to cos^c(phi) (eq. 11 in 2D).
// Exact rejection sampling: for c >= 1 the proposal is a normal N(0, 1/c) truncated to
// |phi| < pi/2, accepted with cos^c(phi) * exp(c phi^2 / 2) <= 1 (since
// ln cos phi <= -phi^2/2); for c < 1 a uniform proposal accepted with cos^c(phi).
// `uniform` yields uniforms in [0, 1).
template <typename Uniform>
float sample_cos_power_angle_2d(float c, Uniform&& uniform) {
    constexpr float kHalfPi = std::numbers::pi_v<float> / 2.0f;
    if (c >= 1.0f) {
        const float sigma = 1.0f / std::sqrt(c);
        for (;;) {
            // Box-Muller normal.
            const float u1 = std::max(uniform(), 1e-12f), u2 = uniform();
            const float phi = sigma * std::sqrt(-2.0f * std::log(u1)) *
                              std::cos(2.0f * std::numbers::pi_v<float> * u2);
            if (std::abs(phi) >= kHalfPi) continue;
            const float accept = std::exp(c * (std::log(std::cos(phi)) + 0.5f * phi * phi));
            if (uniform() < accept) return phi;
        }
    }
    for (;;) {
        const float phi = (2.0f * uniform() - 1.0f) * kHalfPi;
        if (uniform() < std::pow(std::cos(phi), c)) return phi;
    }
}

// Share of a reflected lobe cos^c about the mirror direction that a receiver subtending
// +-half_acceptance (rad) about a direction `off_axis` (rad) from the mirror takes: the
// lobe as a Gaussian of sigma 1 / sqrt(c) (its small-angle form, in the plane of
// incidence), integrated over the acceptance. A mirror (c large) sends everything or
// nothing; a rough surface (bone: c ~ 3) a share at most angles.
inline double lobe_share(double off_axis, double lobe_exponent, double half_acceptance) {
    const double sigma = 1.0 / std::sqrt(std::max(lobe_exponent, 1.0));
    auto cdf = [](double z) { return 0.5 * std::erfc(-z / std::numbers::sqrt2); };
    return cdf((half_acceptance - off_axis) / sigma) - cdf((-half_acceptance - off_axis) / sigma);
}

// Direction about `axis` with solid-angle density proportional to cos^c(theta) on the
// hemisphere (eq. 11 in 3D): cos(theta) = u^(1/(c+1)), azimuth uniform.
inline Vec<3> sample_cos_power_direction_3d(const Vec<3>& axis, float c, float u1, float u2) {
    const float cos_t = std::pow(u1, 1.0f / (c + 1.0f));
    const float sin_t = std::sqrt(std::max(0.0f, 1.0f - cos_t * cos_t));
    const float phi = 2.0f * std::numbers::pi_v<float> * u2;
    Vec<3> b1, b2;
    orthonormal_basis(axis, &b1, &b2);
    return glm::normalize(cos_t * axis + sin_t * (std::cos(phi) * b1 + std::sin(phi) * b2));
}

}  // namespace sonotrace::simulator
