#pragma once
// Echoes drawn as clutter: those of paths that took a rough reflection, and a rough
// interface's own echo met off the beam (after mirror-like bounces, or turned by
// refraction beyond the beam's angular width) where such echoes are too sparse to image
// themselves (rough_echo_after_mirrors, rough_echo_turned_off_the_beam, sparse_echoes);
// gathered into a smooth mean intensity and drawn as speckle of that mean.
//
// A particle reflected into a rough lobe leaves in a direction drawn at random: its phase
// is no longer the transmit's, and what it meets afterwards echoes incoherently. A rough
// interface's backscatter (EchoKind::diffuse) is itself a sum over its patch's random
// heights. Met directly, every particle of a line meets the interface, and their pulses
// interfere as the skull's bright band; after a mirror-like bounce off the curved skull
// one particle of a line may meet it, its pulse alone in the image. The few particles of
// a line that take such paths are a sparse sample of a diffuse field; drawn each as one
// coherent pulse at its line and time, a single path stood 15-49 dB above the brain
// around it (the transtemporal view's lone spots: docs/guide/simulate.md). Their
// intensities are estimated instead by adaptive kernel density estimation (the
// sample-point estimator, Terrell & Scott 1992): each echo's intensity spread by a
// Gaussian in the image plane whose sigma is half the distance to its k-th nearest such
// echo of another path, within [min_sigma_mm, max_sigma_mm] (a path met by several
// interfaces leaves a cluster of echoes on its own line, which says nothing of how
// densely such paths are sampled). Where the paths are dense the kernels are
// narrow (down to the pulse's and beam's scale), where they are sparse wide; each echo's
// kernel is normalised over the lines and samples it reaches, so the total intensity is
// kept. As the particle count grows the kernels shrink and the estimate converges to the
// echoes' expected intensity. Rough echoes after mirrors whose kernel would be the
// narrowest anyway (k echoes of other paths within 2 min_sigma_mm) stay pulses: their
// paths image themselves, as a rough wire's ghost in a flat mirror does, sharp
// (validate --case mirror_image).
#include <cmath>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "imaging/bmode.h"
#include "probe/transducer.h"
#include "simulator/records.h"

namespace sonotrace::imaging {

// Echoes of paths that took a rough reflection: always clutter.
inline bool after_a_rough_reflection(const simulator::EchoEvent<2>& e) {
    return e.rough_bounces > 0;
}
// A rough interface's echo after mirror-like reflections only: clutter where sparse.
inline bool rough_echo_after_mirrors(const simulator::EchoEvent<2>& e) {
    return e.bounces > 0 && e.rough_bounces == 0 && e.kind == simulator::EchoKind::diffuse;
}
// A rough interface's echo met directly by a particle that refraction turned from its
// launch direction `launch` (unit) by more than the beam's full angular width (twice
// `receive_half_angle_rad`, the receive's half-angle at the echo's range): no part of the
// beam travels that way, and its piece of the wavefront left it. Clutter where sparse, as
// after a mirror, if also shown far from where it happened (shown_far_from_its_event).
// (Turns beyond the half-angle alone are common behind the skull: spreading them all
// lightened the temporal ventricles by 2.5-3.5 dB.)
inline bool rough_echo_turned_off_the_beam(const simulator::EchoEvent<2>& e, glm::vec2 launch,
                                           double receive_half_angle_rad) {
    if (e.bounces > 0 || e.rough_bounces > 0 || e.kind != simulator::EchoKind::diffuse)
        return false;
    const float length = glm::length(e.direction);
    return length > 0.0f &&
           double(glm::dot(e.direction, launch)) < std::cos(2.0 * receive_half_angle_rad) * length;
}

struct IncoherentEcho {
    int line = 0;
    double range_mm = 0.0;   // along the line, where its time places it (c0 t / 2)
    double intensity = 0.0;  // as a coherent echo of this intensity would carry
    uint32_t particle = 0;   // within its line: one path's echoes are not each other's neighbours
};

// Why these defaults (bench/frame_spots.py on the head views; docs/log has the table):
// wider kernels removed a few more spots but spread the clutter into the ventricles,
// whose contrast the craniotomy view must keep at 20 dB.
struct IncoherentSpread {
    int neighbours = 16;        // k: the kernel's width follows the k-th nearest echo
    double min_sigma_mm = 1.0;  // about the pulse's length and the beam's width
    double max_sigma_mm = 2.5;  // a lone echo is spread over about +-5 mm
    double bin_mm = 0.5;        // the mean is gathered in range bins this long
};

// Whether an echo shown `displacement_mm` from where it happened lies beyond the reach of a
// lone echo's kernel (3 max_sigma_mm): spread there, it would not touch its interface. The
// skull under the temporal window, met near its critical angle, sent one particle 30 mm
// along the bone, whose echo stood 15-17 dB above the brain 32 mm from it; the bone at a
// craniotomy's rim, met through its edge, echoes 5-10 mm from where it lies, and spread,
// lit the brain beside it 17 dB above its surroundings.
inline bool shown_far_from_its_event(double displacement_mm, const IncoherentSpread& spread = {}) {
    return displacement_mm > 3.0 * spread.max_sigma_mm;
}

// The mean intensity per line and RF sample of `layout` (lines x samples, row-major, per
// sample: the intensity a coherent echo puts into one sample bin), each echo spread as
// described above.
std::vector<float> incoherent_intensity(const probe::ScanGeometry& geometry, const LineData& layout,
                                        const std::vector<IncoherentEcho>& echoes,
                                        const IncoherentSpread& spread = {});

// For each of `echoes`, whether it is sparse: its kernel (above) would be wider than
// spread.min_sigma_mm, i.e. fewer than spread.neighbours echoes of other paths among
// `echoes` lie within 2 min_sigma_mm of it.
std::vector<uint8_t> sparse_echoes(const probe::ScanGeometry& geometry,
                                   const std::vector<IncoherentEcho>& echoes,
                                   const IncoherentSpread& spread = {});

// Adds speckle of mean intensity `mean` (as incoherent_intensity gives it) to the
// in-phase and quadrature scatterer sums that synthesize_rf convolves with the pulse:
// circular Gaussian numbers (a function of seed, line and sample) correlated across lines
// as speckle is across a beam (a Gaussian of the receive beam's width, lambda times the
// receive F-number at the range, FWHM), of variance mean / 2 each.
void add_incoherent_speckle(const std::vector<float>& mean, const LineData& layout,
                            const probe::Transducer& t, const probe::ScanGeometry& geometry,
                            uint64_t seed, float* in_phase, float* quadrature);

}  // namespace sonotrace::imaging
