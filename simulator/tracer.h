#pragma once
// The particle integrator of Reis & Bertram, in 2D and 3D (one template).
//
// Each step of length s at position x with direction r:
//   1. sample the map (bi/trilinear): refractive index n and its gradient, impedance Z
//      and its gradient, attenuation, backscatter, roughness;
//   2. absorb: E *= exp(-a s) with a the intensity attenuation alpha*f (Np/mm);
//   3. scatter (acoustic mode): when the accumulated optical depth of sub-resolution
//      scatterers reaches an exponential draw, a scattering echo takes its fraction;
//   4. interface: where |grad Z| h / Z exceeds the threshold and the particle is not
//      already crossing, the plateaus on both sides are found by marching along the
//      normal. If both exist (a sharp interface) the normal is the gradient summed over
//      a patch of the transition, an echo with weight R^2 (eq. 10, oblique incidence)
//      is recorded (the monostatic expectation), and the particle reflects with
//      probability R^2 keeping its energy (unbiased), specularly or into the cos^c
//      lobe (eq. 11). Otherwise the medium is graded and only refraction acts;
//   5. refract (eqs. 5-8, corrected): Snell's law between the index sampled at the
//      previous step and the one sampled here (not eq. 4's extrapolation, see
//      tracer.cpp), about the gradient normal (at a sharp interface: the patch
//      normal); total reflection when sin(theta_t) would exceed 1;
//   6. move: x += s r, time of flight += s n / c0, path length += s;
//   7. leave through the domain boundary (perfectly absorbing), the probe face
//      (captured), or by Russian roulette / path and bounce limits.
//
// Why interfaces are decided as a whole: a smooth transition split into k steps has
// per-step reflectances of order (dZ/2Z/k)^2, whose sum vanishes as k grows; deciding
// per step would make reflection depend on the step size and the smoothing width.
//
// Threads take whole scan lines; random numbers come from Philox keyed by (seed, line,
// particle, event); deposit maps accumulate in 64-bit fixed point (integer addition is
// associative), so results are byte-identical on any thread count.
#include <functional>

#include "simulator/records.h"
#include "simulator/sources.h"
#include "simulator/trace_settings.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::simulator {

// Called from worker threads after each finished line with (lines done, lines total).
using TraceProgress = std::function<void(std::size_t, std::size_t)>;

// Throws base::InputError("sources" / settings source, field) on invalid input.
template <int Dim>
TraceResult<Dim> trace(const tissue::AcousticMap<Dim>& map, const Sources<Dim>& sources,
                       const TraceSettings& settings, const TraceProgress& progress = {});

extern template TraceResult<2> trace<2>(const tissue::AcousticMap<2>&, const Sources<2>&,
                                        const TraceSettings&, const TraceProgress&);
extern template TraceResult<3> trace<3>(const tissue::AcousticMap<3>&, const Sources<3>&,
                                        const TraceSettings&, const TraceProgress&);

}  // namespace sonotrace::simulator
