// The general step of a batch, eight particles at a time (GCC vector extensions: AVX2
// registers where the CPU has them, SSE pairs otherwise; a clone for x86-64-v4 adds
// AVX-512's 32 registers and two-source shuffles). In textured tissue (the head)
// nearly every step interpolates and refracts; as scalar code with a branch per physics
// stage it cost ~270 cycles, while lanes in lockstep share one instruction stream.
//
// The step is step.h's take_step(), the one the scalar step calls, here over eight lanes
// (no FMA contraction: this file is built with -ffp-contract=off), so a particle takes the
// same path bit for bit whichever stage steps it (test:
// Tracer.VectorStepsTakeTheScalarStepsPaths). Anything rarer (an interface to search, a
// scattering event, total reflection while crossing, a large attenuation) goes back to
// step() untouched. The interface searches' points are sampled here too
// (sample_impedance_points), eight at a time.
#include <cstring>
#include <type_traits>

// The helpers here (and step.h's stages) return 32-byte vectors by value; they are
// inlined, so the ABI warning about AVX vectors in the SSE build does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"

#include "simulator/batch.h"
#include "simulator/step.h"

namespace sonotrace::simulator::detail {

namespace {

constexpr int kLanes = 8;
typedef float vf __attribute__((vector_size(32)));
typedef int32_t vi __attribute__((vector_size(32)));
typedef double vd __attribute__((vector_size(32)));
typedef int64_t vl __attribute__((vector_size(32)));
typedef float vf4 __attribute__((vector_size(16)));
typedef int32_t vi4 __attribute__((vector_size(16)));

template <class T, class S>
[[gnu::always_inline]] inline T load(const S* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
template <class T, class S>
[[gnu::always_inline]] inline void store(S* p, const T& v) {
    std::memcpy(p, &v, sizeof v);
}

[[gnu::always_inline]] inline vf lane_sqrt(const vf& v) {
    vf out;
    for (int i = 0; i < kLanes; ++i) out[i] = __builtin_sqrtf(v[i]);
    return out;
}

// Lanes 0-3 or 4-7 as doubles, and 4 + 4 double-lane masks as one 8-lane mask.
[[gnu::always_inline]] inline vd low_to_double(const vf& v) {
    return __builtin_convertvector(__builtin_shufflevector(v, v, 0, 1, 2, 3), vd);
}
[[gnu::always_inline]] inline vd high_to_double(const vf& v) {
    return __builtin_convertvector(__builtin_shufflevector(v, v, 4, 5, 6, 7), vd);
}
[[gnu::always_inline]] inline vi join_masks(const vl& low, const vl& high) {
    return __builtin_shufflevector(__builtin_convertvector(low, vi4),
                                   __builtin_convertvector(high, vi4), 0, 1, 2, 3, 4, 5, 6, 7);
}

// A mask vector's lanes (0 or -1) as bits 0-7.
[[gnu::always_inline]] inline uint64_t lane_bits(const vi& mask) {
    uint64_t bits = 0;
    for (int l = 0; l < kLanes; ++l) bits |= uint64_t(mask[l] < 0) << l;
    return bits;
}

// Lanes' records (one 8-float vector each) to fields (one vector of 8 lanes each).
[[gnu::always_inline]] inline void transpose8(const vf (&rows)[kLanes], vf (&columns)[kLanes]) {
    vf t[kLanes], u[kLanes];
    for (int p = 0; p < kLanes; p += 2) {
        t[p] = __builtin_shufflevector(rows[p], rows[p + 1], 0, 8, 1, 9, 4, 12, 5, 13);
        t[p + 1] = __builtin_shufflevector(rows[p], rows[p + 1], 2, 10, 3, 11, 6, 14, 7, 15);
    }
    for (int q = 0; q < kLanes; q += 4) {
        for (int h = 0; h < 2; ++h) {
            u[q + 2 * h] =
                __builtin_shufflevector(t[q + h], t[q + h + 2], 0, 1, 8, 9, 4, 5, 12, 13);
            u[q + 2 * h + 1] =
                __builtin_shufflevector(t[q + h], t[q + h + 2], 2, 3, 10, 11, 6, 7, 14, 15);
        }
    }
    for (int j = 0; j < 4; ++j) {
        columns[j] = __builtin_shufflevector(u[j], u[j + 4], 0, 1, 2, 3, 8, 9, 10, 11);
        columns[j + 4] = __builtin_shufflevector(u[j], u[j + 4], 4, 5, 6, 7, 12, 13, 14, 15);
    }
}

// Lanes' 4-float tails to 4 fields of 8 lanes.
[[gnu::always_inline]] inline void transpose4x8(const vf4 (&rows)[kLanes], vf (&columns)[4]) {
    vf q[4], t[4];
    for (int p = 0; p < 4; ++p)
        q[p] = __builtin_shufflevector(rows[p], rows[p + 4], 0, 1, 2, 3, 4, 5, 6, 7);
    for (int p = 0; p < 4; p += 2) {
        t[p] = __builtin_shufflevector(q[p], q[p + 1], 0, 8, 1, 9, 4, 12, 5, 13);
        t[p + 1] = __builtin_shufflevector(q[p], q[p + 1], 2, 10, 3, 11, 6, 14, 7, 15);
    }
    for (int h = 0; h < 2; ++h) {
        columns[2 * h] = __builtin_shufflevector(t[h], t[h + 2], 0, 1, 8, 9, 4, 5, 12, 13);
        columns[2 * h + 1] = __builtin_shufflevector(t[h], t[h + 2], 2, 3, 10, 11, 6, 7, 14, 15);
    }
}

// sample()'s blend of the four records around a point in one plane, w = (w00, w10, w01,
// w11), for the floats of T from p on.
template <class T, int K>
[[gnu::always_inline]] inline T blend(const float* p, std::size_t dy, const float (&w)[4]) {
    return w[0] * load<T>(p) + w[1] * load<T>(p + K) + w[2] * load<T>(p + dy) +
           w[3] * load<T>(p + dy + K);
}

// AcousticMap::locate() for 8 lanes: the lower corner's record index, the fractions and
// the four weights of a plane (sample()'s operations: glm::clamp, std::min, truncation).
template <int Dim>
[[gnu::always_inline]] inline vi locate_lanes(const MapView<Dim>& m, const vf (&x)[Dim],
                                              vf (&frac)[Dim], vf& w00, vf& w10, vf& w01, vf& w11) {
    vi corner[Dim];
    for (int a = 0; a < Dim; ++a) {
        const auto axis = std::size_t(a);
        const float top = float(m.dims[axis] - 1);
        vf u = x[a] * m.inverse_spacing[axis];
        u = u < 0.0f ? vf{} : u;                // glm::max(u, 0)
        u = top < u ? vf{} + top : u;           // glm::min(u, top)
        vi i = __builtin_convertvector(u, vi);  // truncation, u >= 0
        const vi last = vi{} + (m.dims[axis] - 2);
        i = last < i ? last : i;  // std::min(i, dims - 2)
        corner[a] = i;
        frac[a] = u - __builtin_convertvector(i, vf);
    }
    const vf gx = 1.0f - frac[0], gy = 1.0f - frac[1];
    w00 = gx * gy, w10 = frac[0] * gy, w01 = gx * frac[1], w11 = frac[0] * frac[1];
    vi index = corner[Dim - 1];
    for (int a = Dim - 2; a >= 0; --a) index = index * m.dims[std::size_t(a)] + corner[a];
    return index;
}

// AcousticMap::sample() for 8 lanes: locate() and the weights as vectors, each lane's
// corner records blended as one 8-float vector (plus a 4-float tail in 3D), then turned
// into fields. The operations and their order are sample()'s (glm::clamp, std::min,
// truncation), so the values are the same bits.
template <int Dim>
[[gnu::always_inline]] inline void sample_lanes_impl(const MapView<Dim>& m, const Batch<Dim>& b,
                                                     LaneFields<Dim>& f, int lanes) {
    constexpr int K = Dim == 2 ? 8 : 12;  // floats per record
    const std::size_t dy = std::size_t(m.dims[0]) * K;
    const std::size_t dz = Dim == 3 ? dy * std::size_t(m.dims[1]) : 0;  // between z planes
    for (int base = 0; base < lanes; base += kLanes) {
        const auto at = std::size_t(base);
        const vi eligible = load<vi>(&f.eligible[at]);
        vf x[Dim];
        for (int a = 0; a < Dim; ++a) x[a] = load<vf>(&b.position.axis[std::size_t(a)][at]);
        // -- locate(): corner i0 and fraction per axis
        vf frac[Dim], w00, w10, w01, w11;
        const vi index = locate_lanes(m, x, frac, w00, w10, w01, w11);
        // -- where each lane's next step's corner records lie, to prefetch them: the
        // records of a new texel come from a map beyond the caches (Colin27: 172 MB in 3D,
        // 11.5 MB in 2D), and the blends waited for them. A lane's lines are prefetched
        // before its blend: prefetching all 64 lanes' after the blends filled the miss
        // buffers, and the prefetches stalled.
        vi ahead = vi{};
        if (m.prefetch_mm > 0.0f) {
            for (int a = Dim - 1; a >= 0; --a) {
                const auto axis = std::size_t(a);
                const vf d = load<vf>(&b.direction.axis[axis][at]);
                vf u = (x[a] + m.prefetch_mm * d) * m.inverse_spacing[axis];
                u = u < 0.0f ? vf{} : u;
                const float top = float(m.dims[axis] - 2);
                u = top < u ? vf{} + top : u;
                ahead = ahead * m.dims[axis] + __builtin_convertvector(u, vi);
            }
        }
        // -- each lane's four (eight) corner records, blended
        vf head[kLanes];
        vf4 tail[kLanes];
        for (int l = 0; l < kLanes; ++l) {
            head[l] = vf{};
            tail[l] = vf4{};
            if (eligible[l] == 0) continue;
            if (m.prefetch_mm > 0.0f) {
                const char* next =
                    reinterpret_cast<const char*>(m.texels + std::size_t(uint32_t(ahead[l])) * K);
                // each row's two records: 2 K floats, over two or three cache lines (2D:
                // one or two)
                if constexpr (Dim == 3) {
                    for (const std::size_t row : {std::size_t(0), dy, dz, dz + dy}) {
                        const char* r = next + row * sizeof(float);
                        __builtin_prefetch(r);
                        __builtin_prefetch(r + 64);
                        __builtin_prefetch(r + 2 * K * sizeof(float) - 1);
                    }
                } else {
                    for (const std::size_t row : {std::size_t(0), dy}) {
                        const char* r = next + row * sizeof(float);
                        __builtin_prefetch(r);
                        __builtin_prefetch(r + 2 * K * sizeof(float) - 1);
                    }
                }
            }
            const float* t = m.texels + std::size_t(uint32_t(index[l])) * K;
            const float w[4] = {w00[l], w10[l], w01[l], w11[l]};
            head[l] = blend<vf, K>(t, dy, w);
            if constexpr (Dim == 3) {
                const float fz = frac[2][l];
                head[l] = (1.0f - fz) * head[l] + fz * blend<vf, K>(t + dz, dy, w);
                tail[l] = (1.0f - fz) * blend<vf4, K>(t + 8, dy, w) +
                          fz * blend<vf4, K>(t + dz + 8, dy, w);
            }
        }
        vf field[kLanes];
        transpose8(head, field);
        // AcousticTexel's order: Z, grad Z, n, grad n, attenuation, backscatter
        store(&f.impedance[at], field[0]);
        for (int a = 0; a < Dim; ++a) {
            store(&f.grad_impedance[std::size_t(a)][at], field[1 + a]);
            store(&f.grad_refractive_index[std::size_t(a)][at], field[2 + Dim + a]);
        }
        store(&f.refractive_index[at], field[1 + Dim]);
        if constexpr (Dim == 2) {
            store(&f.attenuation[at], field[6]);
            store(&f.backscatter[at], field[7]);
        } else {
            vf rest[4];
            transpose4x8(tail, rest);
            store(&f.attenuation[at], rest[0]);
            store(&f.backscatter[at], rest[1]);
        }
        // -- the deposit texel: the nearest texel's number in DepositTiles
        if (m.deposit_texels) {
            constexpr int shift = kDepositTileShift;
            vi tile = vi{}, offset = vi{};
            for (int a = Dim - 1; a >= 0; --a) {
                const auto axis = std::size_t(a);
                vi i = __builtin_convertvector(x[a] * m.inverse_spacing[axis] + 0.5f, vi);
                const vi last = vi{} + (m.dims[axis] - 1);
                i = i < 0 ? vi{} : (last < i ? last : i);  // std::clamp(i, 0, dims - 1)
                tile = tile * m.deposit_tiles[axis] + (i >> shift);
                offset = (offset << shift) | (i & ((1 << shift) - 1));
            }
            store(reinterpret_cast<int32_t*>(&f.texel[at]), (tile << (shift * Dim)) | offset);
        }
    }
}

// AcousticMap::sample_impedance() at 8 points at a time: locate() as vectors, then each
// point's first 4-float chunk of its corner records blended (sample()'s operations).
template <int Dim>
[[gnu::always_inline]] inline void sample_impedance_impl(const MapView<Dim>& m,
                                                         ImpedancePoints<Dim>& p, int count) {
    constexpr int K = Dim == 2 ? 8 : 12;  // floats per record
    const std::size_t dy = std::size_t(m.dims[0]) * K;
    const std::size_t dz = Dim == 3 ? dy * std::size_t(m.dims[1]) : 0;
    for (int base = 0; base < count; base += kLanes) {
        const auto at = std::size_t(base);
        vf x[Dim];
        for (int a = 0; a < Dim; ++a) x[a] = load<vf>(&p.position[std::size_t(a)][at]);
        vf frac[Dim], w00, w10, w01, w11;
        const vi index = locate_lanes(m, x, frac, w00, w10, w01, w11);
        for (int l = 0; l < kLanes; ++l) {
            const float* t = m.texels + std::size_t(uint32_t(index[l])) * K;
            const float w[4] = {w00[l], w10[l], w01[l], w11[l]};
            vf4 v = blend<vf4, K>(t, dy, w);
            if constexpr (Dim == 3) {
                const float fz = frac[2][l];
                v = (1.0f - fz) * v + fz * blend<vf4, K>(t + dz, dy, w);
            }
            store(p.sample[at + std::size_t(l)].data(), v);
        }
    }
}

// AcousticMap::uniform_block() for 8 lanes at a time (the positions are inside the map).
template <int Dim>
[[gnu::always_inline]] inline void find_uniform_blocks_impl(const MapView<Dim>& m,
                                                            const Batch<Dim>& b, LaneFields<Dim>& f,
                                                            int count) {
    const vi lane = {0, 1, 2, 3, 4, 5, 6, 7};
    for (int base = 0; base < count; base += kLanes) {
        const auto at = std::size_t(base);
        const vi live = lane + base < count;  // the others' positions are stale
        vi record = vi{} - 1;
        if (m.block_records != nullptr) {
            vi index = vi{};
            for (int a = Dim - 1; a >= 0; --a) {
                const auto axis = std::size_t(a);
                const vf u = load<vf>(&b.position.axis[axis][at]) * m.inverse_spacing[axis];
                vi block = __builtin_convertvector(u, vi) >> m.block_shift;
                const vi last = vi{} + (m.block_dims[axis] - 1);
                block = last < block ? last : block;  // std::min(block, dims - 1)
                index = index * m.block_dims[axis] + block;
            }
            for (int l = 0; l < kLanes; ++l)
                if (live[l]) record[l] = m.block_records[uint32_t(index[l])];
        }
        store(&f.block[at], record);
        store(&f.eligible[at], live & (record >> 31));  // -1 where no uniform block
    }
}

// Eight particles as one lane type of step.h (lanes.h): GCC vector masks, doubles in two
// halves of four.
struct DoubleLanes {
    vd low, high;
};
[[gnu::always_inline]] inline DoubleLanes operator+(const DoubleLanes& a, const DoubleLanes& b) {
    return {a.low + b.low, a.high + b.high};
}
[[gnu::always_inline]] inline DoubleLanes operator+(const DoubleLanes& a, double b) {
    return {a.low + b, a.high + b};
}
[[gnu::always_inline]] inline DoubleLanes operator*(double a, const DoubleLanes& b) {
    return {a * b.low, a * b.high};
}
struct VectorLane {
    using F = vf;
    using I = vi;
    using Mask = vi;
    using D = DoubleLanes;
    [[gnu::always_inline]] static F sqrt(const F& v) { return lane_sqrt(v); }
    [[gnu::always_inline]] static D widen(const F& v) {
        return {low_to_double(v), high_to_double(v)};
    }
    [[gnu::always_inline]] static Mask andnot(const Mask& a, const Mask& b) { return a & ~b; }
    [[gnu::always_inline]] static Mask greater(const D& a, double b) {
        return join_masks(a.low > b, a.high > b);
    }
    [[gnu::always_inline]] static bool any(const Mask& m) { return lane_bits(m) != 0; }
};

// The vector stage's events: each marks its lanes for the scalar step (LaneResults::to_step),
// except the deposits and the echo profile's inputs, which it hands over in LaneResults.
template <int Dim>
struct VectorEvents {
    using State = StepState<VectorLane, Dim>;
    vi to_step;
    vi flush = vi{};
    LaneResults<Dim>& out;
    std::size_t at;
    const Batch<Dim>& batch;
    const StepConstants<Dim>& constants;
    [[gnu::always_inline]] void flush_deposits(const vi& changed, const State& p) {
        flush = changed;
        store(&out.flush_texel[at], p.pending_texel);
        store(&out.flush_fluence[at], p.fluence);
        store(&out.flush_absorbed[at], p.absorbed);
    }
    [[gnu::always_inline]] void beyond_series(const vi& m, const vf&, vf&) { to_step |= m; }
    [[gnu::always_inline]] void scatter_profile(const State& p, const vf& backscatter) {
        if (!constants.profile) return;
        for (std::size_t a = 0; a < Dim; ++a) store(&out.start_position[a][at], p.x[a]);
        store(&out.start_time[at], p.time.low);
        store(&out.start_time[at + 4], p.time.high);
        // Each lane's receive weight from its own row, and its next ones fetched ahead:
        // 64 particles walk their own rows, too many streams for the hardware's prefetcher.
        vf receive = vf{} + 1.0f;
        if (const ReceiveWeights* weights = constants.receive) {
            for (int l = 0; l < kLanes; ++l) {
                const float* row = batch.receive_row[at + std::size_t(l)];
                if (row == nullptr) continue;
                const int column = weights->column(out.start_time[at + std::size_t(l)]);
                receive[l] = row[column];
                if (column + 16 < weights->bins) __builtin_prefetch(row + column + 16);
            }
        }
        const ProfileTerms<VectorLane> terms = profile_terms<VectorLane>(
            p.E, load<vf>(&batch.initial_energy[at]), load<vf>(&batch.return_factor[at]), receive,
            backscatter, constants.profile_scale);
        store(&out.profile_lit[at], terms.lit);
        store(&out.profile_scattered[at], terms.scattered);
    }
    [[gnu::always_inline]] void scattering_event(const vi& m, State&, const vf&) { to_step |= m; }
    [[gnu::always_inline]] void interface_event(const vi& m, State&) { to_step |= m; }
};

// step.h's take_step() for lanes [0, lanes) in groups of eight, then the endings' masks;
// the lanes it takes are committed to the batch, the others stay for the scalar step.
template <int Dim>
[[gnu::always_inline]] inline void step_lanes(Batch<Dim>& b, const LaneFields<Dim>& f,
                                              const StepConstants<Dim>& c, LaneResults<Dim>& out,
                                              int lanes) {
    out.to_step = out.flush = out.may_end = 0;
    for (int base = 0; base < lanes; base += kLanes) {
        const auto at = std::size_t(base);
        StepState<VectorLane, Dim> p;
        StepFields<VectorLane, Dim> fields;
        for (std::size_t a = 0; a < Dim; ++a) {
            p.x[a] = load<vf>(&b.position.axis[a][at]);
            p.r[a] = load<vf>(&b.direction.axis[a][at]);
            p.interface_normal[a] = load<vf>(&b.interface_normal.axis[a][at]);
            fields.grad_refractive_index[a] = load<vf>(&f.grad_refractive_index[a][at]);
            fields.grad_impedance[a] = load<vf>(&f.grad_impedance[a][at]);
        }
        p.E = load<vf>(&b.energy[at]);
        p.fluence = load<vf>(&b.pending_fluence[at]);
        p.absorbed = load<vf>(&b.pending_absorbed[at]);
        p.optical_depth = load<vf>(&b.optical_depth[at]);
        p.scatter_target = load<vf>(&b.scatter_target[at]);
        p.previous_index = load<vf>(&b.previous_index[at]);
        p.pending_texel = load<vi>(&b.pending_texel[at]);
        p.state = load<vi>(&b.in_interface[at]);
        p.graded_steps = load<vi>(&b.graded_steps[at]);
        p.time = {load<vd>(&b.time[at]), load<vd>(&b.time[at + 4])};
        p.path_length = {load<vd>(&b.path_length[at]), load<vd>(&b.path_length[at + 4])};
        fields.refractive_index = load<vf>(&f.refractive_index[at]);
        fields.impedance = load<vf>(&f.impedance[at]);
        fields.attenuation = load<vf>(&f.attenuation[at]);
        fields.backscatter = load<vf>(&f.backscatter[at]);
        fields.texel = load<vi>(&f.texel[at]);

        VectorEvents<Dim> events{~load<vi>(&f.eligible[at]), vi{}, out, at, b, c};
        take_step(p, fields, c, events);
        const vi to_step = events.to_step;

        // -- endings are continues()'s (bounces do not change in this stage)
        const vi past_limit = VectorLane::greater(p.path_length, c.max_path_mm) |
                              VectorLane::greater(p.time, c.max_time_s);
        const vi weak = p.E < load<vf>(&b.roulette_below[at]);
        const vi may_end = ~inside_domain<VectorLane>(p.x, c) | past_limit | weak;

        // -- commit the lanes taken; the others stay as they were for step()
        auto commit = [&](auto* field, const auto& value) {
            using T = std::remove_cvref_t<decltype(value)>;
            const T old = load<T>(field);
            store(field, to_step ? old : value);
        };
        const vl keep[2] = {
            // to_step as two double-lane masks
            __builtin_convertvector(__builtin_shufflevector(to_step, to_step, 0, 1, 2, 3), vl),
            __builtin_convertvector(__builtin_shufflevector(to_step, to_step, 4, 5, 6, 7), vl)};
        auto commit_double = [&](double* field, const DoubleLanes& value) {
            const vd halves[2] = {value.low, value.high};
            for (int h = 0; h < 2; ++h) {
                const vd old = load<vd>(field + 4 * h);
                store(field + 4 * h, keep[h] ? old : halves[h]);
            }
        };
        commit(&b.energy[at], p.E);
        for (std::size_t a = 0; a < Dim; ++a) {
            commit(&b.position.axis[a][at], p.x[a]);
            commit(&b.direction.axis[a][at], p.r[a]);
        }
        commit(&b.pending_fluence[at], p.fluence);
        commit(&b.pending_absorbed[at], p.absorbed);
        commit(reinterpret_cast<int32_t*>(&b.pending_texel[at]), p.pending_texel);
        commit(&b.optical_depth[at], p.optical_depth);
        commit(reinterpret_cast<int32_t*>(&b.in_interface[at]), p.state);
        commit(&b.graded_steps[at], p.graded_steps);
        commit(&b.previous_index[at], p.previous_index);
        commit_double(&b.time[at], p.time);
        commit_double(&b.path_length[at], p.path_length);
        out.to_step |= lane_bits(to_step) << base;
        out.flush |= lane_bits(~to_step & events.flush) << base;
        out.may_end |= lane_bits(~to_step & may_end) << base;
    }
}

}  // namespace

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void vector_step(
    Batch<2>& batch, const LaneFields<2>& fields, const StepConstants<2>& constants,
    LaneResults<2>& results, int lanes) {
    step_lanes(batch, fields, constants, results, lanes);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void vector_step(
    Batch<3>& batch, const LaneFields<3>& fields, const StepConstants<3>& constants,
    LaneResults<3>& results, int lanes) {
    step_lanes(batch, fields, constants, results, lanes);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void sample_lanes(const MapView<2>& map,
                                                                              const Batch<2>& batch,
                                                                              LaneFields<2>& fields,
                                                                              int lanes) {
    sample_lanes_impl(map, batch, fields, lanes);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void sample_lanes(const MapView<3>& map,
                                                                              const Batch<3>& batch,
                                                                              LaneFields<3>& fields,
                                                                              int lanes) {
    sample_lanes_impl(map, batch, fields, lanes);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void sample_impedance_points(
    const MapView<2>& map, ImpedancePoints<2>& points, int count) {
    sample_impedance_impl(map, points, count);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void sample_impedance_points(
    const MapView<3>& map, ImpedancePoints<3>& points, int count) {
    sample_impedance_impl(map, points, count);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void find_uniform_blocks(
    const MapView<2>& map, const Batch<2>& batch, LaneFields<2>& fields, int count) {
    find_uniform_blocks_impl(map, batch, fields, count);
}

[[gnu::target_clones("arch=x86-64-v4", "avx2", "default")]] void find_uniform_blocks(
    const MapView<3>& map, const Batch<3>& batch, LaneFields<3>& fields, int count) {
    find_uniform_blocks_impl(map, batch, fields, count);
}

}  // namespace sonotrace::simulator::detail
