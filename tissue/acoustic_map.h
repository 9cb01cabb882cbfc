#pragma once
// The fields the particle tracer samples at every step, with their gradients, in 2D
// (a slice) or 3D (a sub-volume).
//
// Layout: texel-interleaved (array of structs), x fastest. Every tracer step reads all
// fields and gradients at the same 4 (2D) or 8 (3D) texels, so one record per texel
// puts everything a step needs into 2-3 contiguous cache lines per texel pair along x;
// a planar layout would touch 10-12 separate lines per texel. Records are 40 bytes (2D)
// and 48 bytes (3D) of float.
//
// Positions are in mm in the grid's own frame: texel centre (i, j[, k]) sits at
// (i*hx, j*hy[, k*hz]). For a probe grid (tissue/resample.h) the axes are lateral,
// axial and elevation, so the tracer works directly in probe coordinates.
//
// Gradients: central differences of eq. 3 of Reis & Bertram, divided by the texel
// distance so they carry physical units (the paper's are per texel); one-sided at the
// border.
#include <vector>

#include <glm/glm.hpp>

#include "tissue/property_maps.h"
#include "tissue/volume.h"

namespace sonotrace::tissue {

// Reference speed of sound (m/s): display depth c0*t/2 and refractive index n = c0/c.
inline constexpr double kReferenceSpeed = 1540.0;

template <int Dim>
struct AcousticTexel {
    float refractive_index;   // n = c0 / c, dimensionless
    float impedance;          // Z = rho*c, MRayl
    float attenuation;        // dB/(cm*MHz)
    float backscatter;        // relative 0..1
    float scatterer_density;  // 1/mm^3
    float roughness;          // 0..1
    float grad_refractive_index[Dim];  // 1/mm along the grid axes
    float grad_impedance[Dim];         // MRayl/mm along the grid axes
};
static_assert(sizeof(AcousticTexel<2>) == 40 && sizeof(AcousticTexel<3>) == 48);

template <int Dim>
class AcousticMap {
public:
    static_assert(Dim == 2 || Dim == 3);
    using Vec = glm::vec<Dim, float>;
    using IVec = glm::vec<Dim, int>;

    AcousticMap() = default;
    // Packs property maps (nz must be 1 for Dim == 2) and computes the gradients.
    static AcousticMap build(const PropertyMaps& maps);

    const VolumeGeometry& geometry() const { return geometry_; }
    const IVec& dims() const { return dims_; }
    const Vec& spacing() const { return spacing_; }
    // Size of the domain in mm (from the first to the last texel centre).
    Vec extent_mm() const { return Vec(dims_ - 1) * spacing_; }

    const AcousticTexel<Dim>& texel(const IVec& i) const { return texels_[linear(i)]; }
    // True within the texel-centre box [0, (n-1)*h] (the tracer's domain).
    bool inside(const Vec& p_mm) const;
    // Bi-/trilinear interpolation of every field; clamps to the edge outside.
    AcousticTexel<Dim> sample(const Vec& p_mm) const;

private:
    std::size_t linear(const IVec& i) const;

    VolumeGeometry geometry_;
    IVec dims_{};
    Vec spacing_{};
    Vec inverse_spacing_{};
    std::vector<AcousticTexel<Dim>> texels_;
};

extern template class AcousticMap<2>;
extern template class AcousticMap<3>;

}  // namespace sonotrace::tissue
