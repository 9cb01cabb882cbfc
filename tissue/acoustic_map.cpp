#include "tissue/acoustic_map.h"

#include <tbb/parallel_for.h>

#include <cstring>
#include <stdexcept>

namespace sonotrace::tissue {

namespace {

// d/d(axis) of a planar field at integer index `i`, in units per mm.
float derivative(const Volume& f, const glm::ivec3& i, int axis) {
    const int n = f.dims()[axis];
    if (n < 2) return 0.0f;
    glm::ivec3 lo = i, hi = i;
    lo[axis] = std::max(0, i[axis] - 1);
    hi[axis] = std::min(n - 1, i[axis] + 1);
    const double h = f.geometry().spacing[axis] * (hi[axis] - lo[axis]);
    return float((double(f.at(hi.x, hi.y, hi.z)) - f.at(lo.x, lo.y, lo.z)) / h);
}

}  // namespace

template <int Dim>
AcousticMap<Dim> AcousticMap<Dim>::build(const PropertyMaps& maps) {
    AcousticMap map;
    map.geometry_ = maps.geometry();
    const glm::ivec3 n = map.geometry_.dims;
    if (Dim == 2 && n.z != 1) throw std::invalid_argument("AcousticMap<2> needs a single slice");
    // Interpolation needs two texels per axis; probe grids are far larger.
    for (int a = 0; a < Dim; ++a) {
        if (n[a] < 2) throw std::invalid_argument("AcousticMap needs at least 2 texels per axis");
    }
    for (int a = 0; a < Dim; ++a) {
        map.dims_[a] = n[a];
        map.spacing_[a] = float(map.geometry_.spacing[a]);
        map.inverse_spacing_[a] = float(1.0 / map.geometry_.spacing[a]);
    }

    // Planar n and Z first: their gradients need neighbours.
    Volume refractive_index(map.geometry_), impedance = maps.impedance();
    const auto& speed = maps[Property::speed_of_sound].voxels();
    for (std::size_t v = 0; v < speed.size(); ++v) {
        refractive_index.voxels()[v] = float(kReferenceSpeed / speed[v]);
    }

    map.texels_.resize(map.geometry_.voxel_count());
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        for (int i = 0; i < n.x; ++i) {
            const std::size_t v = refractive_index.linear_index(i, j, k);
            AcousticTexel<Dim>& t = map.texels_[v];
            t.refractive_index = refractive_index.voxels()[v];
            t.impedance = impedance.voxels()[v];
            t.attenuation = maps[Property::attenuation].voxels()[v];
            t.backscatter = maps[Property::backscatter].voxels()[v];
            t.scatterer_density = maps[Property::scatterer_density].voxels()[v];
            t.roughness = maps[Property::roughness].voxels()[v];
            for (int a = 0; a < Dim; ++a) {
                t.grad_refractive_index[a] = derivative(refractive_index, {i, j, k}, a);
                t.grad_impedance[a] = derivative(impedance, {i, j, k}, a);
            }
        }
    });
    return map;
}

template class AcousticMap<2>;
template class AcousticMap<3>;

}  // namespace sonotrace::tissue
