#include "tissue/resample.h"

#include <tbb/parallel_for.h>

#include <cmath>

#include "tissue/base/error.h"

namespace sonotrace::tissue {

VolumeGeometry probe_grid(const ProbeFrame& frame, const GridExtent& extent,
                          const std::string& source) {
    auto positive = [&](double v, const char* field) {
        if (!(std::isfinite(v) && v > 0.0)) {
            throw base::InputError(source, field,
                                   "must be a positive number of mm, got " + base::number_text(v));
        }
    };
    positive(extent.width_mm, "width");
    positive(extent.depth_mm, "depth");
    positive(extent.pixel_mm, "resolution");
    if (!(std::isfinite(extent.elevation_mm) && extent.elevation_mm >= 0.0)) {
        throw base::InputError(source, "elevation", "must be zero or a positive number of mm");
    }
    const double ll = glm::length(frame.lateral), la = glm::length(frame.axial);
    if (std::abs(ll - 1.0) > 1e-6 || std::abs(la - 1.0) > 1e-6 ||
        std::abs(glm::dot(frame.lateral, frame.axial)) > 1e-6) {
        throw base::InputError(source, "pose", "lateral and axial axes must be orthonormal");
    }
    VolumeGeometry g;
    const double h = extent.pixel_mm;
    for (double length : {extent.width_mm, extent.depth_mm, extent.elevation_mm}) {
        if (length / h > 1e8) {
            throw base::InputError(source, "dims",
                                   "the grid would need more than 1e8 samples per axis "
                                   "(memory); increase the resolution value");
        }
    }
    // An acoustic map needs two samples per axis of the plane (gradients, interpolation).
    if (std::round(extent.width_mm / h) < 2.0 || std::round(extent.depth_mm / h) < 2.0) {
        throw base::InputError(
            source, extent.width_mm < extent.depth_mm ? "width" : "depth",
            "the plane needs at least 2 samples along each axis: width and depth "
            "at least twice the resolution (" +
                base::number_text(h) + " mm)");
    }
    g.dims = glm::ivec3(std::max(1.0, std::round(extent.width_mm / h)),
                        std::max(1.0, std::round(extent.depth_mm / h)),
                        std::max(1.0, std::round(extent.elevation_mm / h)));
    g.spacing = glm::dvec3(h);
    g.direction = glm::dmat3(frame.lateral, frame.axial, frame.elevation());
    // Centre the lateral and elevation extents on the beam axis; depth starts at the face.
    g.origin = frame.origin + frame.lateral * (-0.5 * (g.dims.x - 1) * h) +
               frame.axial * (0.5 * h) + frame.elevation() * (-0.5 * (g.dims.z - 1) * h);
    g.validate(source);
    return g;
}

Volume resample(const Volume& volume, const VolumeGeometry& target, Interpolation interpolation,
                float outside) {
    Volume out(target);
    const VolumeGeometry& src = volume.geometry();
    // target index -> source index is affine: p_src = M * p_tgt + b.
    const glm::dmat3 to_src_index = glm::inverse(src.linear()) * target.linear();
    const glm::dvec3 b = src.world_to_index(target.origin);
    const glm::ivec3 n = target.dims;
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        for (int i = 0; i < n.x; ++i) {
            const glm::dvec3 p = to_src_index * glm::dvec3(i, j, k) + b;
            out.at(i, j, k) = interpolation == Interpolation::trilinear
                                  ? volume.sample_trilinear(p, outside)
                                  : volume.sample_nearest(p, outside);
        }
    });
    return out;
}

}  // namespace sonotrace::tissue
