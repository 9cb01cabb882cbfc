#pragma once
// A frame of unfocused transmits (probe/transmit.h): for each transmit the tracer carries
// the transmit's particles through the map, and its echoes become the channel data of
// every element (imaging/channel_data.h), which delay-and-sum beamforms and compounds into
// the displayed image (imaging/delay_and_sum.h). Everything the tracer does to the wave
// (reflection, refraction, shadowing, multiple bounces) is in the channels.
//
// The echoes of one transmit:
//   - reflections the tracer recorded (EchoEvent, specular and diffuse): each particle is a
//     piece of the wavefront, array length / particles wide as it left, and its reflection
//     a secondary source (lit, imaging/channel_data.h) of strength
//         a(s) (E / E_0) R ds / pitch
//     at the image point of its path (the launch point plus its time of flight at c0 along
//     its launch direction: a mirrored path images where the mirror puts it), arriving when
//     the particle did: a(s) the transmit apodization where it left, E / E_0 its two-way
//     loss (the way back repeats the way in, as in the focused mode), R the reflection's
//     amplitude (sqrt of its recorded R^2). Amplitudes add coherently, so the particles are
//     an estimator of amplitude, not of intensity: one that took stochastic choices of
//     probabilities p_i (reflect R_i^2, transmit 1 - R_i^2) stands for 1 / prod p_i of the
//     wave whose amplitude they scaled by prod sqrt(p_i), and the way back scales it by
//     prod sqrt(p_i) again; the three cancel (the focused mode's intensities keep the
//     return weight prod p_i instead). The sum of the secondary sources along a reflector
//     is the reflected wave (R times the incident, mirrored: stationary phase). For it to
//     cancel away from the mirror direction (or delay-and-sum draws the whole reflector):
//     under a diverging wave each carries 1 / sqrt(G) (spreading G: it stands for ds / G
//     of the wavefront, whose amplitude is sqrt(G) of a plane wave's); the coherent ones
//     move onto the surface their neighbours describe, below the map's staircase, the
//     particles the tracer let through without an echo are filled in between their
//     neighbours, and first reflections radiate as facets of that surface
//     (imaging/coherent_surfaces.h, ChannelEcho::Lit).
//     A rough interface's secondary sources take random phases (their sum is diffuse)
//     and the share of the reflected lobe that heads back into the receive's half-angle;
//   - scattering a particle met after a reflection (the tracer's scatter events): an
//     echo at the path's image point with a random phase (the speckle behind a mirror);
//   - point targets (point_echoes): the transmit's wave at each (probe/transmit.h) with the
//     two-way losses of the straight path from the face;
//   - the tissue's scatterers (imaging/channel_scatterers.h, the plane map's backscatter b
//     at each; their cells lie in the probe plane, so a probe that moves draws new
//     speckle, where the focused mode's field is fixed in the world), lit by the
//     transmit's intensity there relative to its free-field value:
//     the fluence the trace deposited, smoothed over a millimetre, over what the same
//     particles deposit in a lossless medium, L: the echo's amplitude takes L (sqrt(L)
//     on the way in, again on the way back). Their strength per unit area makes the
//     focused mode's scattering: n |sigma|^2 = rate x fraction x b^2 x F_rx
//     (TraceSettings::scattering_rate_per_mm, scatter_echo_fraction; the fraction returns
//     into a receive of 1 / F_rx rad).
// The image: |delay-and-sum| of all transmits at the display's pixels, over the sum of
// the receive weights and sqrt(lambda) / pitch (what a perpendicular reflector of R = 1
// sends each element), then TGC and log compression as for focused frames. Delay-and-sum
// gathers a plane reflector coherently over its Fresnel zone only, so one shows below
// 20 log10 R (R = 0.3 at 25 mm under one plane wave: -16 dB; the focused frame -12 dB).
#include "imaging/simulation.h"

namespace sonotrace::imaging {

// Particles per transmit: at least two per wavelength of the face (the secondary sources'
// sum along a reflector must not alias), more with the quality.
int particles_per_transmit(const SimulationSettings& settings);

// The frame of `settings.transmit` on the plane's map (SimulationSettings: 2D traces).
Frame simulate_channel_frame(const tissue::AcousticMap<2>& map, const PlaneGrid& grid,
                             const probe::Pose& pose, const SimulationSettings& settings,
                             const FrameProgress& progress);

}  // namespace sonotrace::imaging
