#include "tissue/volume.h"

#include <algorithm>
#include <array>
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

// In blocks of 32 samples whose sums stay in registers through all the taps (one load per
// tap and sample, where adding each tap into `out` took a load and a store more); the
// order of the additions is that of one tap at a time. Built for AVX2 too (no FMA: the
// same numbers).
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

Volume gaussian_smoothed(const Volume& volume, double sigma_mm) {
    return gaussian_smoothed(volume, glm::dvec3(sigma_mm));
}

Volume gaussian_smoothed(const Volume& volume, const glm::dvec3& sigma_mm) {
    Volume out = volume;
    const glm::ivec3 dims = volume.dims();
    const std::size_t nx = std::size_t(dims.x),
                      row_count = std::size_t(dims.y) * std::size_t(dims.z);
    for (int axis = 0; axis < 3; ++axis) {
        const int n = dims[axis];
        const double sigma = sigma_mm[axis] / volume.geometry().spacing[axis];
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

Volume gaussian_smoothed_coarse(const Volume& volume, double sigma_mm) {
    const VolumeGeometry& fine = volume.geometry();
    const glm::ivec3 n = fine.dims;
    glm::ivec3 m(1);
    for (int a = 0; a < 3; ++a)
        if (n[a] > 1 && sigma_mm > 0.0)
            m[a] = std::clamp(int(sigma_mm / fine.spacing[a] / 3.0), 1, n[a]);
    if (m == glm::ivec3(1)) return gaussian_smoothed(volume, sigma_mm);

    // The coarse grid reaches `pad` fine voxels beyond each edge (the Gaussian's reach,
    // whole blocks), filled by repeating the edge voxels: near an edge the result is the
    // fine Gaussian's with its edges replicated, not a block mean's.
    VolumeGeometry coarse_geometry = fine;
    glm::dvec3 coarse_sigma_mm;
    glm::ivec3 pad(0);
    for (int a = 0; a < 3; ++a) {
        const double s = sigma_mm / fine.spacing[a], mm = double(m[a]);
        // Variance (fine voxels^2) the blocks add, and the interpolation on average over
        // a block's voxels (|d| (m - |d|) at offset d from the nearest centre).
        const double blocks = (mm * mm - 1.0) / 12.0;
        const double interpolation =
            m[a] % 2 == 0 ? (2.0 * mm * mm + 1.0) / 12.0 : (mm * mm - 1.0) / 6.0;
        const double coarse_sigma = std::sqrt(std::max(s * s - blocks - interpolation, 0.0));
        coarse_sigma_mm[a] = coarse_sigma * fine.spacing[a];
        if (m[a] > 1) pad[a] = m[a] * (int(std::ceil(3.0 * coarse_sigma / mm)) + 1);
        coarse_geometry.dims[a] = (n[a] + 2 * pad[a] + m[a] - 1) / m[a];
        coarse_geometry.spacing[a] = fine.spacing[a] * m[a];
    }
    const glm::ivec3 nc = coarse_geometry.dims;
    // Block means, a coarse row at a time: its blocks' fine rows, padded with their edge
    // voxels, added up first, then each block's run of m.x along x.
    const std::size_t padded_x = std::size_t(nc.x) * std::size_t(m.x);
    Volume coarse(coarse_geometry);
    const float inverse_count = float(1.0 / (double(m.x) * m.y * m.z));
    tbb::parallel_for(0, nc.y * nc.z, [&](int row) {
        const int jc = row % nc.y, kc = row / nc.y;
        std::vector<float> rows(padded_x, 0.0f);
        for (int k = kc * m.z - pad.z; k < (kc + 1) * m.z - pad.z; ++k)
            for (int j = jc * m.y - pad.y; j < (jc + 1) * m.y - pad.y; ++j) {
                const float* source =
                    volume.voxels().data() +
                    volume.linear_index(0, std::clamp(j, 0, n.y - 1), std::clamp(k, 0, n.z - 1));
                const std::size_t before = std::size_t(pad.x),
                                  inside = std::min(std::size_t(n.x), padded_x - before);
                for (std::size_t q = 0; q < before; ++q) rows[q] += source[0];
                for (std::size_t q = 0; q < inside; ++q) rows[before + q] += source[q];
                for (std::size_t q = before + inside; q < padded_x; ++q) rows[q] += source[n.x - 1];
            }
        float* target = &coarse.at(0, jc, kc);
        for (int ic = 0; ic < nc.x; ++ic) {
            float block = 0.0f;
            for (int u = 0; u < m.x; ++u) block += rows[std::size_t(ic * m.x + u)];
            target[ic] = block * inverse_count;
        }
    });
    const Volume smoothed = gaussian_smoothed(coarse, coarse_sigma_mm);
    // Back by linear interpolation between the blocks' centres, at fine coordinate
    // m c - pad + (m - 1) / 2.
    struct Tap {
        int lo, hi;
        float f;
    };
    std::array<std::vector<Tap>, 3> taps;
    for (int a = 0; a < 3; ++a) {
        taps[std::size_t(a)].resize(std::size_t(n[a]));
        for (int i = 0; i < n[a]; ++i) {
            const double u = std::clamp((i + pad[a] - 0.5 * (m[a] - 1)) / m[a], 0.0,
                                        double(std::max(nc[a] - 1, 0)));
            const int lo = std::min(int(u), std::max(nc[a] - 2, 0));
            taps[std::size_t(a)][std::size_t(i)] = {lo, std::min(lo + 1, nc[a] - 1), float(u - lo)};
        }
    }
    // Along x on the coarse rows first, then each fine row a blend of the two (four)
    // rows around it: loops over contiguous samples.
    const std::size_t fine_x = std::size_t(n.x);
    std::vector<float> along_x(std::size_t(nc.y) * std::size_t(nc.z) * fine_x);
    tbb::parallel_for(0, nc.y * nc.z, [&](int row) {
        const float* source = smoothed.voxels().data() + std::size_t(row) * std::size_t(nc.x);
        float* target = along_x.data() + std::size_t(row) * fine_x;
        for (std::size_t i = 0; i < fine_x; ++i) {
            const Tap tx = taps[0][i];
            target[i] = (1.0f - tx.f) * source[tx.lo] + tx.f * source[tx.hi];
        }
    });
    Volume out(fine);
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        const Tap ty = taps[1][std::size_t(j)], tz = taps[2][std::size_t(k)];
        auto coarse_row = [&](int jc, int kc) {
            return along_x.data() +
                   (std::size_t(kc) * std::size_t(nc.y) + std::size_t(jc)) * fine_x;
        };
        const float *a0 = coarse_row(ty.lo, tz.lo), *a1 = coarse_row(ty.hi, tz.lo),
                    *b0 = coarse_row(ty.lo, tz.hi), *b1 = coarse_row(ty.hi, tz.hi);
        float* target = &out.at(0, j, k);
        for (std::size_t i = 0; i < fine_x; ++i)
            target[i] = (1.0f - tz.f) * ((1.0f - ty.f) * a0[i] + ty.f * a1[i]) +
                        tz.f * ((1.0f - ty.f) * b0[i] + ty.f * b1[i]);
    });
    return out;
}

}  // namespace sonotrace::tissue
