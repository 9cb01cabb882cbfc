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

namespace {

// The beams of make_beams (Dim 2) and make_beams_3d (Dim 3), written once: a 3D particle
// starts where its 2D twin does in the scan plane, with its in-plane heading and clock,
// plus an elevation start and an elevation aim of its own draws.
template <int Dim>
Sources<Dim> beams(const Transducer& t, const BeamSettings& settings,
                   const glm::vec<Dim, double>& to_map) {
    const ScanGeometry geometry(t);
    const ArrayGeometry& array = geometry.array();
    const int n = std::max(1, settings.particles_per_line);
    const double half_array = 0.5 * t.array_length_mm();
    const double half_aperture = 0.5 * t.active_aperture_mm();
    const double seconds_per_mm = 1e-3 / tissue::kReferenceSpeed;
    // Elevation: the lens's height, and the aim's spread at its focus (the slice
    // thickness as FWHM). Their draws come from a stream of their own.
    const double half_height = 0.5 * t.elevation_aperture_mm();
    const double elevation_sigma = t.slice_thickness_mm / (2.0 * std::sqrt(2.0 * std::log(2.0)));
    const uint64_t elevation_seed = settings.seed ^ 0x656c657661746eull;
    Sources<Dim> sources;
    sources.reserve(std::size_t(t.lines) * std::size_t(n));
    std::vector<int> strata(static_cast<std::size_t>(n)), elevation_strata;
    if constexpr (Dim == 3) elevation_strata.resize(std::size_t(n));
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
        auto shuffle = [&](std::vector<int>& order, uint64_t seed, uint64_t draw) {
            std::iota(order.begin(), order.end(), 0);
            for (int i = n - 1; i > 0; --i) {
                const int j = int(uniform(seed, uint64_t(l), uint64_t(i), draw) * (i + 1));
                std::swap(order[std::size_t(i)], order[std::size_t(j)]);
            }
        };
        shuffle(strata, settings.seed, 3);
        if constexpr (Dim == 3) shuffle(elevation_strata, elevation_seed, 2);
        for (int i = 0; i < n; ++i) {
            const double u1 = (i + uniform(settings.seed, uint64_t(l), uint64_t(i), 0)) / n;
            const double u2 =
                (strata[std::size_t(i)] + uniform(settings.seed, uint64_t(l), uint64_t(i), 1)) / n;
            const double s = s_lo + (s_hi - s_lo) * hann_inverse_cdf(u1);
            const glm::dvec2 element = array.face(s).position;
            const double offset = sigma * normal_inverse_cdf(u2);
            const glm::dvec2 aim = focus + offset * across;
            const glm::dvec2 heading = glm::normalize(aim - element);
            SourceParticle<Dim> p;
            p.energy = 1.0f / float(n);
            p.line = uint32_t(l);
            const double time_mm = t.focus_mm - glm::length(focus - element);
            if constexpr (Dim == 2) {
                p.position = glm::vec2(element + to_map);
                p.direction = glm::vec2(heading);
                p.time_s = float(time_mm * seconds_per_mm);
            } else {
                // A uniform start over the elements' height (stratified), towards a
                // Gaussian aim at the elevation focus (its strata shuffled against them),
                // reached after elevation_focus mm in the scan plane.
                const double u3 = (i + uniform(elevation_seed, uint64_t(l), uint64_t(i), 0)) / n;
                const double u4 = (elevation_strata[std::size_t(i)] +
                                   uniform(elevation_seed, uint64_t(l), uint64_t(i), 1)) /
                                  n;
                const double e = half_height * (2.0 * u3 - 1.0);
                const double e_aim = elevation_sigma * normal_inverse_cdf(u4);
                const double slope = (e_aim - e) / t.elevation_focus_mm;
                p.position = glm::vec3(glm::dvec3(element, e) + to_map);
                p.direction = glm::vec3(glm::normalize(glm::dvec3(heading, slope)));
                // The lens delays the centre: every height reaches its focus together.
                const double lens_mm = std::hypot(t.elevation_focus_mm, e) - t.elevation_focus_mm;
                p.time_s = float((time_mm - lens_mm) * seconds_per_mm);
            }
            sources.push_back(p);
        }
    }
    return sources;
}

}  // namespace

Sources<2> make_beams(const Transducer& t, const BeamSettings& settings, const glm::dvec2& to_map) {
    return beams<2>(t, settings, to_map);
}

Sources<3> make_beams_3d(const Transducer& t, const BeamSettings& settings,
                         const glm::dvec3& to_map) {
    return beams<3>(t, settings, to_map);
}

}  // namespace sonotrace::probe
