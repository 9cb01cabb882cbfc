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
// distance so they carry physical units (the paper's are per texel), one-sided at the
// border, and averaged over the neighbours across the other axes with weights 1/4, 1/2,
// 1/4 (Sobel) for direction accuracy at oblique interfaces (see acoustic_map.cpp).
#include <algorithm>
#include <cstring>
#include <vector>

#include <glm/glm.hpp>

#include "tissue/property_maps.h"
#include "tissue/volume.h"

namespace sonotrace::tissue {

// Reference speed of sound (m/s): display depth c0*t/2 and refractive index n = c0/c.
inline constexpr double kReferenceSpeed = 1540.0;

template <int Dim>
struct AcousticTexel {
    float refractive_index;            // n = c0 / c, dimensionless
    float impedance;                   // Z = rho*c, MRayl
    float attenuation;                 // dB/(cm*MHz)
    float backscatter;                 // relative 0..1
    float scatterer_density;           // 1/mm^3
    float roughness;                   // 0..1
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
    // Packs property maps (nz must be 1 for Dim == 2; at least 2 texels per used axis)
    // and computes the gradients.
    static AcousticMap build(const PropertyMaps& maps);
    // The paper's medium: one scalar density d acting as refractive index and impedance
    // (n = Z = d); no attenuation or scattering.
    static AcousticMap build_paper(const Volume& density);

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
    // The refractive index alone (one float per texel read), same interpolation.
    float sample_refractive_index(const Vec& p_mm) const;

  private:
    std::size_t linear(const IVec& i) const;
    static AcousticMap pack(const Volume& refractive_index, const Volume& impedance,
                            const Volume* attenuation, const Volume* backscatter,
                            const Volume* scatterer_density, const Volume* roughness);

    VolumeGeometry geometry_;
    IVec dims_{};
    Vec spacing_{};
    Vec inverse_spacing_{};
    std::vector<AcousticTexel<Dim>> texels_;
};

// ---- inline hot path: sampling is called once per particle step ----

template <int Dim>
inline std::size_t AcousticMap<Dim>::linear(const IVec& i) const {
    std::size_t index = std::size_t(i[Dim - 1]);
    for (int a = Dim - 2; a >= 0; --a) index = index * std::size_t(dims_[a]) + std::size_t(i[a]);
    return index;
}

template <int Dim>
inline bool AcousticMap<Dim>::inside(const Vec& p_mm) const {
    for (int a = 0; a < Dim; ++a) {
        if (!(p_mm[a] >= 0.0f && p_mm[a] <= (dims_[a] - 1) * spacing_[a])) return false;
    }
    return true;
}

template <int Dim>
inline AcousticTexel<Dim> AcousticMap<Dim>::sample(const Vec& p_mm) const {
    constexpr int K = int(sizeof(AcousticTexel<Dim>) / sizeof(float));
    // Cell corner (clamped so that i0 + 1 stays inside) and fractional position.
    IVec i0;
    Vec f;
    for (int a = 0; a < Dim; ++a) {
        const float x = glm::clamp(p_mm[a] * inverse_spacing_[a], 0.0f, float(dims_[a] - 1));
        i0[a] = std::min(int(x), dims_[a] - 2);
        f[a] = x - float(i0[a]);
    }
    const float* t000 = reinterpret_cast<const float*>(texels_.data() + linear(i0));
    const std::size_t dy = std::size_t(dims_[0]) * K;
    const float gx = 1.0f - f[0], gy = 1.0f - f[1];
    float out[K];
    if constexpr (Dim == 2) {
        const float w00 = gx * gy, w10 = f[0] * gy, w01 = gx * f[1], w11 = f[0] * f[1];
        const float *t10 = t000 + K, *t01 = t000 + dy, *t11 = t01 + K;
        for (int k = 0; k < K; ++k)
            out[k] = w00 * t000[k] + w10 * t10[k] + w01 * t01[k] + w11 * t11[k];
    } else {
        const std::size_t dz = dy * std::size_t(dims_[1]);
        const float gz = 1.0f - f[2];
        const float w00 = gx * gy, w10 = f[0] * gy, w01 = gx * f[1], w11 = f[0] * f[1];
        const float *t100 = t000 + K, *t010 = t000 + dy, *t110 = t010 + K;
        const float *t001 = t000 + dz, *t101 = t001 + K, *t011 = t001 + dy, *t111 = t011 + K;
        for (int k = 0; k < K; ++k) {
            const float lower = w00 * t000[k] + w10 * t100[k] + w01 * t010[k] + w11 * t110[k];
            const float upper = w00 * t001[k] + w10 * t101[k] + w01 * t011[k] + w11 * t111[k];
            out[k] = gz * lower + f[2] * upper;
        }
    }
    AcousticTexel<Dim> result;
    std::memcpy(&result, out, sizeof result);
    return result;
}

template <int Dim>
inline float AcousticMap<Dim>::sample_refractive_index(const Vec& p_mm) const {
    constexpr int K = int(sizeof(AcousticTexel<Dim>) / sizeof(float));
    IVec i0;
    Vec f;
    for (int a = 0; a < Dim; ++a) {
        const float x = glm::clamp(p_mm[a] * inverse_spacing_[a], 0.0f, float(dims_[a] - 1));
        i0[a] = std::min(int(x), dims_[a] - 2);
        f[a] = x - float(i0[a]);
    }
    const float* t = reinterpret_cast<const float*>(texels_.data() + linear(i0));  // n is field 0
    const std::size_t dy = std::size_t(dims_[0]) * K;
    const float lower = (1 - f[1]) * ((1 - f[0]) * t[0] + f[0] * t[K]) + f[1] * ((1 - f[0]) * t[dy] + f[0] * t[dy + K]);
    if constexpr (Dim == 2) {
        return lower;
    } else {
        const float* u = t + dy * std::size_t(dims_[1]);
        const float upper = (1 - f[1]) * ((1 - f[0]) * u[0] + f[0] * u[K]) + f[1] * ((1 - f[0]) * u[dy] + f[0] * u[dy + K]);
        return (1 - f[2]) * lower + f[2] * upper;
    }
}

extern template class AcousticMap<2>;
extern template class AcousticMap<3>;

}  // namespace sonotrace::tissue
