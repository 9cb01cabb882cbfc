#pragma once
// What the particle renderer's files share (pbvr.cpp: particles, images; occlusion.cpp;
// pbvr_mesh.cpp: tetrahedral meshes): the sub-pixels a footprint covers and a mesh
// layer's data. Private to imaging/pbvr.
#include <algorithm>
#include <vector>

#include "imaging/pbvr/pbvr.h"
#include "imaging/pbvr/preintegration.h"
#include "tissue/base/fast_math.h"

namespace sonotrace::imaging::pbvr {

// The sub-pixels [first, last] of a buffer row `size` wide whose centres (index + 1/2) lie
// in [low, high]; first > last if none. Integer floor and ceil (std::floor and std::ceil
// are library calls on the x86-64 baseline: a tenth of the particle loop), arguments
// clamped first so that far-off or non-finite positions convert safely.
template <typename Real>
inline void centres_within(Real low, Real high, int size, int* first, int* last) {
    *first = std::max(0, base::ceil_to_int(std::max(Real(-1), low - Real(0.5))));
    *last = std::min(size - 1, base::floor_to_int(std::min(Real(size), high - Real(0.5))));
}

struct PbvrRenderer::MeshLayer {
    const TetMesh* mesh;
    const ColourTransferFunction* tf;
    PreIntegration pre;
    DepthSampling depth;
    std::vector<float> values;  // normalized by tf
};

}  // namespace sonotrace::imaging::pbvr
