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
#include <cmath>
#include <numbers>

#include <glm/glm.hpp>

namespace sonotrace::simulator {

template <int Dim>
using Vec = glm::vec<Dim, float>;

template <int Dim>
inline Vec<Dim> reflect(const Vec<Dim>& r, const Vec<Dim>& normal) {
    return r - 2.0f * glm::dot(r, normal) * normal;  // eq. 9, unit normal
}

template <int Dim>
struct Refraction {
    Vec<Dim> direction;     // transmitted direction, or the mirror direction on total reflection
    bool total_reflection;  // sin(theta_t) would exceed 1
    float cos_incident;     // |cos| of the angle between r and the normal
    float cos_transmitted;  // 0 on total reflection
};

// Snell's law n_from sin(theta_i) = n_to sin(theta_t) in vector form, with
// eta = n_from / n_to (refractive index n = c0 / c, or the paper's density).
template <int Dim>
inline Refraction<Dim> refract(const Vec<Dim>& r, const Vec<Dim>& normal, float eta) {
    // Orient the normal against the travel direction (pointing back to the incident side).
    const float d = glm::dot(r, normal);
    const Vec<Dim> facing = d > 0.0f ? -normal : normal;
    const float cos_i = std::abs(d);
    const float k = 1.0f - eta * eta * (1.0f - cos_i * cos_i);
    if (k < 0.0f) return {reflect<Dim>(r, facing), true, cos_i, 0.0f};
    const float cos_t = std::sqrt(k);
    // Unit length for unit r and normal; one Newton step for 1/sqrt(|t|^2) about 1 keeps
    // the rounding of many steps from accumulating (error quadratic in |t|^2 - 1, where
    // normalize() put a root and a division on every step's critical path).
    const Vec<Dim> t = eta * r + (eta * cos_i - cos_t) * facing;
    return {t * (1.5f - 0.5f * glm::dot(t, t)), false, cos_i, cos_t};
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
