#pragma once
// The interface events of the tracer (simulator/tracer.cpp), private to it: where a
// particle crosses a sharp transition and with which sides (Crossing), the reflection's
// angles, fractions and lobe there (Reflection, eq. 10 and 11), and the diffuse lobe's
// sampling. The code a new interaction at an interface edits; what the tracer then
// records and counts (echoes, the ledger, deposits) stays in LineTracer::decide_reflection.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "simulator/batch.h"
#include "simulator/interactions.h"
#include "simulator/interface_search.h"
#include "simulator/physics_switches.h"
#include "simulator/trace_settings.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

// Where a particle's path crosses a sharp interface: the sides in the order it meets
// them, the normal it keeps while crossing, `forward` into the far side, and the path from
// the particle to the middle of the transition, where it reflects.
template <int Dim>
struct Crossing {
    Plateau near_side, far_side;
    Vec<Dim> normal, forward;
    float to_middle_mm = 0.0f;
};

// The crossing of a particle at x moving along r, with fields t there, through `sides`
// (a sharp interface). Where the reflection happens: where the particle's own path crosses
// the transition (ln Z halfway between the plateaus), within twice the reach. The patch's
// middle lies along grad Z, which beside a wall (the side of the choroid plexus, a corner)
// points across the path: with the zone's normal facing the particle, echoes were timed
// there, up to 2 mm before the face the path meets, inside the CSF. Which way the path
// crosses: by grad Z where the particle stands, along it or against it; beside a wall (the
// path all but across grad Z) by the zone's normal, which stands for the face further on.
// A path that meets no crossing runs along the wall it is beside: it meets that wall, at
// grazing incidence, with the patch's own normal, at the middle.
template <int Dim>
Crossing<Dim> crossing_of(const InterfaceSearch<Dim>& search, const InterfaceSides<Dim>& sides,
                          const Vec<Dim>& x, const Vec<Dim>& r,
                          const tissue::AcousticTexel<Dim>& t) {
    using V = Vec<Dim>;
    const float reach_mm = float(search.plateau_steps()) * search.texel_mm();
    const V end = x + r * reach_mm;
    V towards(0.0f);
    for (int a = 0; a < Dim; ++a) towards[a] = t.grad_impedance[a];
    const float along_gradient = glm::dot(r, towards);
    auto crosses_upwards = [&](const V& normal) {
        return glm::dot(along_gradient >= 0.0f ? towards : -towards, normal) >= 0.0f;
    };
    const bool beside = std::abs(along_gradient) < 0.1f * glm::length(towards);
    const bool upwards = beside ? glm::dot(r, sides.normal) >= 0.0f : crosses_upwards(sides.normal);
    Crossing<Dim> c;
    c.near_side = upwards ? sides.low : sides.high;
    c.far_side = upwards ? sides.high : sides.low;
    c.normal = sides.normal;
    c.forward = upwards ? c.normal : -c.normal;
    const V crossing = search.halfway_point(x, end, c.near_side.impedance, c.far_side.impedance);
    c.to_middle_mm = glm::dot(crossing - x, r);
    if (crossing == end) {
        c.normal = sides.patch_normal;
        const bool into_wall = crosses_upwards(c.normal);
        c.forward = into_wall ? c.normal : -c.normal;
        c.near_side = into_wall ? sides.low : sides.high;
        c.far_side = into_wall ? sides.high : sides.low;
        const float ahead = glm::dot(sides.middle - x, c.forward);
        c.to_middle_mm = std::max(ahead, 0.0f) / std::max(glm::dot(r, c.forward), 0.1f);
    }
    return c;
}

// Whether a particle in a gas's transition, whose impedance is `z_here`, stands on the far
// side of it already (ln Z nearer the far plateau's): moving up grad Z, away from the
// gas, it is taken by crossing_of as coming out of the gas. It is leaving the transition,
// not meeting it; reflected there (R^2 = 1), it went into the gas with no decision of its
// own. Gases only: their impedance lies three orders below tissue's, so the side is never
// in doubt, where between tissues a particle deep in a wide fringe may stand nearer the
// far plateau and still be meeting the interface.
template <int Dim>
bool leaving_a_gas_transition(const InterfaceSearch<Dim>& search, const Crossing<Dim>& c,
                              float z_here) {
    if (!search.gas(c.near_side) || search.gas(c.far_side)) return false;
    const float here = std::log(std::max(z_here, 1e-12f));
    return std::abs(here - std::log(std::max(c.far_side.impedance, 1e-12f))) <
           std::abs(here - std::log(std::max(c.near_side.impedance, 1e-12f)));
}

// The fractions of the energy an interface reflects and converts into a solid's shear
// wave (0 between fluids). From the fluid side, fluid_solid_fractions at the incidence;
// from inside the solid, by reciprocity the fluid side's at the transmitted angle: the same
// longitudinal share crosses, the same shear share converts (the solid-side split of the
// rest between reflected longitudinal and shear waves is taken as the fluid side's).
struct Fractions {
    float reflected, converted;
};
inline Fractions reflected_and_converted(const TraceSettings& settings, const Plateau& near_side,
                                         const Plateau& far_side, float sin_i, float sin_t,
                                         float cos_i, float cos_t) {
    const float fluid_r2 =
        reflected_fraction(near_side.impedance, far_side.impedance, cos_i, cos_t);
    if (!settings.physics.on(Physics::shear) || settings.mode != PhysicsMode::acoustic)
        return {fluid_r2, 0.0f};
    auto speed = [](const Plateau& p) {
        return tissue::kReferenceSpeed / std::max(double(p.refractive_index), 1e-9);
    };
    const double c_near = speed(near_side), c_far = speed(far_side);
    const bool near_solid = c_near > kSolidSpeedMin, far_solid = c_far > kSolidSpeedMin;
    if (near_solid == far_solid) return {fluid_r2, 0.0f};
    const Plateau& fluid = far_solid ? near_side : far_side;
    const Plateau& solid = far_solid ? far_side : near_side;
    const double c_fluid = far_solid ? c_near : c_far, c_solid = far_solid ? c_far : c_near;
    const double sin_fluid = far_solid ? double(sin_i) : double(sin_t);
    const SolidFractions f = fluid_solid_fractions(double(fluid.impedance) / c_fluid, c_fluid,
                                                   double(solid.impedance) / c_solid, c_solid,
                                                   kShearToLongitudinalSpeed * c_solid, sin_fluid);
    return {float(f.reflected), float(f.shear)};
}

// A lobe exponent at or above this is a mirror (no lobe sampled).
constexpr float kSpecularLobe = 1e4f;

// The diffuse lobe's exponent c (eq. 11) by TraceSettings::lobe_exponent; 1e6 for a
// mirror.
inline float lobe_exponent(const TraceSettings& settings, const Plateau& near_side,
                           const Plateau& far_side, float roughness) {
    switch (settings.lobe_exponent) {
        case LobeExponent::roughness:
            return roughness <= 1e-3f ? 1e6f : 1.0f / (roughness * roughness) - 1.0f;
        case LobeExponent::reflecting_density:
            return float(settings.lobe_scale) * far_side.impedance;
        case LobeExponent::density_ratio:
            return float(settings.lobe_scale) * far_side.impedance /
                   std::max(near_side.impedance, 1e-12f);
    }
    return 1e6f;
}

// The reflection at a crossing (eq. 10 with the plateau values on both sides): the
// direction the particle had on the near plateau, the angles, the reflected and converted
// fractions and the lobe's exponent.
template <int Dim>
struct Reflection {
    Vec<Dim> incoming;
    float cos_i = 1.0f, cos_t = 1.0f;
    Fractions fractions{};
    float lobe_exponent = 1e6f;
    bool diffuse() const { return lobe_exponent < kSpecularLobe; }
    bool total() const { return cos_t == 0.0f; }  // Snell's law has no solution
};

// `index_here`: the refractive index where the particle stands, in the transition's fringe.
template <int Dim>
Reflection<Dim> reflection_at(const TraceSettings& settings, const Crossing<Dim>& c,
                              const Vec<Dim>& r, float index_here, float roughness) {
    using V = Vec<Dim>;
    Reflection<Dim> out;
    // The direction the particle had on the near plateau: undo the slight refraction it
    // met in the fringe, using the conserved n sin(theta).
    const float cos_now = glm::dot(r, c.forward);
    V tangential = (r - cos_now * c.forward) * (index_here / c.near_side.refractive_index);
    // Beyond 1 the fringe's index is not the near side's (the particle came through another
    // transition): it met the interface at grazing incidence. Kept a unit vector, or the
    // reflected particle would fly faster than its clock.
    const float tangential_length = glm::length(tangential);
    if (tangential_length > 1.0f) tangential /= tangential_length;
    const float sin_i = std::min(tangential_length, 1.0f);
    out.cos_i = std::sqrt(1.0f - sin_i * sin_i);
    out.incoming = tangential + out.cos_i * c.forward;
    const float sin_t = sin_i * c.near_side.refractive_index / c.far_side.refractive_index;
    out.cos_t = sin_t >= 1.0f ? 0.0f : std::sqrt(1.0f - sin_t * sin_t);
    out.fractions = reflected_and_converted(settings, c.near_side, c.far_side, sin_i, sin_t,
                                            out.cos_i, out.cos_t);
    out.lobe_exponent = settings.physics.on(Physics::diffuse)
                            ? lobe_exponent(settings, c.near_side, c.far_side, roughness)
                            : 1e6f;
    return out;
}

// A direction in the diffuse lobe cos^c about the specular direction `mirror`; `forward`
// points into the far medium, so a valid reflected direction has dot(dir, forward) < 0.
// `weight`: the energy the direction keeps (below 1 for TraceSettings::lobe_weight
// uniform).
template <int Dim>
Vec<Dim> sample_lobe(const Vec<Dim>& mirror, const Vec<Dim>& forward, float c,
                     LobeWeight lobe_weight, RandomStream& rs, float* weight) {
    using V = Vec<Dim>;
    auto uniform = [&rs] { return rs.next(); };
    for (int attempt = 0; attempt < 8; ++attempt) {
        V dir;
        if (lobe_weight == LobeWeight::probability) {
            if constexpr (Dim == 2)
                dir = rotate(mirror, sample_cos_power_angle_2d(c, uniform));
            else
                dir = sample_cos_power_direction_3d(mirror, c, rs.next(), rs.next());
            *weight = 1.0f;
        } else {  // uniform over the opening angle, energy weighted by cos^c
            float cos_phi;
            if constexpr (Dim == 2) {
                const float phi = (2.0f * rs.next() - 1.0f) * std::numbers::pi_v<float> / 2.0f;
                dir = rotate(mirror, phi), cos_phi = std::cos(phi);
            } else {
                dir = sample_cos_power_direction_3d(mirror, 0.0f, rs.next(), rs.next());
                cos_phi = glm::dot(dir, mirror);
            }
            *weight = std::pow(std::max(cos_phi, 0.0f), c);
        }
        if (glm::dot(dir, forward) < 0.0f) return dir;
    }
    *weight = 1.0f;
    return mirror;
}

}  // namespace
}  // namespace sonotrace::simulator::detail
