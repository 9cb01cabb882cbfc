#include "probe/beam.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

#include "probe/array_geometry.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/hash.h"

namespace sonotrace::probe {

namespace {

using base::mix64;

// Uniform in [0, 1) from a key: 53 random bits.
double uniform(uint64_t seed, uint64_t line, uint64_t particle, uint64_t draw) {
    const uint64_t h = mix64(mix64(mix64(seed ^ 0x62656d73ull) ^ line) ^ (particle << 2 | draw));
    return double(h >> 11) * 0x1.0p-53;
}

}  // namespace

double hann_inverse_cdf(double u) {
    u = std::clamp(u, 0.0, 1.0);
    // CDF F(v) = v - sin(2 pi v) / (2 pi), monotone; Newton inside a shrinking bracket.
    double lo = 0.0, hi = 1.0, v = u;
    for (int i = 0; i < 60; ++i) {
        const double f = v - std::sin(2.0 * std::numbers::pi * v) / (2.0 * std::numbers::pi) - u;
        if (std::abs(f) < 1e-13) break;
        (f > 0.0 ? hi : lo) = v;
        const double density = 1.0 - std::cos(2.0 * std::numbers::pi * v);
        double next = density > 1e-12 ? v - f / density : 0.5 * (lo + hi);
        if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
        v = next;
    }
    return v;
}

double normal_inverse_cdf(double u) {
    // Acklam's rational approximation (relative error 1.2e-9), then one Halley step on
    // erfc for full double precision.
    static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,
                               -2.759285104469687e+02, 1.383577518672690e+02,
                               -3.066479806614716e+01, 2.506628277459239e+00};
    static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02,
                               -1.556989798598866e+02, 6.680131188771972e+01,
                               -1.328068155288572e+01};
    static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01,
                               -2.400758277161838e+00, -2.549732539343734e+00,
                               4.374664141464968e+00,  2.938163982698783e+00};
    static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                               3.754408661907416e+00};
    u = std::clamp(u, 1e-300, 1.0 - 1e-16);
    double x;
    if (u < 0.02425) {
        const double q = std::sqrt(-2.0 * std::log(u));
        x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
    } else if (u <= 1.0 - 0.02425) {
        const double q = u - 0.5, r = q * q;
        x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
            (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0);
    } else {
        const double q = std::sqrt(-2.0 * std::log(1.0 - u));
        x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
    }
    const double e = 0.5 * std::erfc(-x / std::numbers::sqrt2) - u;
    const double g = e * std::sqrt(2.0 * std::numbers::pi) * std::exp(0.5 * x * x);
    return x - g / (1.0 + 0.5 * x * g);
}

double focal_sigma_mm(const Transducer& t, double aperture_mm) {
    const double f_number = t.focus_mm / std::max(aperture_mm, 1e-9);
    return t.wavelength_mm() * f_number / (2.0 * std::sqrt(2.0 * std::log(2.0)));
}

Sources<2> make_beams(const Transducer& t, const BeamSettings& settings, const glm::dvec2& to_map) {
    const ScanGeometry geometry(t);
    const ArrayGeometry& array = geometry.array();
    const int n = std::max(1, settings.particles_per_line);
    const double half_array = 0.5 * t.array_length_mm();
    const double half_aperture = 0.5 * t.active_aperture_mm();
    const double seconds_per_mm = 1e-3 / tissue::kReferenceSpeed;
    Sources<2> sources;
    sources.reserve(std::size_t(t.lines) * std::size_t(n));
    std::vector<int> strata(static_cast<std::size_t>(n));
    for (int l = 0; l < t.lines; ++l) {
        const ScanLine line = geometry.line(l);
        const glm::dvec2 focus = line.origin + t.focus_mm * line.direction;
        const glm::dvec2 across(line.direction.y, -line.direction.x);
        // The active aperture as a coordinate s along the array (mm from its centre),
        // clipped to the array: edge lines of a linear or convex probe have less. A
        // closed array has no ends; steered lines use the whole array.
        const double centre = array.aperture_centre(line).value_or(0.0);
        const double s_lo =
            array.closed() ? centre - half_aperture : std::max(centre - half_aperture, -half_array);
        const double s_hi =
            array.closed() ? centre + half_aperture : std::min(centre + half_aperture, half_array);
        const double sigma = focal_sigma_mm(t, s_hi - s_lo);
        // Aim offsets: stratified too, paired with the aperture strata by a shuffle.
        std::iota(strata.begin(), strata.end(), 0);
        for (int i = n - 1; i > 0; --i) {
            const int j = int(uniform(settings.seed, uint64_t(l), uint64_t(i), 3) * (i + 1));
            std::swap(strata[std::size_t(i)], strata[std::size_t(j)]);
        }
        for (int i = 0; i < n; ++i) {
            const double u1 = (i + uniform(settings.seed, uint64_t(l), uint64_t(i), 0)) / n;
            const double u2 =
                (strata[std::size_t(i)] + uniform(settings.seed, uint64_t(l), uint64_t(i), 1)) / n;
            const double s = s_lo + (s_hi - s_lo) * hann_inverse_cdf(u1);
            const glm::dvec2 element = array.face(s).position;
            const double offset = sigma * normal_inverse_cdf(u2);
            const glm::dvec2 aim = focus + offset * across;
            SourceParticle<2> p;
            p.position = glm::vec2(element + to_map);
            p.direction = glm::vec2(glm::normalize(aim - element));
            p.energy = 1.0f / float(n);
            p.line = uint32_t(l);
            p.time_s = float((t.focus_mm - glm::length(focus - element)) * seconds_per_mm);
            sources.push_back(p);
        }
    }
    return sources;
}

}  // namespace sonotrace::probe
