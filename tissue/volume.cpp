#include "tissue/volume.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "tissue/error.h"
#include "tissue/memory.h"

namespace sonotrace::tissue {

glm::dvec3 VolumeGeometry::world_to_index(const glm::dvec3& world) const {
    return glm::inverse(linear()) * (world - origin);
}

glm::dmat4 VolumeGeometry::index_to_world_matrix() const {
    glm::dmat4 m(1.0);
    for (int c = 0; c < 3; ++c) m[c] = glm::dvec4(direction[c] * spacing[c], 0.0);
    m[3] = glm::dvec4(origin, 1.0);
    return m;
}

void VolumeGeometry::validate(const std::string& source) const {
    for (int a = 0; a < 3; ++a) {
        const std::string axis(1, "ijk"[a]);
        if (dims[a] < 1) {
            throw InputError(source, "dims[" + axis + "]",
                             "must be at least 1, got " + std::to_string(dims[a]));
        }
        if (!(std::isfinite(spacing[a]) && spacing[a] > 0.0)) {
            std::ostringstream s;
            s << "voxel spacing must be a positive finite number of mm, got " << spacing[a];
            throw InputError(source, "spacing[" + axis + "]", s.str());
        }
        if (!std::isfinite(origin[a])) {
            throw InputError(source, "origin[" + axis + "]", "is not finite");
        }
    }
    const double det = glm::determinant(direction);
    if (!std::isfinite(det) || std::abs(det) < 1e-6) {
        throw InputError(
            source, "direction",
            "the axis directions are degenerate (determinant " + number_text(det) + ")");
    }
    // In double: a corrupt header's dims can overflow size_t.
    check_allocation(double(dims.x) * double(dims.y) * double(dims.z) * sizeof(float), source,
                     "dims");
}

Volume::Volume(const VolumeGeometry& geometry, float fill) : geometry_(geometry) {
    voxels_.resize(geometry.voxel_count());  // zero without a write
    if (fill != 0.0f) std::fill(voxels_.begin(), voxels_.end(), fill);
}

Volume::Volume(const VolumeGeometry& geometry, Voxels voxels)
    : geometry_(geometry), voxels_(std::move(voxels)) {
    if (voxels_.size() != geometry_.voxel_count()) {
        throw std::invalid_argument("Volume: voxel count does not match dims");
    }
}

float Volume::sample_trilinear(const glm::dvec3& ijk, float outside) const {
    const glm::ivec3& n = geometry_.dims;
    for (int a = 0; a < 3; ++a) {
        if (!(ijk[a] >= -0.5 && ijk[a] <= n[a] - 0.5)) return outside;
    }
    // Clamp to the outer voxel centres, then interpolate between the two neighbours
    // on each axis (a degenerate axis of size 1 uses the single voxel twice).
    const glm::dvec3 p = glm::clamp(ijk, glm::dvec3(0.0), glm::dvec3(n - 1));
    // p >= 0: truncation is the floor (std::floor is a library call on the x86-64 baseline).
    const glm::ivec3 i0 = glm::min(glm::ivec3(p), glm::max(n - 2, 0));
    const glm::ivec3 i1 = glm::min(i0 + 1, n - 1);
    const glm::dvec3 f = p - glm::dvec3(i0);
    auto v = [&](int x, int y, int z) { return double(voxels_[linear_index(x, y, z)]); };
    const double c00 = v(i0.x, i0.y, i0.z) * (1 - f.x) + v(i1.x, i0.y, i0.z) * f.x;
    const double c10 = v(i0.x, i1.y, i0.z) * (1 - f.x) + v(i1.x, i1.y, i0.z) * f.x;
    const double c01 = v(i0.x, i0.y, i1.z) * (1 - f.x) + v(i1.x, i0.y, i1.z) * f.x;
    const double c11 = v(i0.x, i1.y, i1.z) * (1 - f.x) + v(i1.x, i1.y, i1.z) * f.x;
    const double c0 = c00 * (1 - f.y) + c10 * f.y;
    const double c1 = c01 * (1 - f.y) + c11 * f.y;
    return float(c0 * (1 - f.z) + c1 * f.z);
}

float Volume::sample_nearest(const glm::dvec3& ijk, float outside) const {
    const glm::ivec3& n = geometry_.dims;
    for (int a = 0; a < 3; ++a) {
        if (!(ijk[a] >= -0.5 && ijk[a] <= n[a] - 0.5)) return outside;
    }
    const glm::ivec3 i = glm::clamp(glm::ivec3(glm::round(ijk)), glm::ivec3(0), n - 1);
    return voxels_[linear_index(i.x, i.y, i.z)];
}

void Volume::require_finite(const std::string& source) const {
    for (std::size_t n = 0; n < voxels_.size(); ++n) {
        if (std::isfinite(voxels_[n])) continue;
        const glm::ivec3& d = geometry_.dims;
        std::ostringstream s;
        s << "voxel (" << n % d.x << ", " << (n / d.x) % d.y << ", " << n / (std::size_t(d.x) * d.y)
          << ") is " << voxels_[n] << "; NaN and Inf voxels are not allowed";
        throw InputError(source, "data", s.str());
    }
}

std::pair<float, float> Volume::value_range() const {
    if (voxels_.empty()) return {0.0f, 0.0f};
    const auto [lo, hi] = std::minmax_element(voxels_.begin(), voxels_.end());
    return {*lo, *hi};
}

float Volume::quantile(double q) const {
    if (voxels_.empty()) return 0.0f;
    const auto [lo, hi] = value_range();
    if (!(hi > lo)) return lo;
    // A 4096-bin histogram is exact enough for choosing intensity windows and avoids
    // sorting tens of millions of voxels.
    constexpr int bins = 4096;
    std::vector<std::size_t> counts(bins, 0);
    const double scale = bins / (double(hi) - double(lo));
    for (float v : voxels_) {
        counts[std::min(bins - 1, int((double(v) - lo) * scale))]++;
    }
    const double target = std::clamp(q, 0.0, 1.0) * double(voxels_.size());
    std::size_t cumulative = 0;
    for (int b = 0; b < bins; ++b) {
        if (double(cumulative + counts[b]) >= target) {
            const double within = counts[b] ? (target - cumulative) / counts[b] : 0.0;
            return float(lo + (b + within) / scale);
        }
        cumulative += counts[b];
    }
    return hi;
}

}  // namespace sonotrace::tissue
