#pragma once
// Particle sources: plain lists of particles. Transducer models (probe/) generate them;
// the injectors here make the parallel and fan beams of the paper's figures.
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "probe/source_particle.h"

namespace sonotrace::simulator {

using probe::SourceParticle;
using probe::Sources;

// `count` particles spread evenly across a segment of `width_mm` centred on `centre`,
// all travelling along `direction` (2D: the segment is perpendicular to it).
Sources<2> parallel_beam(glm::vec2 centre, glm::vec2 direction, float width_mm, int count,
                         uint32_t line = 0, float energy = 1.0f);
// `count` particles from one point, directions evenly spread over +-half_angle_deg
// about `direction`.
Sources<2> fan_beam(glm::vec2 origin, glm::vec2 direction, float half_angle_deg, int count,
                    uint32_t line = 0, float energy = 1.0f);
// 3D: a square bundle of count x count particles across width_mm, along `direction`.
Sources<3> parallel_beam_3d(glm::vec3 centre, glm::vec3 direction, float width_mm, int count,
                            uint32_t line = 0, float energy = 1.0f);
// 3D: a cone of directions within half_angle_deg (count x count on a polar grid).
Sources<3> fan_beam_3d(glm::vec3 origin, glm::vec3 direction, float half_angle_deg, int count,
                       uint32_t line = 0, float energy = 1.0f);

// Refuses (base::InputError, file "sources") a particle whose position, direction or
// energy is not finite, whose energy is negative or whose direction is zero.
template <int Dim>
void validate_sources(const Sources<Dim>& sources);

}  // namespace sonotrace::simulator
