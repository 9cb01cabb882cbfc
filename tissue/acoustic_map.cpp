#include "tissue/acoustic_map.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cstring>
#include <map>
#include <stdexcept>
#include <string>

namespace sonotrace::tissue {

namespace {

// d/d(axis) of a planar field at integer index `i`, in units per mm: the central
// difference of eq. 3, averaged over the neighbours across the other used axes with
// weights 1/4, 1/2, 1/4 (Sobel). The plain central difference is anisotropic at oblique
// interfaces a few texels wide: its direction errs by degrees at the edges of the
// transition, and refracting about a wrong normal breaks Snell's law by ~1 degree across
// an interface tilted 20 degrees to the grid. The averaging keeps the O(h^2) accuracy.
float axis_difference(const Volume& f, const glm::ivec3& i, int axis) {
    const int n = f.dims()[axis];
    if (n < 2) return 0.0f;
    glm::ivec3 lo = i, hi = i;
    lo[axis] = std::max(0, i[axis] - 1);
    hi[axis] = std::min(n - 1, i[axis] + 1);
    const double h = f.geometry().spacing[axis] * (hi[axis] - lo[axis]);
    return float((double(f.at(hi.x, hi.y, hi.z)) - f.at(lo.x, lo.y, lo.z)) / h);
}

float derivative(const Volume& f, const glm::ivec3& i, int axis) {
    const glm::ivec3 d = f.dims();
    const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    // Neighbours across the other axes that exist (none across a flat axis).
    const int u_lo = d[a1] < 2 ? 0 : std::max(-1, -i[a1]),
              u_hi = d[a1] < 2 ? 0 : std::min(1, d[a1] - 1 - i[a1]);
    const int v_lo = d[a2] < 2 ? 0 : std::max(-1, -i[a2]),
              v_hi = d[a2] < 2 ? 0 : std::min(1, d[a2] - 1 - i[a2]);
    double sum = 0.0, weight = 0.0;
    for (int u = u_lo; u <= u_hi; ++u) {
        for (int v = v_lo; v <= v_hi; ++v) {
            glm::ivec3 j = i;
            j[a1] += u, j[a2] += v;
            const double w = (u == 0 ? 2.0 : 1.0) * (v == 0 ? 2.0 : 1.0);
            sum += w * axis_difference(f, j, axis);
            weight += w;
        }
    }
    return float(sum / weight);
}

// derivative() at a texel with neighbours on every side of a 3D field, by direct
// indexing: the same differences, weights and order of summation (the same float).
float interior_derivative(const float* f, const glm::ivec3& strides, std::size_t at, int axis,
                          double spacing) {
    const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    const std::ptrdiff_t step = strides[axis], s1 = strides[a1], s2 = strides[a2];
    const double h = spacing * 2.0;
    double sum = 0.0;
    for (int u = -1; u <= 1; ++u) {
        for (int v = -1; v <= 1; ++v) {
            const std::ptrdiff_t j = std::ptrdiff_t(at) + u * s1 + v * s2;
            const double w = (u == 0 ? 2.0 : 1.0) * (v == 0 ? 2.0 : 1.0);
            sum += w * double(float((double(f[j + step]) - f[j - step]) / h));
        }
    }
    return float(sum / 16.0);
}

// n = c0 / c.
Volume refractive_index_of(const Volume& speed) {
    Volume index(speed.geometry());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, speed.size(), 4096), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v)
            index.voxels()[v] = float(kReferenceSpeed / speed.voxels()[v]);
    });
    return index;
}

}  // namespace

Volume soft_tissue_smoothed_index(const Volume& speed, double sigma_mm) {
    // Normalised convolution over the soft-tissue texels: G * (w n) / G * w with w = 1 in
    // the band, so bone, air or a metal wire neither pull their neighbours' average nor
    // are averaged themselves.
    Volume index = refractive_index_of(speed), weighted(speed.geometry()), weight(speed.geometry());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, speed.size(), 4096), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            const float c = speed.voxels()[v];
            const bool soft = c >= kSoftTissueSpeedMin && c <= kSoftTissueSpeedMax;
            weight.voxels()[v] = soft ? 1.0f : 0.0f;
            weighted.voxels()[v] = soft ? index.voxels()[v] : 0.0f;
        }
    });
    const Volume sum = gaussian_smoothed_coarse(weighted, sigma_mm),
                 total = gaussian_smoothed_coarse(weight, sigma_mm);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, speed.size(), 4096), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v)
            if (weight.voxels()[v] > 0.0f && total.voxels()[v] > 0.0f)
                index.voxels()[v] = sum.voxels()[v] / total.voxels()[v];
    });
    return index;
}

template <int Dim>
AcousticMap<Dim> AcousticMap<Dim>::build(const PropertyMaps& maps, double refraction_smoothing_mm) {
    const Volume& speed = maps[Property::speed_of_sound];
    AcousticMap map = pack(refraction_smoothing_mm > 0.0
                               ? soft_tissue_smoothed_index(speed, refraction_smoothing_mm)
                               : refractive_index_of(speed),
                           maps.impedance(), &maps[Property::attenuation],
                           &maps[Property::backscatter], &maps[Property::roughness]);
    if (refraction_smoothing_mm > 0.0) map.average_zone_gradients(refraction_smoothing_mm);
    return map;
}

template <int Dim>
void AcousticMap<Dim>::average_zone_gradients(double sigma_mm) {
    constexpr int kTensor = Dim * (Dim + 1) / 2;  // xx, xy, yy or xx, xy, xz, yy, yz, zz
    // On a grid of the MRI's scale (kZoneCell): the zone spans millimetres, and the map's
    // own texels made these averages most of a frame's map.
    VolumeGeometry coarse;
    coarse.dims = glm::ivec3(1);
    for (int a = 0; a < Dim; ++a) {
        zone_block_[a] = std::max(1, int(std::lround(kZoneCell / spacing_[a])));
        coarse.dims[a] = (dims_[a] + zone_block_[a] - 1) / zone_block_[a];
        coarse.spacing[a] = double(spacing_[a]) * zone_block_[a];
        zone_dims_[a] = coarse.dims[a];
    }
    const std::size_t cells = coarse.voxel_count();
    auto parallel = [&](auto body) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 1024), [&](const auto& r) {
            for (std::size_t v = r.begin(); v != r.end(); ++v) body(v);
        });
    };
    // grad Z at the MRI's scale: each cell's mean over its texels, smoothed by a
    // millimetre, so a voxel staircase is the slope it steps along.
    std::array<Volume, Dim> g0;
    for (auto& part : g0) part = Volume(coarse);
    parallel([&](std::size_t c) {
        IVec cell, lo, hi;
        std::size_t rest = c;
        for (int a = 0; a < Dim; ++a) {
            cell[a] = int(rest % std::size_t(zone_dims_[a]));
            rest /= std::size_t(zone_dims_[a]);
            lo[a] = cell[a] * zone_block_[a];
            hi[a] = std::min(lo[a] + zone_block_[a], dims_[a]);
        }
        Vec sum(0.0f);
        int count = 0;
        IVec i = lo;
        while (true) {
            for (int a = 0; a < Dim; ++a) sum[a] += texel(i).grad_impedance[a];
            ++count;
            int a = 0;
            for (; a < Dim; ++a) {
                if (++i[a] < hi[a]) break;
                i[a] = lo[a];
            }
            if (a == Dim) break;
        }
        for (int a = 0; a < Dim; ++a) g0[std::size_t(a)].voxels()[c] = sum[a] / float(count);
    });
    for (auto& part : g0) part = gaussian_smoothed_coarse(part, std::min(1.0, sigma_mm));
    auto gradient = [&](std::size_t c) {
        Vec g;
        for (int a = 0; a < Dim; ++a) g[a] = g0[std::size_t(a)].voxels()[c];
        return g;
    };
    // The zone's orientation: the smoothed structure tensor.
    std::array<Volume, kTensor> tensor;
    for (auto& part : tensor) part = Volume(coarse);
    parallel([&](std::size_t c) {
        const Vec g = gradient(c);
        int k = 0;
        for (int a = 0; a < Dim; ++a)
            for (int b = a; b < Dim; ++b) tensor[std::size_t(k++)].voxels()[c] = g[a] * g[b];
    });
    for (auto& part : tensor) part = gaussian_smoothed_coarse(part, sigma_mm);
    // Each cell's gradient turned into the half-space of that orientation (its axis by
    // power iteration from the gradient itself, signed by a fixed rule), and |grad Z|,
    // then averaged.
    std::array<Volume, Dim + 1> turned;
    for (auto& part : turned) part = Volume(coarse);
    parallel([&](std::size_t c) {
        const Vec g = gradient(c);
        glm::mat<Dim, Dim, float> J;
        int k = 0;
        for (int a = 0; a < Dim; ++a)
            for (int b = a; b < Dim; ++b) J[a][b] = J[b][a] = tensor[std::size_t(k++)].voxels()[c];
        Vec axis = g;
        for (int n = 0; n < 8 && glm::dot(axis, axis) > 0.0f; ++n) axis = glm::normalize(J * axis);
        // One sign for the axis wherever it points about the same way: into +y (the
        // frames' depth), or where it lies across y, into +x (then +z).
        const int leading = std::abs(axis[1]) >= 0.2f                ? 1
                            : (Dim == 3 && std::abs(axis[0]) < 0.2f) ? Dim - 1
                                                                     : 0;
        if (axis[leading] < 0.0f) axis = -axis;
        const float side = glm::dot(g, axis) < 0.0f ? -1.0f : 1.0f;
        for (int a = 0; a < Dim; ++a) turned[std::size_t(a)].voxels()[c] = side * g[a];
        turned[Dim].voxels()[c] = glm::length(g);
    });
    for (auto& part : turned) part = gaussian_smoothed_coarse(part, sigma_mm);
    zone_gradient_.resize(cells);
    for (std::size_t c = 0; c < cells; ++c)
        for (int k = 0; k <= Dim; ++k)
            zone_gradient_[c][std::size_t(k)] = turned[std::size_t(k)].voxels()[c];
}

template <int Dim>
typename AcousticMap<Dim>::Vec AcousticMap<Dim>::zone_normal(const Vec& p_mm,
                                                             const Vec& local) const {
    if (zone_gradient_.empty()) return local;
    // Interpolated between the cells' centres (multilinear, clamped to the edge cells).
    IVec i0;
    Vec f;
    for (int a = 0; a < Dim; ++a) {
        const float cell_mm = spacing_[a] * float(zone_block_[a]);
        const float centre_offset = 0.5f * float(zone_block_[a] - 1) * spacing_[a];
        const float u =
            std::clamp((p_mm[a] - centre_offset) / cell_mm, 0.0f, float(zone_dims_[a] - 1));
        i0[a] = std::min(int(u), std::max(zone_dims_[a] - 2, 0));
        f[a] = u - float(i0[a]);
    }
    std::array<float, Dim + 1> z{};
    for (int corner = 0; corner < (1 << Dim); ++corner) {
        float w = 1.0f;
        std::size_t at = 0, stride = 1;
        for (int a = 0; a < Dim; ++a) {
            const bool upper = (corner >> a) & 1;
            w *= upper ? f[a] : 1.0f - f[a];
            at += std::size_t(std::min(i0[a] + int(upper), zone_dims_[a] - 1)) * stride;
            stride *= std::size_t(zone_dims_[a]);
        }
        for (int k = 0; k <= Dim; ++k) z[std::size_t(k)] += w * zone_gradient_[at][std::size_t(k)];
    }
    Vec mean;
    for (int a = 0; a < Dim; ++a) mean[a] = z[std::size_t(a)];
    const float length = glm::length(mean);
    if (!(length >= kZoneCoherence * z[Dim]) || !(length > 0.0f)) return local;
    return glm::dot(mean, local) >= 0.0f ? mean / length : -mean / length;
}

template <int Dim>
AcousticMap<Dim> AcousticMap<Dim>::build_paper(const Volume& density) {
    return pack(density, density, nullptr, nullptr, nullptr);
}

template <int Dim>
AcousticMap<Dim> AcousticMap<Dim>::pack(const Volume& refractive_index, const Volume& impedance,
                                        const Volume* attenuation, const Volume* backscatter,
                                        const Volume* roughness) {
    AcousticMap map;
    map.geometry_ = refractive_index.geometry();
    const glm::ivec3 n = map.geometry_.dims;
    if (Dim == 2 && n.z != 1) throw std::invalid_argument("AcousticMap<2> needs a single slice");
    // Interpolation needs two texels per axis; probe grids are far larger.
    for (int a = 0; a < Dim; ++a) {
        if (n[a] < 2) throw std::invalid_argument("AcousticMap needs at least 2 texels per axis");
        map.dims_[a] = n[a];
        map.spacing_[a] = float(map.geometry_.spacing[a]);
        map.inverse_spacing_[a] = float(1.0 / map.geometry_.spacing[a]);
        map.extent_[a] = float(n[a] - 1) * map.spacing_[a];
    }
    auto value = [](const Volume* f, std::size_t v) { return f ? f->voxels()[v] : 0.0f; };
    // Value-initialised in place: the 3D records' padding is zero too (records are keys
    // of the uniform-block table, byte for byte).
    map.texels_.resize(map.geometry_.voxel_count());
    if constexpr (Dim == 2) map.roughness_.assign(map.geometry_.voxel_count(), 0.0f);
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        for (int i = 0; i < n.x; ++i) {
            const std::size_t v = refractive_index.linear_index(i, j, k);
            AcousticTexel<Dim>& t = map.texels_[v];
            t.refractive_index = refractive_index.voxels()[v];
            t.impedance = impedance.voxels()[v];
            t.attenuation = value(attenuation, v);
            t.backscatter = value(backscatter, v);
            if constexpr (Dim == 3)
                t.surface.roughness = value(roughness, v);
            else
                map.roughness_[v] = value(roughness, v);
            if (Dim == 2 && i > 0 && i + 1 < n.x && j > 0 && j + 1 < n.y) {
                // Interior of a slice: the same Sobel weights, straight from the rows.
                for (const auto& [f, grad] :
                     {std::pair{&refractive_index, &t.grad_refractive_index[0]},
                      std::pair{&impedance, &t.grad_impedance[0]}}) {
                    const float* up = f->voxels().data() + f->linear_index(0, j - 1, k);
                    const float* mid = f->voxels().data() + f->linear_index(0, j, k);
                    const float* down = f->voxels().data() + f->linear_index(0, j + 1, k);
                    auto d = [](float a, float b) { return double(a) - double(b); };
                    grad[0] = float((d(up[i + 1], up[i - 1]) + 2.0 * d(mid[i + 1], mid[i - 1]) +
                                     d(down[i + 1], down[i - 1])) /
                                    (8.0 * map.geometry_.spacing.x));
                    grad[1] = float((d(down[i - 1], up[i - 1]) + 2.0 * d(down[i], up[i]) +
                                     d(down[i + 1], up[i + 1])) /
                                    (8.0 * map.geometry_.spacing.y));
                }
                continue;
            }
            const bool interior =
                Dim == 3 && i > 0 && i + 1 < n.x && j > 0 && j + 1 < n.y && k > 0 && k + 1 < n.z;
            for (int a = 0; a < Dim; ++a) {
                if (interior) {
                    const glm::ivec3 strides(1, n.x, n.x * n.y);
                    const double h = map.geometry_.spacing[a];
                    t.grad_refractive_index[a] =
                        interior_derivative(refractive_index.voxels().data(), strides, v, a, h);
                    t.grad_impedance[a] =
                        interior_derivative(impedance.voxels().data(), strides, v, a, h);
                    continue;
                }
                t.grad_refractive_index[a] = derivative(refractive_index, {i, j, k}, a);
                t.grad_impedance[a] = derivative(impedance, {i, j, k}, a);
            }
        }
    });
    map.find_uniform_blocks();
    return map;
}

template <int Dim>
void AcousticMap<Dim>::find_uniform_blocks() {
    std::size_t blocks = 1;
    for (int a = 0; a < Dim; ++a) {
        block_dims_[a] = (dims_[a] + kBlock - 1) / kBlock;
        blocks *= std::size_t(block_dims_[a]);
    }
    block_record_.assign(blocks, -1);
    tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t block) {
        IVec lo, hi, b;
        std::size_t rest = block;
        for (int a = 0; a < Dim; ++a) {
            b[a] = int(rest % std::size_t(block_dims_[a]));
            rest /= std::size_t(block_dims_[a]);
            // The margin covers the far corners of the block's cells and the cell
            // sample() uses at the clamped upper edge.
            lo[a] = std::max(0, b[a] * kBlock - 1);
            hi[a] = std::min(dims_[a] - 1, (b[a] + 1) * kBlock);
        }
        const AcousticTexel<Dim>& first = texel(lo);
        for (int a = 0; a < Dim; ++a) {
            if (first.grad_refractive_index[a] != 0.0f || first.grad_impedance[a] != 0.0f) return;
        }
        IVec i = lo;
        while (true) {
            if (std::memcmp(&texel(i), &first, kStepRecordBytes<Dim>) != 0) return;
            int a = 0;
            for (; a < Dim; ++a) {
                if (++i[a] <= hi[a]) break;
                i[a] = lo[a];
            }
            if (a == Dim) break;
        }
        block_record_[block] = int32_t(linear(lo));
    });
    // Distinct records, numbered in block order (deterministic).
    std::map<std::string, int32_t> index_of;
    uniform_records_.clear();
    for (int32_t& record : block_record_) {
        if (record < 0) continue;
        const AcousticTexel<Dim>& t = texels_[std::size_t(record)];
        const auto [it, inserted] = index_of.try_emplace(
            std::string(reinterpret_cast<const char*>(&t), kStepRecordBytes<Dim>),
            int32_t(index_of.size()));
        if (inserted) uniform_records_.push_back(t);
        record = it->second;
    }
}

template <int Dim>
double AcousticMap<Dim>::uniform_block_fraction() const {
    if (block_record_.empty()) return 0.0;
    const auto uniform =
        std::count_if(block_record_.begin(), block_record_.end(), [](int32_t r) { return r >= 0; });
    return double(uniform) / double(block_record_.size());
}

template class AcousticMap<2>;
template class AcousticMap<3>;

}  // namespace sonotrace::tissue
