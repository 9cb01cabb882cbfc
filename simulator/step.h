#pragma once
// One step of a particle through the medium, written once over a lane type (lanes.h): the
// scalar step (tracer.cpp, one particle), the vector stage (vector_step.cpp, eight
// particles in lockstep) and the uniform runs (tracer.cpp: the stages below with a
// uniform block's constants) all call these functions, so they agree bit for bit by
// construction (tests: Tracer.VectorStepsTakeTheScalarStepsPaths,
// Tracer.UniformRunsDoWhatInterpolatedStepsDo; bench_tracer --digest across builds).
//
// What is rare is an event, handed to an `Events` object at the point of the step where
// it happens (Mitsuba 3's masks, with the rare work out of the lanes):
//
//   flush_deposits(Mask changed, const StepState& p)   the particle left its deposit texel
//   beyond_series(Mask m, F optical, F& transmitted)   exp(-optical) beyond the series
//   scatter_profile(const StepState&, F backscatter)   track-length echo and illumination
//   scattering_event(Mask m, StepState&, F backscatter)   the optical depth reached its draw
//   interface_event(Mask m, StepState&)                a steep gradient to search
//
// The scalar step's events do the work there and then (LineTracer::ScalarEvents); the
// vector stage's mark the lane for the scalar step, which then takes the whole step again
// from the state the vector stage left untouched.
#include <type_traits>

#include "simulator/batch.h"
#include "simulator/interactions.h"
#include "simulator/lanes.h"

namespace sonotrace::simulator::detail {

// A particle's state through one step (of one particle or of a lane group).
template <class Lane, int Dim>
struct StepState {
    using F = typename Lane::F;
    using I = typename Lane::I;
    using D = typename Lane::D;
    LaneVec<F, Dim> x, r;  // position (mm) and unit direction
    F E;                   // energy
    F fluence, absorbed;   // sums for the deposit texel, not yet in the maps
    F optical_depth, scatter_target;
    F previous_index;  // n sampled at the step's start (Batch::previous_index)
    I pending_texel;   // the deposit texel of the sums
    I state;           // InterfaceState
    I graded_steps;
    D time, path_length;               // s, mm
    LaneVec<F, Dim> interface_normal;  // of the interface being crossed
};

// The medium's fields at the step's start (AcousticTexel's) and its deposit texel.
template <class Lane, int Dim>
struct StepFields {
    using F = typename Lane::F;
    F refractive_index, impedance, attenuation, backscatter;
    LaneVec<F, Dim> grad_refractive_index, grad_impedance;
    typename Lane::I texel;  // read only with StepConstants::deposition_maps
};

// What a step adds to the echo profile (EchoProfileSettings): to the illumination E s w
// and to the scattered intensity E s b^2 w, with s the profile's scale, b the backscatter
// and w = (E / E0) x return factor x receive weight the way back; in this order of
// operations wherever a step is taken (the same bits).
template <class Lane>
struct ProfileTerms {
    typename Lane::F lit, scattered;
};
template <class Lane>
SONOTRACE_LANE_INLINE ProfileTerms<Lane> profile_terms(const typename Lane::F& E,
                                                       const typename Lane::F& initial_energy,
                                                       const typename Lane::F& return_factor,
                                                       const typename Lane::F& receive,
                                                       const typename Lane::F& backscatter,
                                                       float scale) {
    using F = typename Lane::F;
    const F scattered = scale * backscatter * backscatter;
    const F two_way = E / initial_energy * return_factor;
    return {E * scale * two_way * receive, E * scattered * two_way * receive};
}

// -- the stages, in the order of a step

// Deposits of the step go to the texel the particle is in: the sums of the old one are
// handed over when it changes.
template <class Lane, int Dim, class Events>
SONOTRACE_LANE_INLINE void enter_deposit_texel(StepState<Lane, Dim>& p,
                                               const typename Lane::I& texel, Events& events) {
    using F = typename Lane::F;
    const auto changed = texel != p.pending_texel;
    events.flush_deposits(changed, p);
    p.fluence = select(changed, F{}, p.fluence);
    p.absorbed = select(changed, F{}, p.absorbed);
    p.pending_texel = texel;
}

// The fraction of the energy absorbed over one step in a medium of `attenuation`
// (dB/(cm MHz)): 1 - exp(-alpha f s).
template <class Lane, int Dim, class Events, class F = typename Lane::F>
SONOTRACE_LANE_INLINE F absorbed_fraction(const F& attenuation, const StepConstants<Dim>& c,
                                          Events& events) {
    const F optical = c.attenuation_per_mm * attenuation * c.step_mm;
    F transmitted = exp_minus_series(optical);
    const auto absorbs = attenuation > 0.0f;
    events.beyond_series(absorbs & (optical > kExpSeries7Below), optical, transmitted);
    return select(absorbs, 1.0f - transmitted, F{});
}

template <class Lane, int Dim, class F = typename Lane::F>
SONOTRACE_LANE_INLINE void absorb(StepState<Lane, Dim>& p, const F& fraction) {
    const F lost = p.E * fraction;
    p.E = p.E - lost;
    p.absorbed = p.absorbed + lost;
}

// Fluence: energy times path length, after the step's absorption.
template <class Lane, int Dim>
SONOTRACE_LANE_INLINE void add_fluence(StepState<Lane, Dim>& p, float step_mm) {
    p.fluence = p.fluence + p.E * step_mm;
}

// The optical depth of sub-resolution scattering one step adds (zero where nothing
// scatters).
template <class Lane, int Dim, class F = typename Lane::F>
SONOTRACE_LANE_INLINE F scatter_increment(const F& backscatter, const StepConstants<Dim>& c) {
    return select(backscatter > 0.0f, c.scattering_rate_per_mm * backscatter * c.step_mm, F{});
}

// The step's time: path length over the local speed, n / c0 per mm.
template <class Lane, int Dim, class F = typename Lane::F>
SONOTRACE_LANE_INLINE typename Lane::D step_time(const F& refractive_index,
                                                 const StepConstants<Dim>& c) {
    return c.step_time_per_index * Lane::widen(refractive_index);
}

template <class Lane, int Dim>
SONOTRACE_LANE_INLINE void move(StepState<Lane, Dim>& p, float step_mm,
                                const typename Lane::D& time) {
    for (std::size_t a = 0; a < std::size_t(Dim); ++a) p.x[a] = p.x[a] + step_mm * p.r[a];
    p.time = p.time + time;
    p.path_length = p.path_length + double(step_mm);
}

// Inside the map's domain [0, extent] on every axis (tissue::AcousticMap::inside). One
// particle leaves at the first axis outside: the test guards every uniform step, and the
// branches are cheaper there than combining all comparisons.
template <class Lane, int Dim>
SONOTRACE_LANE_INLINE typename Lane::Mask inside_domain(const LaneVec<typename Lane::F, Dim>& x,
                                                        const StepConstants<Dim>& c) {
    if constexpr (std::is_same_v<typename Lane::Mask, bool>) {
        for (std::size_t a = 0; a < std::size_t(Dim); ++a)
            if (!(x[a] >= 0.0f && x[a] <= c.extent[a])) return false;
        return true;
    } else {
        typename Lane::Mask inside = (x[0] >= 0.0f) & (x[0] <= c.extent[0]);
        for (std::size_t a = 1; a < std::size_t(Dim); ++a)
            inside = inside & (x[a] >= 0.0f) & (x[a] <= c.extent[a]);
        return inside;
    }
}

// The general step: deposits, absorption, scattering, the interface test, refraction
// (eqs. 4-8 corrected, interactions.h), the move.
template <class Lane, int Dim, class Events>
SONOTRACE_LANE_INLINE void take_step(StepState<Lane, Dim>& p, const StepFields<Lane, Dim>& f,
                                     const StepConstants<Dim>& c, Events& events) {
    using F = typename Lane::F;
    using I = typename Lane::I;
    const float s = c.step_mm;
    if (c.deposition_maps) enter_deposit_texel(p, f.texel, events);
    if (c.attenuation) absorb(p, absorbed_fraction<Lane>(f.attenuation, c, events));
    add_fluence(p, s);

    // -- sub-resolution scattering: an event when the optical depth reaches the draw
    if (c.scattering) {
        events.scatter_profile(p, f.backscatter);
        p.optical_depth = p.optical_depth + scatter_increment<Lane>(f.backscatter, c);
        events.scattering_event((f.backscatter > 0.0f) & (p.optical_depth >= p.scatter_target), p,
                                f.backscatter);
    }

    // -- interface: a steep impedance gradient (|grad Z| h / Z above the threshold,
    // squared: no root or division) met from outside, or graded for a while, is searched
    // for a sharp interface, which is crossed as a whole (one decision, one normal).
    const F gz2 = dot(f.grad_impedance, f.grad_impedance);
    const F scale2 = f.impedance * f.impedance * c.inverse_texel2;
    const auto steep = gz2 > c.threshold2 * scale2;
    const auto graded = p.state == int32_t(kGraded);
    const I next_graded = p.graded_steps + 1;
    const auto search =
        steep & ((p.state == int32_t(kOutside)) | (graded & (next_graded >= kGradedRecheckSteps)));
    p.graded_steps = select(steep & graded, next_graded, p.graded_steps);
    // hysteresis: the fringe's jitter does not re-trigger
    const auto calm = Lane::andnot(gz2 < 0.25f * c.threshold2 * scale2, steep);
    p.state = select(calm, I{} + int32_t(kOutside), p.state);
    events.interface_event(search, p);

    // -- continuous refraction (eqs. 4-8 corrected)
    // Eq. 4 extrapolates the index beyond the step from the gradient, n1 = n0 + s g.r.
    // Summed over a crossing that drifts from the field: central differences spread the
    // gradient a texel beyond the sampled change, and the estimate is taken along the
    // direction before bending. Measured on a 20-degree interface: ~1 degree off Snell's
    // law; in the graded fibre of figure 4, particles escaped. So the index is *sampled*:
    // the step just taken went from n0 (sampled at its start) to n1 (sampled here), and
    // Snell's law turns the direction here. The chain n0 -> n1 -> ... follows the field
    // exactly, at one sample per step. The gradient gives the normal, as in the paper (at
    // a sharp interface: the patch normal, see LineTracer::interface_normal).
    const F n0 = p.previous_index, n1 = f.refractive_index;
    p.previous_index = n1;
    if (c.refraction) {
        const auto crossing = p.state == int32_t(kCrossing);
        const F g2 = dot(f.grad_refractive_index, f.grad_refractive_index);
        // A reflected particle leaves on the near side unrefracted.
        const auto bends = Lane::andnot(n0 != n1, p.state == int32_t(kLeavingAfterReflection)) &
                           (crossing | (g2 > 0.0f));
        if (Lane::any(bends)) {  // skips the root, division and Snell's law where none bends
            const F inverse_length = 1.0f / Lane::sqrt(g2);  // inf where g2 = 0: not selected
            LaneVec<F, Dim> normal;
            for (std::size_t a = 0; a < std::size_t(Dim); ++a)
                normal[a] = select(crossing, p.interface_normal[a],
                                   f.grad_refractive_index[a] * inverse_length);
            const LaneRefraction<Lane, Dim> bent = refract<Lane, Dim>(p.r, normal, n0 / n1);
            p.r = select(bends, bent.direction, p.r);
            // No solution is the ray's turning point in a graded medium (the fibre's
            // particles turn at every period): the particle stays on the n0 side. Inside
            // a sharp crossing too: the interface's one decision was to transmit (total
            // reflection there is decide_reflection's bounce), so a turn means the index
            // changes off the interface normal (bone's own texture, or a smoothed soft
            // side); the crossing ends and the field's gradient bends from there. Were it
            // a bounce, the fixed normal would turn the particle at every step and the
            // bounce limit would end it after a distance set by the step length.
            const auto turns = bends & bent.total_reflection;
            p.previous_index = select(turns, n0, n1);
            const auto ends_crossing = turns & crossing;
            p.state = select(ends_crossing, I{} + int32_t(kGraded), p.state);
            p.graded_steps = select(ends_crossing, I{}, p.graded_steps);
        }
    }
    move(p, s, step_time<Lane>(n1, c));
}

// One particle's state from lane k of the batch, and back (the scalar step's).
template <int Dim>
StepState<ScalarLane, Dim> load_state(const Batch<Dim>& b, int k) {
    const auto i = std::size_t(k);
    StepState<ScalarLane, Dim> p;
    for (std::size_t a = 0; a < Dim; ++a) {
        p.x[a] = b.position.axis[a][i];
        p.r[a] = b.direction.axis[a][i];
        p.interface_normal[a] = b.interface_normal.axis[a][i];
    }
    p.E = b.energy[i];
    p.fluence = b.pending_fluence[i], p.absorbed = b.pending_absorbed[i];
    p.optical_depth = b.optical_depth[i], p.scatter_target = b.scatter_target[i];
    p.previous_index = b.previous_index[i];
    p.pending_texel = int32_t(b.pending_texel[i]);
    p.state = int32_t(b.in_interface[i]);
    p.graded_steps = b.graded_steps[i];
    p.time = b.time[i], p.path_length = b.path_length[i];
    return p;
}
template <int Dim>
void store_state(Batch<Dim>& b, int k, const StepState<ScalarLane, Dim>& p) {
    const auto i = std::size_t(k);
    for (std::size_t a = 0; a < Dim; ++a) {
        b.position.axis[a][i] = p.x[a];
        b.direction.axis[a][i] = p.r[a];
        b.interface_normal.axis[a][i] = p.interface_normal[a];
    }
    b.energy[i] = p.E;
    b.pending_fluence[i] = p.fluence, b.pending_absorbed[i] = p.absorbed;
    b.optical_depth[i] = p.optical_depth, b.scatter_target[i] = p.scatter_target;
    b.previous_index[i] = p.previous_index;
    b.pending_texel[i] = uint32_t(p.pending_texel);
    b.in_interface[i] = InterfaceState(p.state);
    b.graded_steps[i] = p.graded_steps;
    b.time[i] = p.time, b.path_length[i] = p.path_length;
}

}  // namespace sonotrace::simulator::detail
