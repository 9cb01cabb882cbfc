#pragma once
// The sub-resolution scatterers of channel data (imaging/channel_data.h): tissue's
// speckle as discrete points, a fixed number in each cell of a square grid fixed in the
// plane they are laid in, at uniform positions within the cell with independent Gaussian
// strengths, all drawn from a counter hash of (seed, cell, index): the same plane gives
// the same scatterers whatever region, order or thread count asks for them.
//
// A strength is N(0, 1) b(r) / sqrt(density): b the tissue's backscatter amplitude at the
// scatterer (the map's backscatter, whose square the focused mode's speckle takes as the
// scattered intensity), density the scatterers per mm^2, so that the mean scattered
// power per unit area is b^2 whatever the density. Fully developed speckle (Rayleigh
// envelope, SNR 1.91) needs several scatterers per resolution cell; the default is 10.
#include <cstdint>
#include <functional>
#include <vector>

#include <glm/glm.hpp>

#include "imaging/channel_data.h"
#include "probe/transducer.h"

namespace sonotrace::imaging {

// Parameters of the scatterers:
//   per_resolution_cell  (default 10): scatterers per lambda x axial FWHM of the pulse
//   seed                 (default 1): of their positions and strengths
struct ScattererSettings {
    double per_resolution_cell = 10.0;
    uint64_t seed = 1;
};

// The scatterers in the rectangle [lo, hi] (mm, the plane the cells are fixed in) whose
// backscatter `backscatter(r)` is positive.
std::vector<ChannelEcho> channel_scatterers(
    const probe::Transducer& t, const glm::dvec2& lo, const glm::dvec2& hi,
    const ScattererSettings& settings, const std::function<double(const glm::dvec2&)>& backscatter);

}  // namespace sonotrace::imaging
