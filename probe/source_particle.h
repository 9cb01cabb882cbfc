#pragma once
// A particle as a source emits it: the contract between the probe (which makes beams)
// and the tracer (which integrates them). Sources are plain lists of these.
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

namespace sonotrace::probe {

template <int Dim>
struct SourceParticle {
    glm::vec<Dim, float> position;   // mm, map frame
    glm::vec<Dim, float> direction;  // unit
    float energy = 1.0f;
    uint32_t line = 0;  // scan line that emitted it
    // Transmit focusing delay (s): the time the particle's clock starts at, <= 0 for
    // elements that fire before the centre one, so the beam's particles reach the focus
    // together. Echo times include it, as the receive delays of a real scanner would.
    float time_s = 0.0f;
};

template <int Dim>
using Sources = std::vector<SourceParticle<Dim>>;

}  // namespace sonotrace::probe
