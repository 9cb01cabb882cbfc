#pragma once
// Resampling a volume onto another grid: arbitrary planes (a probe's image plane) and
// oriented sub-volumes, at a resolution independent of the source voxel size.
//
// A probe-aligned grid has index i along the lateral axis, j along the beam (depth) and
// k along the elevation axis; (lateral, axial, elevation) is right-handed. Extents are
// rounded to whole pixels n = round(extent / h). Pixel centres sit at lateral
// (i - (nx-1)/2) * h (symmetric about the beam axis), depth (j + 1/2) * h from the probe
// face, and elevation (k - (nz-1)/2) * h.
#include <glm/glm.hpp>

#include "tissue/volume.h"

namespace sonotrace::tissue {

// A rigid world-space frame: the centre of the probe face and unit axes.
struct ProbeFrame {
    glm::dvec3 origin{0.0};             // mm
    glm::dvec3 lateral{1.0, 0.0, 0.0};  // unit, along the array
    glm::dvec3 axial{0.0, 1.0, 0.0};    // unit, along the beam into the tissue
    glm::dvec3 elevation() const { return glm::cross(lateral, axial); }
};

struct GridExtent {
    double width_mm = 100.0;    // lateral extent, centred on the probe
    double depth_mm = 100.0;    // from the probe face
    double elevation_mm = 0.0;  // 0 for a single plane; centred on the image plane
    double pixel_mm = 0.25;     // isotropic sample spacing
};

// Geometry of the probe-aligned grid (nz == 1 when elevation_mm <= pixel_mm).
// Throws base::InputError(source, field) when the extent or frame is unusable.
VolumeGeometry probe_grid(const ProbeFrame& frame, const GridExtent& extent,
                          const std::string& source);

enum class Interpolation { trilinear, nearest };

// Samples `volume` at every voxel centre of `target`. Points outside the volume take
// `outside`. Parallel over rows; the result does not depend on the thread count.
Volume resample(const Volume& volume, const VolumeGeometry& target, Interpolation interpolation,
                float outside);

}  // namespace sonotrace::tissue
