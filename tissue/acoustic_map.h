#pragma once
// The fields the particle tracer samples at every step, with their gradients, in 2D
// (a slice) or 3D (a sub-volume).
//
// Layout: texel-interleaved (array of structs), x fastest. Every tracer step reads all
// fields and gradients at the same 4 (2D) or 8 (3D) texels, so one record per texel
// puts everything a step needs into 2-3 contiguous cache lines per texel pair along x;
// a planar layout would touch 8-10 separate lines per texel. Records are 8 floats
// (32 bytes) in 2D and 12 (48) in 3D, so interpolation runs as two or three 4-wide
// vector blends: the scalar blend of 10 fields was the largest cost of a tracer step
// (96 of ~390 instructions, callgrind).
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
#include <array>
#include <cstddef>
#include <cstring>
#include <limits>
#include <vector>

#include <glm/glm.hpp>

#include "tissue/base/memory.h"
#include "tissue/property_maps.h"
#include "tissue/volume.h"

namespace sonotrace::tissue {

// Reference speed of sound (m/s): display depth c0*t/2 and refractive index n = c0/c.
inline constexpr double kReferenceSpeed = 1540.0;

// Roughness, read only at interfaces (sample_roughness): in 3D it takes a float of the
// record's padding, next to the fields just sampled at the plateau ends (a map of its own
// missed the cache: 1.7 % of a 3D trace). 2D records have no padding, and roughness in
// them made texels 48 bytes instead of 32, so 2D keeps it in a map of its own.
template <int Dim>
struct TexelRoughness {};
template <>
struct TexelRoughness<3> {
    float roughness;  // rms slope of the surface, 0..1
};

// What a step samples, a whole number of 4-float vectors (the alignment pads 3D's 11
// floats to 12; 2D has 8). Z and grad Z come first: they fill the first 4-float vector,
// all that the interface searches read (sample_impedance).
template <int Dim>
struct alignas(16) AcousticTexel {
    float impedance;                                    // Z = rho*c, MRayl
    float grad_impedance[Dim];                          // MRayl/mm, along the grid axes
    float refractive_index;                             // n = c0 / c, dimensionless
    float grad_refractive_index[Dim];                   // 1/mm
    float attenuation;                                  // dB/(cm*MHz)
    float backscatter;                                  // relative 0..1
    [[no_unique_address]] TexelRoughness<Dim> surface;  // 3D only
};
static_assert(sizeof(AcousticTexel<2>) == 32 && sizeof(AcousticTexel<3>) == 48);

// The bytes of a record that a step reads: all but 3D's roughness (and padding). Uniform
// blocks are uniform in these.
template <int Dim>
inline constexpr std::size_t kStepRecordBytes = Dim == 3 ? offsetof(AcousticTexel<3>, surface)
                                                         : sizeof(AcousticTexel<2>);
static_assert(kStepRecordBytes<3> == 10 * sizeof(float));

// Z and grad Z at a point: the first 4-float vector of sample().
template <int Dim>
struct ImpedanceSample {
    float impedance;
    float grad_impedance[Dim];
};

// Speeds of sound (m/s) of the soft-tissue band that soft_tissue_smoothed_index averages:
// every soft tissue and fluid of the tissue table (fat 1450 to dura 1620), not bone or air.
inline constexpr double kSoftTissueSpeedMin = 1400.0, kSoftTissueSpeedMax = 1700.0;

// The refractive index n = c0 / c of `speed`, averaged over the soft tissue around each
// soft-tissue texel by a Gaussian of sigma_mm (bone and air keep their own, and take no
// part in their neighbours' average). A ray stands for a beam whose wavefront spans its
// Fresnel zone (sqrt(lambda z), millimetres), so it bends with the medium averaged over
// that zone: a sulcus or a partial-volume fringe thinner than the zone aberrates the
// wavefront a little, where as a ray it would deflect by up to twice its grazing angle
// (total reflection beyond 74-76 degrees at CSF/brain). An extended soft-tissue interface
// keeps its refraction (n sin(theta) is conserved across a graded planar layer: the ray
// leaves at Snell's angle), spread over a few sigma; at bone or air the index jumps as
// before. Reflections come from the impedance, which is not smoothed.
Volume soft_tissue_smoothed_index(const Volume& speed, double sigma_mm);

template <int Dim>
class AcousticMap {
  public:
    static_assert(Dim == 2 || Dim == 3);
    using Vec = glm::vec<Dim, float>;
    using IVec = glm::vec<Dim, int>;

    AcousticMap() = default;
    // Packs property maps (nz must be 1 for Dim == 2; at least 2 texels per used axis)
    // and computes the gradients. refraction_smoothing_mm > 0: the refractive index is
    // soft_tissue_smoothed_index's at that scale; 0 keeps the maps' own.
    static AcousticMap build(const PropertyMaps& maps, double refraction_smoothing_mm = 0.0);
    // The paper's medium: one scalar density d acting as refractive index and impedance
    // (n = Z = d); no attenuation or scattering.
    static AcousticMap build_paper(const Volume& density);

    const VolumeGeometry& geometry() const { return geometry_; }
    const IVec& dims() const { return dims_; }
    const Vec& spacing() const { return spacing_; }
    // The finest spacing (mm): the tracer's step and interface reach are in its texels.
    float smallest_spacing() const {
        float h = spacing_[0];
        for (int a = 1; a < Dim; ++a) h = std::min(h, spacing_[a]);
        return h;
    }
    // Size of the domain in mm (from the first to the last texel centre).
    Vec extent_mm() const { return Vec(dims_ - 1) * spacing_; }

    const AcousticTexel<Dim>& texel(const IVec& i) const { return texels_[linear(i)]; }
    // All records, x fastest (for vectorised readers that repeat sample()'s arithmetic).
    const AcousticTexel<Dim>* texels() const { return texels_.data(); }
    // 1 / spacing as locate() uses it.
    const Vec& inverse_spacing() const { return inverse_spacing_; }
    // True within the texel-centre box [0, (n-1)*h] (the tracer's domain).
    bool inside(const Vec& p_mm) const;
    // Bi-/trilinear interpolation of every field; clamps to the edge outside.
    AcousticTexel<Dim> sample(const Vec& p_mm) const;
    // Z and grad Z alone, the bits sample() gives, for a third (3D) or half (2D) of its
    // reads and arithmetic: the interface searches take ~100 samples each.
    ImpedanceSample<Dim> sample_impedance(const Vec& p_mm) const;
    // The refractive index alone (one float per texel read), the value sample() gives.
    float sample_refractive_index(const Vec& p_mm) const;
    // Roughness (0..1), same interpolation.
    float sample_roughness(const Vec& p_mm) const;
    // The backscatter alone, the value sample() gives.
    float sample_backscatter(const Vec& p_mm) const {
        return sample_record_float(offsetof(AcousticTexel<Dim>, backscatter), p_mm);
    }

    // Uniform blocks: kBlock^Dim texels that, with a one-texel margin on every side,
    // hold one record with zero gradients. Anywhere in such a block sample() returns
    // that record, so the tracer skips interpolation and refraction there (water, soft
    // tissue of phantoms, air). p_mm must be inside(); nullptr if the block varies.
    static constexpr int kBlockShift = 3, kBlock = 1 << kBlockShift;
    const AcousticTexel<Dim>* uniform_block(const Vec& p_mm) const;
    // The same lookup in parts, for vectorised readers: per block (x fastest, block_dims()
    // per axis) the index of its record for uniform_record(), or -1.
    const int32_t* block_records() const { return block_record_.data(); }
    const IVec& block_dims() const { return block_dims_; }
    const AcousticTexel<Dim>* uniform_record(int32_t index) const {
        return &uniform_records_[std::size_t(index)];
    }
    // How far (mm) from x along unit r to the edge of the block uniform_block(x) looks up
    // (for runs of steps that need not look again).
    float distance_to_block_exit(const Vec& x, const Vec& r) const {
        constexpr float kBlockSide = float(kBlock);
        float distance = std::numeric_limits<float>::max();
        for (int a = 0; a < Dim; ++a) {
            const float h = spacing_[a];
            const int block = int(x[a] * inverse_spacing_[a]) >> kBlockShift;
            const float lo = float(block) * kBlockSide * h;
            if (r[a] > 0.0f) distance = std::min(distance, (lo + kBlockSide * h - x[a]) / r[a]);
            if (r[a] < 0.0f) distance = std::min(distance, (x[a] - lo) / -r[a]);
        }
        return distance;
    }
    // Fraction of blocks that are uniform (for benchmarks and logs).
    double uniform_block_fraction() const;

    // A sharp interface's normal as a beam sees it: the orientation of the interfaces
    // around p averaged over the Fresnel zone (build's refraction_smoothing_mm), signed
    // like `local` (the interface's own normal at p), or `local` itself where no
    // orientation dominates there (a body smaller than the zone) or the map has none.
    // Why: a ray stands for a beam whose wavefront spans the zone; the MRI's voxel-scale
    // jags in a skull surface aberrate that wavefront's phase, they do not turn the beam
    // by the jags' own angles. The average is of grad Z, each texel's turned into the
    // half-space of the zone's dominant orientation (the axis of the smoothed structure
    // tensor g g^T) first: the two faces of a thin plate then add where they would cancel,
    // and the steps of a staircase keep their mean tilt, which the tensor's axis alone
    // pulls towards the grid's axes. Gradients are taken at the MRI's scale (1 mm), so a
    // voxel staircase is the slope it steps along. Dominant: the average holds at least
    // kZoneCoherence of the average of |grad Z| (directions spread evenly over a circle
    // and turned into one half hold 2 / pi).
    static constexpr float kZoneCoherence = 0.8f;
    Vec zone_normal(const Vec& p_mm, const Vec& local) const;

  private:
    std::size_t linear(const IVec& i) const;
    void locate(const Vec& p_mm, IVec* i0, Vec* f) const;
    template <int Chunks>
    void blend_chunks(const Vec& p_mm, float* out) const;
    float sample_field(const float* field, std::size_t stride, const Vec& p_mm) const;
    // sample_field() of the records' float at byte offset `offset`.
    float sample_record_float(std::size_t offset, const Vec& p_mm) const {
        constexpr std::size_t K = sizeof(AcousticTexel<Dim>) / sizeof(float);
        return sample_field(reinterpret_cast<const float*>(texels_.data()) + offset / sizeof(float),
                            K, p_mm);
    }
    static AcousticMap pack(const Volume& refractive_index, const Volume& impedance,
                            const Volume* attenuation, const Volume* backscatter,
                            const Volume* roughness);

    VolumeGeometry geometry_;
    IVec dims_{};
    Vec spacing_{};
    Vec inverse_spacing_{};
    Vec extent_{};  // (n - 1) * h per axis: the domain for inside()
    std::vector<AcousticTexel<Dim>, base::HugePageAllocator<AcousticTexel<Dim>>> texels_;
    std::vector<float, base::HugePageAllocator<float>> roughness_;  // per texel, 2D only
    IVec block_dims_{};
    // Per block: its record's index in uniform_records_ (distinct records, a handful in
    // practice, so they stay in L1), or -1.
    std::vector<int32_t> block_record_;
    std::vector<AcousticTexel<Dim>> uniform_records_;
    void find_uniform_blocks();
    // Per cell of a grid of blocks of zone_block_ texels (about kZoneCell), over the
    // Fresnel zone (zone_normal): the average of the turned grad Z (Dim components) and of
    // |grad Z|; empty without smoothing.
    static constexpr float kZoneCell = 1.0f;  // mm: the MRI's voxel, which the zone averages
    IVec zone_block_{}, zone_dims_{};
    std::vector<std::array<float, Dim + 1>> zone_gradient_;
    void average_zone_gradients(double sigma_mm);
};

// ---- inline hot path: sampling is called once per particle step ----

template <int Dim>
inline std::size_t AcousticMap<Dim>::linear(const IVec& i) const {
    std::size_t index = std::size_t(i[Dim - 1]);
    for (int a = Dim - 2; a >= 0; --a) index = index * std::size_t(dims_[a]) + std::size_t(i[a]);
    return index;
}

// The cell corner (clamped so that i0 + 1 stays inside) and the fractional position.
template <int Dim>
[[gnu::always_inline]] inline void AcousticMap<Dim>::locate(const Vec& p_mm, IVec* i0,
                                                            Vec* f) const {
    for (int a = 0; a < Dim; ++a) {
        const float x = glm::clamp(p_mm[a] * inverse_spacing_[a], 0.0f, float(dims_[a] - 1));
        (*i0)[a] = std::min(int(x), dims_[a] - 2);
        (*f)[a] = x - float((*i0)[a]);
    }
}

template <int Dim>
inline bool AcousticMap<Dim>::inside(const Vec& p_mm) const {
    for (int a = 0; a < Dim; ++a) {
        if (!(p_mm[a] >= 0.0f && p_mm[a] <= extent_[a])) return false;
    }
    return true;
}

// The first 4 * Chunks floats of the records around p_mm, blended: trilinear weights,
// each 4-float chunk as one vector (GCC vector extensions: SSE on x86-64, NEON on ARM).
// sample() blends every chunk, sample_impedance() the first: the same bits.
template <int Dim>
template <int Chunks>
[[gnu::always_inline]] inline void AcousticMap<Dim>::blend_chunks(const Vec& p_mm,
                                                                  float* out) const {
    constexpr int K = int(sizeof(AcousticTexel<Dim>) / sizeof(float));
    static_assert(K % 4 == 0 && Chunks * 4 <= K);
    IVec i0;
    Vec f;
    locate(p_mm, &i0, &f);
    typedef float v4 __attribute__((vector_size(16)));
    auto load = [](const float* p) {
        v4 v;
        std::memcpy(&v, p, sizeof v);
        return v;
    };
    const float* t000 = reinterpret_cast<const float*>(texels_.data() + linear(i0));
    const std::size_t dy = std::size_t(dims_[0]) * K;
    const float gx = 1.0f - f[0], gy = 1.0f - f[1];
    const float w00 = gx * gy, w10 = f[0] * gy, w01 = gx * f[1], w11 = f[0] * f[1];
    for (int c = 0; c < 4 * Chunks; c += 4) {
        const float* t = t000 + c;
        v4 v = w00 * load(t) + w10 * load(t + K) + w01 * load(t + dy) + w11 * load(t + dy + K);
        if constexpr (Dim == 3) {
            const float* u = t + dy * std::size_t(dims_[1]);
            const v4 upper =
                w00 * load(u) + w10 * load(u + K) + w01 * load(u + dy) + w11 * load(u + dy + K);
            v = (1.0f - f[2]) * v + f[2] * upper;
        }
        std::memcpy(out + c, &v, sizeof v);
    }
}

// Forced inline: in the tracer's large step function GCC otherwise calls it and returns
// the 40-byte record through memory (27 % of the step time, measured).
template <int Dim>
[[gnu::always_inline]] inline AcousticTexel<Dim> AcousticMap<Dim>::sample(const Vec& p_mm) const {
    constexpr int K = int(sizeof(AcousticTexel<Dim>) / sizeof(float));
    float out[K];
    blend_chunks<K / 4>(p_mm, out);
    AcousticTexel<Dim> result;
    std::memcpy(&result, out, sizeof result);
    return result;
}

template <int Dim>
[[gnu::always_inline]] inline ImpedanceSample<Dim> AcousticMap<Dim>::sample_impedance(
    const Vec& p_mm) const {
    static_assert(offsetof(AcousticTexel<Dim>, grad_impedance) + sizeof(float) * Dim <= 16);
    float v[4];
    blend_chunks<1>(p_mm, v);
    ImpedanceSample<Dim> result;
    result.impedance = v[0];
    for (int a = 0; a < Dim; ++a) result.grad_impedance[a] = v[1 + a];
    return result;
}

// One float field of `stride` floats per texel (field points at texel 0's), with
// sample()'s weights and order of operations: the same value sample() gives.
template <int Dim>
[[gnu::always_inline]] inline float AcousticMap<Dim>::sample_field(const float* field,
                                                                   std::size_t stride,
                                                                   const Vec& p_mm) const {
    IVec i0;
    Vec f;
    locate(p_mm, &i0, &f);
    const float* t = field + linear(i0) * stride;
    const std::size_t dx = stride, dy = std::size_t(dims_[0]) * stride;
    const float gx = 1.0f - f[0], gy = 1.0f - f[1];
    const float w00 = gx * gy, w10 = f[0] * gy, w01 = gx * f[1], w11 = f[0] * f[1];
    float v = w00 * t[0] + w10 * t[dx] + w01 * t[dy] + w11 * t[dy + dx];
    if constexpr (Dim == 3) {
        const float* u = t + dy * std::size_t(dims_[1]);
        const float upper = w00 * u[0] + w10 * u[dx] + w01 * u[dy] + w11 * u[dy + dx];
        v = (1.0f - f[2]) * v + f[2] * upper;
    }
    return v;
}

template <int Dim>
[[gnu::always_inline]] inline float AcousticMap<Dim>::sample_refractive_index(
    const Vec& p_mm) const {
    return sample_record_float(offsetof(AcousticTexel<Dim>, refractive_index), p_mm);
}

template <int Dim>
inline float AcousticMap<Dim>::sample_roughness(const Vec& p_mm) const {
    if constexpr (Dim == 3)
        return sample_record_float(offsetof(AcousticTexel<Dim>, surface), p_mm);
    else
        return sample_field(roughness_.data(), 1, p_mm);
}

template <int Dim>
[[gnu::always_inline]] inline const AcousticTexel<Dim>* AcousticMap<Dim>::uniform_block(
    const Vec& p_mm) const {
    std::size_t index = 0;
    for (int a = Dim - 1; a >= 0; --a) {
        const int b =
            std::min(int(p_mm[a] * inverse_spacing_[a]) >> kBlockShift, block_dims_[a] - 1);
        index = index * std::size_t(block_dims_[a]) + std::size_t(b);
    }
    const int32_t record = block_record_[index];
    return record < 0 ? nullptr : &uniform_records_[std::size_t(record)];
}

extern template class AcousticMap<2>;
extern template class AcousticMap<3>;

}  // namespace sonotrace::tissue
