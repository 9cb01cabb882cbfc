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
// metropolis: the count ~ Poisson of the integral estimated at the 2x2x2 Gauss points,
//             positions from an independence Metropolis chain with uniform proposals
//             (accept min(1, rho(y)/rho(x))), after a short burn-in. Fewer density
//             evaluations where rho_max is far above the mean, at the price of a count
//             exact only for densities the Gauss rule integrates exactly.
#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>

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
        : state_(mix(seed ^ mix(uint64_t(repetition) << 32 | cell))) {}
    float next() {
        if (has_spare_) {
            has_spare_ = false;
            return spare_;
        }
        state_ += kGamma;
        const uint64_t bits = mix(state_);
        spare_ = float(uint32_t(bits) >> 8) * (1.0f / 16777216.0f);
        has_spare_ = true;
        return float(uint32_t(bits >> 32) >> 8) * (1.0f / 16777216.0f);
    }

  private:
    static constexpr uint64_t kGamma = 0x9E3779B97F4A7C15ull;
    static uint64_t mix(uint64_t z) {
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    uint64_t state_;
    float spare_ = 0.0f;
    bool has_spare_ = false;
};

// A Poisson(mean) count by inversion, given p_zero = exp(-mean) (callers that draw the
// same mean often precompute it); mean <= 100 so p_zero stays representable.
inline int poisson_count_inversion(double mean, double p_zero, CellRandom& random) {
    const double u = random.next();
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
