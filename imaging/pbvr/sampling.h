#pragma once
// Cell-by-cell particle generation of object-space PBVR (Sakamoto & Koyamada, sec. 3.3.1),
// generic over the density so tests can feed analytic ones.
//
// uniform:    a Poisson process of intensity rho in the cell by thinning: candidates are a
//             Poisson process of the cell's majorant rho_max (count ~ Poisson(rho_max V),
//             positions uniform), each kept with probability rho(x) / rho_max. The kept
//             count is Poisson with mean exactly the density integral of eq. 14, and the
//             positions follow rho inside the cell (no blocky noise: that comes from
//             placing a cell's expected count uniformly, which thinning does not do).
//             The renderer draws its numbers stratified across repetitions
//             (CellSequence, thin_stratified): each repetition is still this process.
// metropolis: the count ~ Poisson of the integral estimated at the 2x2x2 Gauss points,
//             positions from an independence Metropolis chain with uniform proposals
//             (accept min(1, rho(y)/rho(x))), after a short burn-in. Fewer density
//             evaluations where rho_max is far above the mean, at the price of a count
//             exact only for densities the Gauss rule integrates exactly.
#include <array>
#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>

#include "tissue/base/hash.h"

namespace sonotrace::imaging::pbvr {

enum class Sampling { uniform, metropolis };

// Uniform numbers for one cell of one repetition: a SplitMix64 sequence (Steele et al.
// 2014; passes BigCrush) started from a hash of (seed, repetition, cell), two 24-bit
// floats per step. Like the tracer's Philox, a cell's numbers are a function of (seed,
// repetition, cell, draw) and never of the thread that draws them; each step costs two
// multiplications instead of Philox's ten rounds (this generator runs ~4 times per
// particle).
class CellRandom {
  public:
    CellRandom(uint64_t seed, uint32_t repetition, uint32_t cell)
        : state_(base::finalise64(seed ^ base::finalise64(uint64_t(repetition) << 32 | cell))) {}
    float next() {
        if (has_spare_) {
            has_spare_ = false;
            return spare_;
        }
        state_ += kGamma;
        const uint64_t bits = base::finalise64(state_);
        spare_ = float(uint32_t(bits) >> 8) * (1.0f / 16777216.0f);
        has_spare_ = true;
        return float(uint32_t(bits >> 32) >> 8) * (1.0f / 16777216.0f);
    }

  private:
    static constexpr uint64_t kGamma = 0x9E3779B97F4A7C15ull;
    uint64_t state_;
    float spare_ = 0.0f;
    bool has_spare_ = false;
};

// Sobol' points in dimensions 0-3 (direction numbers of Joe & Kuo, new-joe-kuo-6.21201:
// s = 1, 2, 3; a = 0, 1, 1; m = {1}, {1, 3}, {1, 3, 1}), 32 bits, and Owen's nested
// uniform scrambling by hashing (Burley 2020, "Practical hash-based Owen scrambling"),
// which CellSequence applies to the point index.
namespace sobol {
constexpr std::array<std::array<uint32_t, 32>, 4> make_directions() {
    std::array<std::array<uint32_t, 32>, 4> v{};
    for (int i = 0; i < 32; ++i) v[0][std::size_t(i)] = 1u << (31 - i);  // van der Corput
    constexpr int s[4] = {0, 1, 2, 3}, a[4] = {0, 0, 1, 1};
    constexpr uint32_t m[4][3] = {{}, {1}, {1, 3}, {1, 3, 1}};
    for (int d = 1; d < 4; ++d) {
        auto& dv = v[std::size_t(d)];
        for (int i = 0; i < 32; ++i) {
            if (i < s[d]) {
                dv[std::size_t(i)] = m[d][i] << (31 - i);
                continue;
            }
            uint32_t x = dv[std::size_t(i - s[d])] ^ (dv[std::size_t(i - s[d])] >> s[d]);
            for (int k = 1; k < s[d]; ++k)
                if ((a[d] >> (s[d] - 1 - k)) & 1) x ^= dv[std::size_t(i - k)];
            dv[std::size_t(i)] = x;
        }
    }
    return v;
}
inline constexpr auto kDirections = make_directions();

inline uint32_t reverse_bits(uint32_t x) {
    x = (x >> 16) | (x << 16);
    x = ((x & 0xFF00FF00u) >> 8) | ((x & 0x00FF00FFu) << 8);
    x = ((x & 0xF0F0F0F0u) >> 4) | ((x & 0x0F0F0F0Fu) << 4);
    x = ((x & 0xCCCCCCCCu) >> 2) | ((x & 0x33333333u) << 2);
    return ((x & 0xAAAAAAAAu) >> 1) | ((x & 0x55555555u) << 1);
}

// Points of indices below 2^16 given as bit-reversed 32-bit words (the index's bit k is
// the word's bit 31 - k, as the scramble leaves it): the XOR of the direction numbers of
// the top byte's bits (index bits 0-7), then of the next byte's (index bits 8-15).
constexpr std::array<std::array<std::array<uint32_t, 256>, 2>, 4> make_byte_tables() {
    std::array<std::array<std::array<uint32_t, 256>, 2>, 4> t{};
    for (int d = 0; d < 4; ++d)
        for (int half = 0; half < 2; ++half)
            for (uint32_t byte = 0; byte < 256; ++byte) {
                uint32_t x = 0;  // word bit 7 - k of this byte is index bit 8 * half + k
                for (int k = 0; k < 8; ++k)
                    if (byte >> (7 - k) & 1u)
                        x ^= kDirections[std::size_t(d)][std::size_t(8 * half + k)];
                t[std::size_t(d)][std::size_t(half)][byte] = x;
            }
    return t;
}
inline constexpr auto kPoints = make_byte_tables();
inline uint32_t point_of_reversed(uint32_t reversed_index, int dim) {
    const auto& t = kPoints[std::size_t(dim)];
    return t[0][reversed_index >> 24] ^ t[1][reversed_index >> 16 & 0xFFu];
}

// Owen's nested uniform scramble on bit-reversed values: each bit is flipped by a hash of
// the bits below it, which are the more significant ones before reversal (Laine & Karras
// 2011, constants of Burley 2020).
inline uint32_t scramble_reversed(uint32_t x, uint32_t seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}
}  // namespace sobol

// A cell's numbers across repetitions: for each draw (the count; each candidate's
// position and thinning number, one 4D point), a Sobol' point whose index is the
// repetition under a nested scramble, with a random digital shift per coordinate; index
// scramble and shifts are hashes of (seed, cell, draw). Within one repetition every
// number is uniform and independent of the others, so each repetition is the same
// Poisson process as with CellRandom; across repetitions a cell's counts and its
// candidates are stratified instead of independent. (A shared sequence shifted per cell
// is not enough: every cell's particles then move by the same offset from one repetition
// to the next, and the images correlate.)
class CellSequence {
  public:
    CellSequence(uint64_t seed, uint32_t repetition, uint32_t cell)
        : CellSequence(
              base::finalise64(seed ^ base::finalise64(uint64_t(cell) << 32 | 0xFFFFFFFFu)),
              repetition) {}
    // The same for any stream of draws named by a 64-bit key (the tetrahedral path's
    // fragments, one per tetrahedron and sub-pixel).
    static CellSequence of_stream(uint64_t seed, uint32_t repetition, uint64_t stream) {
        return CellSequence(base::finalise64(seed ^ base::finalise64(stream)), repetition);
    }
    float count_uniform() const {
        const uint64_t h = base::finalise64(key_);
        return value(index(uint32_t(h)), uint32_t(h >> 32), 0);
    }
    // Candidate `slot`'s position in the unit cube (x, y, z) and thinning number (w).
    glm::vec4 candidate(uint32_t slot) const {
        const uint64_t h = base::finalise64(key_ + slot + 1);
        const auto a = uint32_t(h), b = uint32_t(h >> 32);
        const uint32_t i = index(a);
        return {value(i, b, 0), value(i, base::mix32(b + 1), 1), value(i, base::mix32(b + 2), 2),
                value(i, base::mix32(b + 3), 3)};
    }

  private:
    CellSequence(uint64_t key, uint32_t repetition)
        : key_(key), reversed_repetition_(sobol::reverse_bits(repetition)) {}
    // The Sobol' index of this repetition for one draw: the repetition index shuffled by
    // a nested scramble of its own per draw (Burley's shuffled Owen-scrambled Sobol'),
    // kept below 2^16 (a bijection there). The first 2^m repetitions still take an
    // aligned block of 2^m points, which is stratified; but the draws no longer share
    // one index. With a shared index, points r and r + 2^k agree in their first k bits
    // in every draw, so repetitions r and r + 128 drew nearly the same particles
    // everywhere (the slab test's error grew with the repetitions).
    uint32_t index(uint32_t seed) const {  // bit-reversed (sobol::point_of_reversed)
        return sobol::scramble_reversed(reversed_repetition_, seed);
    }
    // Coordinate `dim` of point `index` under a random digital shift (an XOR with
    // `shift`): uniform, and it keeps the stratification of the points.
    static float value(uint32_t index, uint32_t shift, int dim) {
        return float((sobol::point_of_reversed(index, dim) ^ shift) >> 8) * (1.0f / 16777216.0f);
    }
    uint64_t key_;
    uint32_t reversed_repetition_;
};

// A Poisson(mean) count by inversion of the uniform u, given p_zero = exp(-mean) (callers
// that draw the same mean often precompute it); mean <= 100 so p_zero stays representable.
inline int poisson_count_inversion(double mean, double p_zero, double u) {
    double p = p_zero, cumulative = p;
    int n = 0;
    while (u > cumulative && n < 10000) {
        ++n;
        p *= mean / n;
        cumulative += p;
        if (p < 1e-300) break;
    }
    return n;
}
inline int poisson_count_inversion(double mean, double p_zero, CellRandom& random) {
    return poisson_count_inversion(mean, p_zero, double(random.next()));
}

// A Poisson(mean) count (sums of parts of at most 100); cost grows with the mean, like
// the work of placing the particles.
inline int poisson_count(double mean, CellRandom& random) {
    int count = 0;
    while (mean > 0.0) {
        const double part = std::min(mean, 100.0);
        mean -= part;
        count += poisson_count_inversion(part, std::exp(-part), random);
    }
    return count;
}

// Thinning of `candidates` uniform candidates in the box (see sample_cell_uniform).
template <typename Density, typename Emit>
void thin_candidates(const glm::vec3& origin, const glm::vec3& size, float majorant, int candidates,
                     const Density& density, CellRandom& random, const Emit& emit) {
    for (int c = 0; c < candidates; ++c) {
        const glm::vec3 x = origin + size * glm::vec3(random.next(), random.next(), random.next());
        const auto [rho, payload] = density(x);
        if (random.next() * majorant < rho) emit(x, payload);
    }
}

// Thinning with the cell's numbers stratified across repetitions (CellSequence); the
// count is Poisson(candidates_mean), p_zero = exp(-candidates_mean), mean <= 100.
template <typename Density, typename Emit>
void thin_stratified(const glm::vec3& origin, const glm::vec3& size, float majorant,
                     double candidates_mean, double p_zero, const Density& density,
                     const CellSequence& sequence, const Emit& emit) {
    const int candidates =
        poisson_count_inversion(candidates_mean, p_zero, double(sequence.count_uniform()));
    for (int c = 0; c < candidates; ++c) {
        const glm::vec4 u = sequence.candidate(uint32_t(c));
        const glm::vec3 x = origin + size * glm::vec3(u);
        const auto [rho, payload] = density(x);
        if (u.w * majorant < rho) emit(x, payload);
    }
}

// Thinning in the box [origin, origin + size]. `density(x)` returns rho at x (any
// payload the caller needs travels through `emit(x, value)` as the density's by-product:
// density returns a pair {rho, payload}).
template <typename Density, typename Emit>
void sample_cell_uniform(const glm::vec3& origin, const glm::vec3& size, float majorant,
                         const Density& density, CellRandom& random, const Emit& emit) {
    if (!(majorant > 0.0f)) return;
    const double volume = double(size.x) * size.y * size.z;
    const int candidates = poisson_count(double(majorant) * volume, random);
    thin_candidates(origin, size, majorant, candidates, density, random, emit);
}

// Metropolis in the box; `burn_in` proposals before the first particle.
template <typename Density, typename Emit>
void sample_cell_metropolis(const glm::vec3& origin, const glm::vec3& size, const Density& density,
                            CellRandom& random, const Emit& emit, int burn_in = 4) {
    // Integral by the 2x2x2 Gauss-Legendre rule (exact for cubic polynomials per axis).
    constexpr float g = 0.21132487f;  // (1 - 1/sqrt 3) / 2
    double integral = 0.0;
    for (int corner = 0; corner < 8; ++corner) {
        const glm::vec3 t(corner & 1 ? 1.0f - g : g, corner & 2 ? 1.0f - g : g,
                          corner & 4 ? 1.0f - g : g);
        integral += double(density(origin + size * t).first);
    }
    integral *= double(size.x) * size.y * size.z / 8.0;
    const int count = poisson_count(integral, random);
    if (count == 0) return;
    glm::vec3 x = origin + size * glm::vec3(random.next(), random.next(), random.next());
    auto current = density(x);
    for (int step = 0; step < burn_in + count; ++step) {
        const glm::vec3 y = origin + size * glm::vec3(random.next(), random.next(), random.next());
        const auto proposed = density(y);
        // accept with min(1, rho(y)/rho(x)); a zero-density start always moves
        const float u = random.next();
        if (current.first <= 0.0f || u * current.first < proposed.first) x = y, current = proposed;
        if (step >= burn_in) emit(x, current.second);
    }
}

}  // namespace sonotrace::imaging::pbvr
