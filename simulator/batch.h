#pragma once
// Internal to the tracer: a batch of particles in lockstep, stored field by field
// (structure of arrays, one array per axis for vectors), and the vector stage that takes
// the common step of all of them at once (vector_step.cpp). tracer.cpp runs everything
// else: emission, uniform runs, interface events, endings.
#include <array>
#include <cstdint>

#include "simulator/interactions.h"
#include "simulator/rng.h"
#include "simulator/trace_settings.h"

namespace sonotrace::simulator::detail {

// Uniform random numbers of one particle, four per Philox call.
struct RandomStream {
    ParticleRng rng;
    std::array<float, 4> block{};
    int used = 4;
    float next() {
        if (used == 4) block = rng.draw4(), used = 0;
        return block[used++];
    }
};

// Interface state of a particle (Batch::in_interface). 32 bits: the vector stage compares
// it lane by lane with float masks. (An enum, not a char type: stores through a char may
// alias anything, which made the compiler reload the particle's state after each update.)
enum class InterfaceState : int32_t {
    outside,            // flat or gently graded medium
    crossing,           // transmitting through a sharp interface
    leaving_reflected,  // reflected; leaves without refracting
    graded,             // steep but no plateau near: graded medium
};
constexpr InterfaceState kOutside = InterfaceState::outside;
constexpr InterfaceState kCrossing = InterfaceState::crossing;
constexpr InterfaceState kLeavingAfterReflection = InterfaceState::leaving_reflected;
constexpr InterfaceState kGraded = InterfaceState::graded;
// In the graded state the interface search is repeated every this many steep steps.
constexpr int32_t kGradedRecheckSteps = 8;

// Vectors of N lanes, one array per axis.
template <int Dim, int N>
struct LaneVectors {
    std::array<std::array<float, N>, Dim> axis{};
    Vec<Dim> operator[](int k) const {
        Vec<Dim> v;
        for (int a = 0; a < Dim; ++a) v[a] = axis[std::size_t(a)][std::size_t(k)];
        return v;
    }
    void set(int k, const Vec<Dim>& v) {
        for (int a = 0; a < Dim; ++a) axis[std::size_t(a)][std::size_t(k)] = v[a];
    }
    void copy(int to, int from) {
        for (auto& lane : axis) lane[std::size_t(to)] = lane[std::size_t(from)];
    }
};

// Particles of one batch, stored field by field (structure of arrays).
template <int Dim>
struct Batch {
    static constexpr int kSize = 64;
    static constexpr std::size_t N = kSize;
    LaneVectors<Dim, kSize> position, direction;
    std::array<float, N> energy{}, initial_energy{}, optical_depth{}, scatter_target{};
    // Product of the probabilities of the stochastic choices made so far (R^2 for each
    // reflection taken, 1 - R^2 for each transmission, the survival of each roulette):
    // by reciprocity the echo's way back makes the same crossings, so its two-way
    // intensity carries this factor again.
    std::array<float, N> return_factor{};
    // The energy below which the roulette is looked at: its threshold at the particle's
    // last look (it falls with time, TraceSettings::roulette_loss_db_per_mm).
    std::array<float, N> roulette_below{};
    std::array<float, N> previous_index{};  // n sampled at the previous step's position
    // Deposits gather per particle while it stays in one texel (2-3 steps at the default
    // step), then go to the map in one write: the map writes were cache misses.
    std::array<uint32_t, N> pending_texel{};
    std::array<float, N> pending_fluence{}, pending_absorbed{};
    std::array<double, N> time{}, path_length{};
    std::array<uint16_t, N> bounces{};
    std::array<uint8_t, N> rough_bounces{};  // of those, reflections into a rough lobe
    std::array<InterfaceState, N> in_interface{};
    std::array<int32_t, N> graded_steps{};     // steps since the last interface check in kGraded
    LaneVectors<Dim, kSize> interface_normal;  // normal of the interface being crossed
    std::array<uint32_t, N> particle{};
    // The particle's receive weights (TraceSettings::receive_weights), looked up once:
    // every step's echo profile reads them.
    std::array<const float*, N> receive_row{};
    std::array<int, N> path{};  // index into LineOutput::paths or -1
    std::array<RandomStream, N> random{};
    int count = 0;

    void remove(int k) {  // swap with the last live particle
        const int last = --count;
        const auto to = std::size_t(k), from = std::size_t(last);
        position.copy(k, last), direction.copy(k, last), interface_normal.copy(k, last);
        energy[to] = energy[from], initial_energy[to] = initial_energy[from];
        return_factor[to] = return_factor[from], roulette_below[to] = roulette_below[from];
        optical_depth[to] = optical_depth[from], scatter_target[to] = scatter_target[from];
        previous_index[to] = previous_index[from];
        pending_texel[to] = pending_texel[from];
        pending_fluence[to] = pending_fluence[from];
        pending_absorbed[to] = pending_absorbed[from];
        time[to] = time[from], path_length[to] = path_length[from];
        bounces[to] = bounces[from], in_interface[to] = in_interface[from];
        rough_bounces[to] = rough_bounces[from];
        graded_steps[to] = graded_steps[from];
        particle[to] = particle[from], path[to] = path[from], random[to] = random[from];
        receive_row[to] = receive_row[from];
    }
};

// ---- the vector stage (vector_step.cpp) ----

// The fields sampled at each lane's position (the scalar stage interpolates them) and
// whether the general step applies to the lane: not in a uniform block, whose record
// step() would use as it is.
template <int Dim>
struct LaneFields {
    static constexpr std::size_t N = Batch<Dim>::N;
    alignas(32) std::array<float, N> refractive_index{}, impedance{}, attenuation{}, backscatter{};
    alignas(32) std::array<std::array<float, N>, Dim> grad_refractive_index{}, grad_impedance{};
    alignas(32) std::array<uint32_t, N> texel{};    // the deposit texel of the position
    alignas(32) std::array<int32_t, N> block{};     // find_uniform_blocks
    alignas(32) std::array<int32_t, N> eligible{};  // -1: the general step applies, 0: step()
};

// Deposit maps are numbered in tiles of 2^kDepositTileShift texels per axis (DepositTiles
// in tracer.cpp; sample_lanes computes the same numbers).
constexpr int kDepositTileShift = 3;

// The map as sample_lanes reads it: tissue::AcousticMap's records and locate(), and the
// tracer's deposit texel numbering (LineTracer::texel_index).
template <int Dim>
struct MapView {
    // AcousticTexel<Dim> records, x fastest: Z, grad Z, n, grad n, attenuation, backscatter
    // (the order sample_lanes stores fields in; test LaneSamplingIsTheMapsSampling).
    const float* texels = nullptr;
    std::array<int32_t, Dim> dims{};
    std::array<float, Dim> inverse_spacing{};  // the map's (locate(), texel_index())
    std::array<int32_t, Dim> deposit_tiles{};  // deposit tiles per axis
    bool deposit_texels = true;
    // Distance (mm) ahead along each lane's direction whose corner records are
    // prefetched (the next step's position); 0: none.
    float prefetch_mm = 0.0f;
    // Uniform blocks (AcousticMap::uniform_block): null if uniform runs are off.
    const int32_t* block_records = nullptr;
    std::array<int32_t, Dim> block_dims{};
    int block_shift = 3;
};

// Per live lane (of `count`): the record index of the uniform block the lane's position
// is in (AcousticMap::block_records; -1 if it varies or uniform runs are off) in `block`,
// and `eligible` -1 where that is -1. Up to the next multiple of 8, other lanes get block
// -1 and eligible 0.
void find_uniform_blocks(const MapView<2>& map, const Batch<2>& batch, LaneFields<2>& fields,
                         int count);
void find_uniform_blocks(const MapView<3>& map, const Batch<3>& batch, LaneFields<3>& fields,
                         int count);

// The fields at the positions of lanes [0, lanes) whose `eligible` is -1, as
// AcousticMap::sample() gives them bit for bit, and (deposit_texels) their deposit texels.
// Lanes a multiple of 8; other lanes' fields are left unspecified.
void sample_lanes(const MapView<2>& map, const Batch<2>& batch, LaneFields<2>& fields, int lanes);
void sample_lanes(const MapView<3>& map, const Batch<3>& batch, LaneFields<3>& fields, int lanes);

// Points for sample_impedance_points (the interface searches' lines), one array per axis,
// and what is sampled there: per point Z and grad Z in AcousticMap::sample_impedance()'s
// bits, as the first 1 + Dim floats of a 4-float record (the map's first 4 floats).
template <int Dim>
struct ImpedancePoints {
    static constexpr int kSize = 64;
    alignas(32) std::array<std::array<float, kSize>, Dim> position{};
    alignas(32) std::array<std::array<float, 4>, kSize> sample{};
};

// Z and grad Z at points [0, count) (count <= kSize); points up to the next multiple of
// 8 are sampled too and must be finite (they are left zero or from earlier use).
void sample_impedance_points(const MapView<2>& map, ImpedancePoints<2>& points, int count);
void sample_impedance_points(const MapView<3>& map, ImpedancePoints<3>& points, int count);

// What the vector stage leaves to the scalar one: lane masks (bit k: lane k; lanes past
// the batch's count may be set) and the sums to deposit.
template <int Dim>
struct LaneResults {
    static constexpr std::size_t N = Batch<Dim>::N;
    static_assert(N <= 64);
    uint64_t to_step = 0;  // an event or a state the vector stage does not take: step() does it
    uint64_t flush = 0;    // the particle changed texel: deposit the flush_* sums
    uint64_t may_end = 0;  // outside the domain, past a limit or below the roulette energy
    alignas(32) std::array<uint32_t, N> flush_texel{};
    alignas(32) std::array<float, N> flush_fluence{}, flush_absorbed{};
    // For the echo profile (StepConstants::profile): the step's start position and time,
    // and what it adds to the illumination and the scattered intensity (profile_terms).
    alignas(32) std::array<std::array<float, N>, Dim> start_position{};
    alignas(32) std::array<float, N> profile_lit{}, profile_scattered{};
    alignas(32) std::array<double, N> start_time{};
};

// The step's settings, as the scalar step() uses them (LineTracer's constructor).
template <int Dim>
struct StepConstants {
    float step_mm = 0.5f;
    float attenuation_per_mm = 0.0f;  // Np/mm per dB/(cm MHz)
    float scattering_rate_per_mm = 0.0f;
    float threshold2 = 0.0f, inverse_texel2 = 1.0f;  // the interface test, squared
    double step_time_per_index = 0.0;                // s per step per unit refractive index
    double max_path_mm = 0.0, max_time_s = 0.0;
    std::array<float, Dim> extent{};  // the domain [0, extent] per axis
    bool deposition_maps = true, attenuation = true, scattering = true, refraction = true;
    bool profile = false;
    float profile_scale = 0.0f;               // rate * step * echo fraction per backscatter^2
    const ReceiveWeights* receive = nullptr;  // TraceSettings::receive_weights
};

// Takes the general step (what LineTracer::step does when nothing but absorption,
// scattering's optical depth, the interface test and refraction happens) for lanes
// [0, lanes) of the batch, lanes a multiple of 8. Lanes it does not take (mask
// LaneResults::to_step) keep their state untouched for step().
void vector_step(Batch<2>& batch, const LaneFields<2>& fields, const StepConstants<2>& constants,
                 LaneResults<2>& results, int lanes);
void vector_step(Batch<3>& batch, const LaneFields<3>& fields, const StepConstants<3>& constants,
                 LaneResults<3>& results, int lanes);

}  // namespace sonotrace::simulator::detail
