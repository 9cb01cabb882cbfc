#include "imaging/mirror_ghosts.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>

#include "probe/array_geometry.h"
#include "tissue/acoustic_properties.h"

namespace sonotrace::imaging {

namespace {

// Where segment a -> b crosses segment c -> d, as the fraction of a -> b.
std::optional<double> crossing(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c,
                               const glm::dvec2& d) {
    const glm::dvec2 r = b - a, s = d - c;
    const double denominator = r.x * s.y - r.y * s.x;
    if (std::abs(denominator) < 1e-12) return std::nullopt;
    const glm::dvec2 w = c - a;
    const double u = (w.x * s.y - w.y * s.x) / denominator;
    const double v = (w.x * r.y - w.y * r.x) / denominator;
    if (u < 0.0 || u > 1.0 || v < 0.0 || v > 1.0) return std::nullopt;
    return u;
}

double reflection(double z, double z_ref) {
    return (z - z_ref) / (z + z_ref);
}

}  // namespace

MirrorSearch::MirrorSearch(const tissue::AcousticMap<2>& map, const glm::dvec2& to_map,
                           const probe::Transducer& t)
    : map_(map), to_map_(to_map), frequency_mhz_(t.frequency_mhz) {
    step_mm_ = 0.5 * std::min(map.spacing().x, map.spacing().y);
    // Without an impedance contrast of kStrongReflection anywhere there is nothing to find.
    const std::size_t n = std::size_t(map.dims().x) * std::size_t(map.dims().y);
    float low = std::numeric_limits<float>::max(), high = 0.0f;
    for (std::size_t i = 0; i < n; ++i) {
        low = std::min(low, map.texels()[i].impedance);
        high = std::max(high, map.texels()[i].impedance);
    }
    contrast_ = n > 0 && reflection(high, low) >= kStrongReflection;
    // The face: the array's arc, a point per element.
    const probe::ScanGeometry geometry(t);
    const double length = t.elements * t.pitch_mm;
    for (int e = 0; e <= t.elements; ++e)
        face_.push_back(geometry.array().face(-0.5 * length + e * t.pitch_mm).position);
    face_low_ = face_high_ = face_.front();
    for (const glm::dvec2& p : face_)
        face_low_ = glm::min(face_low_, p), face_high_ = glm::max(face_high_, p);
}

std::vector<MirrorGhost> MirrorSearch::ghosts(const glm::dvec2& target, double start_mm) const {
    std::vector<MirrorGhost> images;
    if (!contrast_) return images;
    auto impedance = [&](const glm::dvec2& p) {
        return double(map_.sample_impedance(glm::vec2(p + to_map_)).impedance);
    };
    auto inside = [&](const glm::dvec2& p) { return map_.inside(glm::vec2(p + to_map_)); };
    const double h = step_mm_;
    const int max_steps = int(4.0 * (map_.extent_mm().x + map_.extent_mm().y) / h);
    for (int ray = 0; ray < kRays; ++ray) {
        const double angle = 2.0 * std::numbers::pi * (ray + 0.5) / kRays;
        glm::dvec2 d(std::cos(angle), std::sin(angle));
        glm::dvec2 p = target + d * start_mm;
        if (!inside(p)) continue;
        const double z_ref = impedance(p);
        double s = start_mm, optical = 0.0, delay = 0.0, r = 0.0;
        bool turned = false;
        for (int k = 0; k < max_steps; ++k) {
            glm::dvec2 q = p + d * h;
            if (turned && q.x + h >= face_low_.x && q.x - h <= face_high_.x &&
                q.y + h >= face_low_.y && q.y - h <= face_high_.y) {
                std::optional<double> at;
                for (std::size_t e = 0; e + 1 < face_.size() && !at; ++e)
                    at = crossing(p, q, face_[e], face_[e + 1]);
                if (at) {
                    const glm::dvec2 arrival = p + d * (*at * h);
                    const double path = s + *at * h;
                    images.push_back({arrival - d * path, r, optical, delay});
                    break;
                }
            }
            if (!inside(q)) break;
            if (std::abs(reflection(impedance(q), z_ref)) >= kStrongReflection) {
                if (turned) break;  // a second strong interface: not followed
                // The interface between p and q, by bisection to 1/64 of a step.
                double lo = 0.0, hi = h;
                for (int b = 0; b < 6; ++b) {
                    const double mid = 0.5 * (lo + hi);
                    (std::abs(reflection(impedance(p + d * mid), z_ref)) >= kStrongReflection
                         ? hi
                         : lo) = mid;
                }
                const glm::dvec2 x = p + d * lo;
                const glm::dvec2 beyond = x + d * kReflectorDepthMm;
                if (!inside(beyond)) break;
                r = reflection(impedance(beyond), z_ref);
                if (std::abs(r) < kStrongReflection) break;  // too thin to be a mirror
                // The normal the tracer's specular reflections take (zone_normal): the
                // interface as a beam sees it.
                const glm::vec2 at(x + to_map_);
                const tissue::ImpedanceSample<2> g = map_.sample_impedance(at);
                const glm::vec2 local(g.grad_impedance[0], g.grad_impedance[1]);
                if (glm::length(local) == 0.0f) break;
                const glm::dvec2 normal =
                    glm::normalize(glm::dvec2(map_.zone_normal(at, glm::normalize(local))));
                s += lo;
                p = x;
                d = glm::normalize(d - 2.0 * glm::dot(d, normal) * normal);
                turned = true;
                continue;
            }
            const tissue::AcousticTexel<2> texel = map_.sample(glm::vec2(q + to_map_));
            optical += tissue::attenuation_per_mm(texel.attenuation, frequency_mhz_) * h;
            delay += (double(texel.refractive_index) - 1.0) * h;
            p = q;
            s += h;
        }
    }
    // One ghost per image point: the rays of one reflector agree.
    std::vector<MirrorGhost> ghosts;
    std::vector<int> counts;
    for (const MirrorGhost& image : images) {
        std::size_t g = 0;
        while (g < ghosts.size() &&
               glm::length(ghosts[g].at / double(counts[g]) - image.at) > kSameImageMm)
            ++g;
        if (g == ghosts.size()) ghosts.push_back({}), counts.push_back(0);
        ghosts[g].at += image.at, ghosts[g].reflection += image.reflection;
        ghosts[g].optical += image.optical, ghosts[g].delay_mm += image.delay_mm;
        ++counts[g];
    }
    for (std::size_t g = 0; g < ghosts.size(); ++g) {
        const double n = counts[g];
        ghosts[g] = {ghosts[g].at / n, ghosts[g].reflection / n, ghosts[g].optical / n,
                     ghosts[g].delay_mm / n};
    }
    return ghosts;
}

}  // namespace sonotrace::imaging
