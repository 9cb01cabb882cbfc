#pragma once
// Volumes and transfer functions the PBVR tests render (test_pbvr*.cpp).
#include <functional>

#include <glm/glm.hpp>

#include "imaging/pbvr/colour_tf.h"
#include "tissue/volume.h"

namespace sonotrace::imaging::pbvr {

inline tissue::Volume make_volume(glm::ivec3 dims, double spacing,
                                  const std::function<float(int, int, int)>& value) {
    tissue::VolumeGeometry g;
    g.dims = dims;
    g.spacing = glm::dvec3(spacing);
    tissue::Volume v(g);
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) v.at(i, j, k) = value(i, j, k);
    return v;
}

// Opacity per mm rising linearly over 0..1 up to `top`; colour from dark to white.
inline ColourTransferFunction ramp(double top) {
    return ColourTransferFunction(
        "ramp", "test", {{0.0, glm::vec3(0.1f), 0.0}, {1.0, glm::vec3(1.0f), top}}, 1.0, 0.0, 1.0);
}

}  // namespace sonotrace::imaging::pbvr
