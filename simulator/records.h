#pragma once
// What a trace produces: echo events, energy maps, optional paths, an energy ledger.
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "tissue/volume.h"

namespace sonotrace::simulator {

enum class EchoKind : uint8_t {
    specular,           // reflection at an interface (weight = R^2)
    diffuse,            // reflection at a rough interface (weight = R^2)
    scatter,            // sub-resolution scattering (weight = scatter_echo_fraction * backscatter)
    returned_to_probe,  // the particle itself came back through the probe face
};
const char* to_string(EchoKind kind);

template <int Dim>
struct EchoEvent {
    uint32_t line = 0;
    uint32_t particle = 0;          // index within its line
    float time_s = 0.0f;            // one-way time of flight to the event
    float energy = 0.0f;            // particle energy arriving at the event
    float weight = 0.0f;            // fraction of that energy sent back towards the probe
    glm::vec<Dim, float> position;  // mm, map frame
    uint16_t bounces = 0;           // reflections before this event
    EchoKind kind = EchoKind::scatter;
    // Of those reflections, the ones whose direction was drawn from a rough lobe (at most
    // 255): after one, the particle's phase is no longer the transmit's.
    uint8_t rough_bounces = 0;
    // Reflections: cosine of the incidence angle and the exponent c of the lobe cos^c
    // about the mirror direction (>= 1e4: a mirror), from which a receiver estimates how
    // much of the reflected energy heads back the way the particle came.
    float cos_incidence = 1.0f;
    float lobe_exponent = 1e6f;
    // Monostatic receive: the probabilities of the particle's stochastic choices before
    // the event (tracer.cpp, Batch::return_factor), which the echo's way back repeats.
    float return_weight = 1.0f;
    // Reflections: the interface's unit normal, facing the side the particle came from
    // (zero for other kinds): the image's plane response needs the reflector's tilt.
    glm::vec<Dim, float> normal{0.0f};
    // The particle's unit direction arriving at the event (zero if unknown): against its
    // launch direction, how far refraction has turned its piece of the beam.
    glm::vec<Dim, float> direction{0.0f};
    bool operator==(const EchoEvent&) const = default;  // field-wise: padding is indeterminate
};

template <int Dim>
struct PathVertex {
    glm::vec<Dim, float> position;  // mm, map frame
    float energy;
};

template <int Dim>
struct Path {
    uint32_t line = 0, particle = 0;
    std::vector<PathVertex<Dim>> vertices;
};

// Where the injected energy went. Russian roulette is unbiased but not conserving in a
// single run, so its killed and added energy are booked separately:
// injected = absorbed + escaped + recorded + remaining + roulette_killed - roulette_added.
struct EnergyLedger {
    double injected = 0.0;
    double absorbed = 0.0;   // attenuation (and lossy diffuse reflection)
    double escaped = 0.0;    // left through the domain boundary
    double recorded = 0.0;   // removed as echoes (scattering, capture at the probe face)
    double remaining = 0.0;  // alive when the path length or bounce limit ended it
    double roulette_killed = 0.0;
    double roulette_added = 0.0;

    double accounted() const {
        return absorbed + escaped + recorded + remaining + roulette_killed - roulette_added;
    }
    double relative_error() const {
        return injected > 0 ? (accounted() - injected) / injected : 0.0;
    }
    EnergyLedger& operator+=(const EnergyLedger& o);
};

struct TraceStats {
    uint64_t particles = 0;
    uint64_t steps = 0;
    uint64_t uniform_steps = 0;  // steps in a uniform block (AcousticMap::uniform_block)
    uint64_t vector_steps = 0;   // steps the vector stage took (TraceSettings::vector_steps)
    uint64_t interface_events = 0;
    uint64_t reflections = 0;
    uint64_t total_reflections = 0;
    uint64_t scatter_events = 0;
    uint64_t captured = 0;
    TraceStats& operator+=(const TraceStats& o);
};

// Track-length scatter echo per line and echo-time bin (TraceSettings::echo_profile).
template <int Dim>
struct EchoProfile {
    int lines = 0, bins = 0;
    double bin_s = 0.0;
    // The tracer's full step (mm): each step's terms sit in the bin of its start, though it
    // scatters all along its length, so a profile of equal steps is a comb of their
    // period that the image spreads over the step (imaging::spread_over_step).
    double step_mm = 0.0;
    std::vector<float> intensity;  // [line * bins + bin], energy units
    // The same sum without the backscatter^2, over every step: the energy that lights the
    // bin's tissue, whatever scatters it (the image lights each point of the beam by it
    // times the backscatter^2 there). Empty if the trace did not make it.
    std::vector<float> illumination;
    std::vector<glm::vec<Dim, float>> illuminated_position;  // illumination-weighted mean
    std::vector<glm::vec<Dim, float>> position;  // intensity-weighted mean position (mm, map)
    float at(int line, int bin) const { return intensity[std::size_t(line) * bins + bin]; }
};

template <int Dim>
struct TraceResult {
    std::vector<EchoEvent<Dim>> echoes;  // by line, then particle, then time of the event
    // Empty unless TraceSettings::deposition_maps.
    tissue::Volume fluence;   // sum of energy * step length per texel / texel area: intensity
    tissue::Volume absorbed;  // energy absorbed per texel: the deposition map
    std::vector<Path<Dim>> paths;
    std::vector<double> ring_profile;  // energy per ring bin, if a ring detector was set
    EchoProfile<Dim> echo_profile;     // lines = highest line id + 1, if requested
    EnergyLedger ledger;
    TraceStats stats;
};

}  // namespace sonotrace::simulator
