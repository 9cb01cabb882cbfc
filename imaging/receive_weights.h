#pragma once
// The receive weights of a frame's particles, from the probe's PSF table (imaging/psf.h).
#include <memory>

#include <glm/glm.hpp>

#include "probe/source_particle.h"
#include "probe/transducer.h"
#include "simulator/trace_settings.h"

namespace sonotrace::imaging {

// The receive weight of every particle of `sources` (map frame; the probe face centre at
// `face_in_map`) by its one-way time: |R|^2 at the point its path
// reaches at that time if it went on straight from launch (for a reflected or refracted
// particle, by reciprocity, where its echo seems to come from), over the energy-weighted
// mean of the same over the line's particles at that range. A reflector or tissue
// across the whole beam averages the weights to 1; a target smaller than the beam echoes
// on the lines whose receive sees it. In 3D (probe frame z = elevation) |R|^2 is times
// the lens's one-way intensity at the path's elevation (probe/elevation.h), the mean
// taken over both.
std::shared_ptr<const simulator::ReceiveWeights> receive_weights(const probe::Transducer& t,
                                                                 const probe::Sources<2>& sources,
                                                                 const glm::dvec2& face_in_map);
std::shared_ptr<const simulator::ReceiveWeights> receive_weights(const probe::Transducer& t,
                                                                 const probe::Sources<3>& sources,
                                                                 const glm::dvec3& face_in_map);

}  // namespace sonotrace::imaging
