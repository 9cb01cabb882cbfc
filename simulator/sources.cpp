#include "simulator/sources.h"

#include <cmath>

#include "simulator/interactions.h"

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

Sources<3> parallel_beam_3d(glm::vec3 centre, glm::vec3 direction, float width_mm, int count,
                            uint32_t line, float energy) {
    const glm::vec3 d = glm::normalize(direction);
    glm::vec3 b1, b2;
    orthonormal_basis(d, &b1, &b2);
    Sources<3> out;
    for (int j = 0; j < count; ++j) {
        for (int i = 0; i < count; ++i) {
            const glm::vec3 p =
                centre + 0.5f * width_mm * (spread(i, count) * b1 + spread(j, count) * b2);
            out.push_back({p, d, energy, line});
        }
    }
    return out;
}

Sources<3> fan_beam_3d(glm::vec3 origin, glm::vec3 direction, float half_angle_deg, int count,
                       uint32_t line, float energy) {
    const glm::vec3 d = glm::normalize(direction);
    glm::vec3 b1, b2;
    orthonormal_basis(d, &b1, &b2);
    Sources<3> out;
    for (int j = 0; j < count; ++j) {
        for (int i = 0; i < count; ++i) {
            const float a = glm::radians(half_angle_deg) * spread(i, count);
            const float b = glm::radians(half_angle_deg) * spread(j, count);
            out.push_back(
                {origin, glm::normalize(d + std::tan(a) * b1 + std::tan(b) * b2), energy, line});
        }
    }
    return out;
}

}  // namespace sonotrace::simulator
