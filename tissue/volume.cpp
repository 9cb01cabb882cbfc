#include "tissue/volume.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <vector>

#include <tbb/parallel_for.h>

#include "tissue/base/error.h"
#include "tissue/base/memory.h"

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
            throw base::InputError(source, "dims[" + axis + "]",
                                   "must be at least 1, got " + std::to_string(dims[a]));
        }
        if (!(std::isfinite(spacing[a]) && spacing[a] > 0.0)) {
            std::ostringstream s;
            s << "voxel spacing must be a positive finite number of mm, got " << spacing[a];
            throw base::InputError(source, "spacing[" + axis + "]", s.str());
        }
        if (!std::isfinite(origin[a])) {
            throw base::InputError(source, "origin[" + axis + "]", "is not finite");
        }
    }
    const double det = glm::determinant(direction);
    if (!std::isfinite(det) || std::abs(det) < 1e-6) {
        throw base::InputError(
            source, "direction",
            "the axis directions are degenerate (determinant " + base::number_text(det) + ")");
    }
    // In double: a corrupt header's dims can overflow size_t.
    base::check_allocation(double(dims.x) * double(dims.y) * double(dims.z) * sizeof(float), source,
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
        throw base::InputError(source, "data", s.str());
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

namespace {
// out[i] = sum over taps o of w[o] rows[o][i], added in the order of o from 0. In blocks of
// 32 samples whose sums stay in registers through all the taps (one load per tap and
// sample, where adding each tap into `out` took a load and a store more); the order of
// the additions is that of one tap at a time. Built for AVX2 too (no FMA: the same numbers).
[[gnu::target_clones("avx2", "default")]] void weighted_sum_of_rows(const float* const* rows,
                                                                    const float* w, int taps,
                                                                    std::size_t n, float* out) {
    // Four vectors of eight (GCC vector extensions: AVX registers, or pairs of SSE2
    // ones); a plain array of 32 sums was kept in memory.
    typedef float v8f __attribute__((vector_size(32)));
    constexpr std::size_t kBlock = 32;
    std::size_t first = 0;
    for (; first + kBlock <= n; first += kBlock) {
        v8f sum[4] = {};
        for (int o = 0; o < taps; ++o) {
            const float weight = w[o];
            const float* source = rows[o] + first;
            for (int v = 0; v < 4; ++v) {
                v8f x;
                std::memcpy(&x, source + 8 * v, sizeof x);
                sum[v] += weight * x;
            }
        }
        std::memcpy(out + first, sum, sizeof sum);
    }
    const std::size_t rest = n - first;
    float sum[kBlock] = {};
    for (int o = 0; o < taps; ++o) {
        const float weight = w[o];
        const float* source = rows[o] + first;
        for (std::size_t i = 0; i < rest; ++i) sum[i] += weight * source[i];
    }
    std::copy_n(sum, rest, out + first);
}
}  // namespace

Volume gaussian_smoothed(const Volume& volume, double sigma_mm) {
    Volume out = volume;
    const glm::ivec3 dims = volume.dims();
    const std::size_t nx = std::size_t(dims.x),
                      row_count = std::size_t(dims.y) * std::size_t(dims.z);
    for (int axis = 0; axis < 3; ++axis) {
        const int n = dims[axis];
        const double sigma = sigma_mm / volume.geometry().spacing[axis];
        if (n < 2 || !(sigma > 0.0)) continue;
        const int radius = std::max(1, int(std::ceil(3.0 * sigma)));
        std::vector<float> kernel(std::size_t(2 * radius + 1));
        double total = 0.0;
        for (int o = -radius; o <= radius; ++o) total += std::exp(-0.5 * o * o / (sigma * sigma));
        for (int o = -radius; o <= radius; ++o)
            kernel[std::size_t(o + radius)] =
                float(std::exp(-0.5 * o * o / (sigma * sigma)) / total);
        const Volume in = out;
        // Each output row (along x) is one task's: the sum over taps of whole source rows
        // (along x: the row shifted, padded with its edge values; along y or z: the rows
        // at clamped offsets), in a fixed order, so the result does not depend on the
        // threads.
        tbb::parallel_for(std::size_t(0), row_count, [&](std::size_t row) {
            float* target = out.voxels().data() + row * nx;
            std::vector<const float*> sources(kernel.size());
            std::vector<float> padded;
            if (axis == 0) {
                padded.resize(nx + 2 * std::size_t(radius));
                const float* source = in.voxels().data() + row * nx;
                std::fill_n(padded.begin(), radius, source[0]);
                std::copy_n(source, nx, padded.begin() + radius);
                std::fill_n(padded.begin() + radius + std::ptrdiff_t(nx), radius, source[nx - 1]);
                for (std::size_t o = 0; o < kernel.size(); ++o) sources[o] = padded.data() + o;
            } else {
                const std::size_t j = row % std::size_t(dims.y), k = row / std::size_t(dims.y);
                const int at = int(axis == 1 ? j : k);
                for (int o = -radius; o <= radius; ++o) {
                    const std::size_t q = std::size_t(std::clamp(at + o, 0, n - 1));
                    const std::size_t source_row =
                        axis == 1 ? k * std::size_t(dims.y) + q : q * std::size_t(dims.y) + j;
                    sources[std::size_t(o + radius)] = in.voxels().data() + source_row * nx;
                }
            }
            weighted_sum_of_rows(sources.data(), kernel.data(), int(kernel.size()), nx, target);
        });
    }
    return out;
}

}  // namespace sonotrace::tissue
