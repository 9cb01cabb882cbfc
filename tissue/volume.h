#pragma once
// A scalar 3D grid with its place in the world. A 2D image is a volume with one slice.
//
// Index space: voxel centres sit at integer indices (i, j, k), i fastest in memory.
// World space: millimetres, world = origin + direction * (spacing ⊙ ijk). `direction`
// holds the world direction of each index axis as a unit column (NIfTI qform/sform,
// ITK's Direction); it is usually a rotation but may be any invertible matrix.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "tissue/base/memory.h"

namespace sonotrace::tissue {

struct VolumeGeometry {
    glm::ivec3 dims{1, 1, 1};           // voxels along i, j, k
    glm::dvec3 spacing{1.0, 1.0, 1.0};  // mm between voxel centres along i, j, k
    glm::dvec3 origin{0.0};             // world position (mm) of voxel (0,0,0)
    glm::dmat3 direction{1.0};          // columns: world unit vectors of the i, j, k axes

    std::size_t voxel_count() const {
        return std::size_t(dims.x) * std::size_t(dims.y) * std::size_t(dims.z);
    }
    // index -> world (mm); continuous indices allowed.
    glm::dvec3 index_to_world(const glm::dvec3& ijk) const {
        return origin + direction * (spacing * ijk);
    }
    // The linear part of index -> world: direction * diag(spacing).
    glm::dmat3 linear() const {
        return glm::dmat3(direction[0] * spacing.x, direction[1] * spacing.y,
                          direction[2] * spacing.z);
    }
    // world (mm) -> continuous index.
    glm::dvec3 world_to_index(const glm::dvec3& world) const;
    // The 4x4 affine index -> world, as NIfTI's sform stores it.
    glm::dmat4 index_to_world_matrix() const;
    // Throws base::InputError(source, ...) when dims or spacing are unusable.
    void validate(const std::string& source) const;
};

// A volume's voxels. Zero-initialized without writing: see base::ZeroedAllocator.
using Voxels = std::vector<float, base::ZeroedAllocator<float>>;

class Volume {
  public:
    Volume() = default;
    Volume(const VolumeGeometry& geometry, float fill = 0.0f);
    Volume(const VolumeGeometry& geometry, Voxels voxels);

    const VolumeGeometry& geometry() const { return geometry_; }
    const glm::ivec3& dims() const { return geometry_.dims; }
    bool is_2d() const { return geometry_.dims.z == 1; }
    std::size_t size() const { return voxels_.size(); }

    std::size_t linear_index(int i, int j, int k) const {
        return (std::size_t(k) * std::size_t(geometry_.dims.y) + std::size_t(j)) *
                   std::size_t(geometry_.dims.x) +
               std::size_t(i);
    }
    float& at(int i, int j, int k = 0) { return voxels_[linear_index(i, j, k)]; }
    float at(int i, int j, int k = 0) const { return voxels_[linear_index(i, j, k)]; }
    Voxels& voxels() { return voxels_; }
    const Voxels& voxels() const { return voxels_; }

    // Trilinear interpolation at a continuous index. Positions within half a voxel of
    // the outer voxel centres clamp to the edge; farther out return `outside`.
    float sample_trilinear(const glm::dvec3& ijk, float outside) const;
    // Value of the nearest voxel (for label maps), or `outside`.
    float sample_nearest(const glm::dvec3& ijk, float outside) const;

    // Smallest and largest voxel value.
    std::pair<float, float> value_range() const;
    // Value below which the fraction `q` (0..1) of voxels lies (histogram estimate).
    float quantile(double q) const;

    // Throws base::InputError(source, "data", ...) naming the first NaN or Inf voxel.
    void require_finite(const std::string& source) const;

  private:
    VolumeGeometry geometry_;
    Voxels voxels_;
};

// out[i] = sum over taps o of w[o] rows[o][i] for i < n, added in the order of o from 0
// (so it equals adding one tap at a time into zeros, bit for bit).
void weighted_sum_of_rows(const float* const* rows, const float* w, int taps, std::size_t n,
                          float* out);

// The volume convolved with a Gaussian of standard deviation sigma_mm along every axis of
// more than one voxel (separable, truncated at 3 sigma, edges replicated).
Volume gaussian_smoothed(const Volume& volume, double sigma_mm);
// The same with a standard deviation per axis (mm; i, j, k).
Volume gaussian_smoothed(const Volume& volume, const glm::dvec3& sigma_mm);

// gaussian_smoothed() for a sigma of many voxels, on a grid m times coarser along each axis
// where sigma spans 3 m voxels or more: block means (the grid reaching the Gaussian's
// reach beyond the edges, which are replicated), the Gaussian there, linear interpolation
// back. The coarse Gaussian is narrowed by what the blocks and the interpolation add, so
// the whole has sigma's second moment. Within 1 % of a step's height of the full
// Gaussian; its cost falls as m^2 in a plane. Where every m is 1 it is gaussian_smoothed().
Volume gaussian_smoothed_coarse(const Volume& volume, double sigma_mm);

}  // namespace sonotrace::tissue
