#include "simulator/sources.h"

#include <cmath>
#include <string>

#include "simulator/interactions.h"
#include "tissue/base/error.h"

namespace sonotrace::simulator {

namespace {
// Evenly spaced offsets in [-1, 1] (the single particle sits at 0).
float spread(int index, int count) {
    return count > 1 ? -1.0f + 2.0f * float(index) / float(count - 1) : 0.0f;
}
}  // namespace

Sources<2> parallel_beam(glm::vec2 centre, glm::vec2 direction, float width_mm, int count,
                         uint32_t line, float energy) {
    const glm::vec2 d = glm::normalize(direction), across(-d.y, d.x);
    Sources<2> out;
    for (int i = 0; i < count; ++i) {
        out.push_back({centre + across * (0.5f * width_mm * spread(i, count)), d, energy, line});
    }
    return out;
}

Sources<2> fan_beam(glm::vec2 origin, glm::vec2 direction, float half_angle_deg, int count,
                    uint32_t line, float energy) {
    const glm::vec2 d = glm::normalize(direction);
    Sources<2> out;
    for (int i = 0; i < count; ++i) {
        out.push_back(
            {origin, rotate(d, glm::radians(half_angle_deg) * spread(i, count)), energy, line});
    }
    return out;
}

// count x count particles over a square grid of offsets (u, v) in [-1, 1]^2 about the
// unit `axis`; `make` turns (axis, b1, b2, u, v) into a particle.
template <typename Make>
Sources<3> square_grid(glm::vec3 axis, int count, Make make) {
    const glm::vec3 d = glm::normalize(axis);
    glm::vec3 b1, b2;
    orthonormal_basis(d, &b1, &b2);
    Sources<3> out;
    for (int j = 0; j < count; ++j) {
        for (int i = 0; i < count; ++i)
            out.push_back(make(d, b1, b2, spread(i, count), spread(j, count)));
    }
    return out;
}

Sources<3> parallel_beam_3d(glm::vec3 centre, glm::vec3 direction, float width_mm, int count,
                            uint32_t line, float energy) {
    return square_grid(
        direction, count, [&](glm::vec3 d, glm::vec3 b1, glm::vec3 b2, float u, float v) {
            return SourceParticle<3>{centre + 0.5f * width_mm * (u * b1 + v * b2), d, energy, line};
        });
}

Sources<3> fan_beam_3d(glm::vec3 origin, glm::vec3 direction, float half_angle_deg, int count,
                       uint32_t line, float energy) {
    const float half = glm::radians(half_angle_deg);
    return square_grid(
        direction, count, [&](glm::vec3 d, glm::vec3 b1, glm::vec3 b2, float u, float v) {
            return SourceParticle<3>{
                origin, glm::normalize(d + std::tan(half * u) * b1 + std::tan(half * v) * b2),
                energy, line};
        });
}

template <int Dim>
void validate_sources(const Sources<Dim>& sources) {
    for (std::size_t n = 0; n < sources.size(); ++n) {
        const auto& s = sources[n];
        bool finite = std::isfinite(s.energy);
        for (int a = 0; a < Dim; ++a)
            finite = finite && std::isfinite(s.position[a]) && std::isfinite(s.direction[a]);
        const std::string field = "sources[" + std::to_string(n) + "]";
        if (!finite)
            throw base::InputError("sources", field,
                                   "position, direction and energy must be finite");
        if (s.energy < 0.0f) throw base::InputError("sources", field + ".energy", "must be >= 0");
        if (!(glm::length(s.direction) > 0.0f))
            throw base::InputError("sources", field + ".direction", "is zero");
    }
}

template void validate_sources<2>(const Sources<2>&);
template void validate_sources<3>(const Sources<3>&);

}  // namespace sonotrace::simulator
