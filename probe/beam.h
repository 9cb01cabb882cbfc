#pragma once
// Beams of particles from a transducer: one beam per scan line, shaped by the active
// aperture, its apodization and the transmit focus.
//
// Each particle leaves a point of the active aperture, drawn from the Hann apodization,
// and travels straight towards the focal point displaced sideways by an aim offset drawn
// from a Gaussian: the beam converges to a focal waist and diverges after it. The
// particles carry the beam's energy through the tissue (refraction, reflection,
// attenuation, shadowing); the image's lateral resolution does not come from their
// spread but from the aperture's two-way field (probe/aperture.h), applied to their
// echoes by the image formation. The waist only keeps the energy where the beam goes:
// its width is lambda * F-number (FWHM of the two-way amplitude at the focus).
//
// Transmit delays start each particle's clock so that all reach the focus together
// (focal time = focus / c0); the monostatic echo time 2t then places the focus at its
// depth. Both draws are stratified over the line's particles and jittered by a
// counter-based hash of (seed, line, particle): the same inputs give the same beams.
#include <cstdint>

#include "probe/source_particle.h"
#include "probe/transducer.h"

namespace sonotrace::probe {

struct BeamSettings {
    int particles_per_line = 64;
    uint64_t seed = 1;
};

// Sigma (mm) of the aim-offset Gaussian at the focus for an aperture of `aperture_mm`.
double focal_sigma_mm(const Transducer& t, double aperture_mm);

// The beams of every scan line in the probe plane, shifted by `to_map` into the
// tracer's map frame (map = probe plane + to_map). Line ids are 0..lines-1; energy 1 per
// line.
Sources<2> make_beams(const Transducer& t, const BeamSettings& settings, const glm::dvec2& to_map);
// The same beams in 3D, in the probe frame x lateral, y axial, z elevation shifted by
// `to_map`. Each particle starts where its make_beams twin does in the scan plane (z = 0
// there), with the same in-plane heading; it also leaves a height z drawn uniformly over
// the elements' height (Transducer::elevation_aperture_mm) and aims at a point drawn from
// a Gaussian whose FWHM is the slice thickness at the elevation focus, so the beam's
// elevation profile narrows to the slice thickness there. Its clock is its twin's less the
// lens's extra path sqrt(F_e^2 + z^2) - F_e.
Sources<3> make_beams_3d(const Transducer& t, const BeamSettings& settings,
                         const glm::dvec3& to_map);

// Inverse CDF of the Hann (raised-cosine) density 1 - cos(2 pi v) on [0, 1].
double hann_inverse_cdf(double u);
// Inverse CDF of the standard normal distribution, u in (0, 1).
double normal_inverse_cdf(double u);

}  // namespace sonotrace::probe
