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

#include "simulator/rng.h"

namespace sonotrace::imaging::pbvr {

enum class Sampling { uniform, metropolis };

// Uniform numbers for one cell of one repetition, four per Philox call.
class CellRandom {
  public:
    CellRandom(uint64_t seed, uint32_t repetition, uint32_t cell) : rng_(seed, repetition, cell) {}
    float next() {
        if (used_ == 4) block_ = rng_.draw4(), used_ = 0;
        return block_[std::size_t(used_++)];
    }

  private:
    simulator::ParticleRng rng_;
    std::array<float, 4> block_{};
    int used_ = 4;
};

// A Poisson(mean) count by inversion (in steps of at most 100 so exp(-mean) stays
// representable); cost grows with the mean, like the work of placing the particles.
inline int poisson_count(double mean, CellRandom& random) {
    int count = 0;
    while (mean > 0.0) {
        const double part = std::min(mean, 100.0);
        mean -= part;
        const double u = random.next();
        double p = std::exp(-part), cumulative = p;
        int n = 0;
        while (u > cumulative && n < 10000) {
            ++n;
            p *= part / n;
            cumulative += p;
            if (p < 1e-300) break;
        }
        count += n;
    }
    return count;
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
    for (int c = 0; c < candidates; ++c) {
        const glm::vec3 x =
            origin + size * glm::vec3(random.next(), random.next(), random.next());
        const auto [rho, payload] = density(x);
        if (random.next() * majorant < rho) emit(x, payload);
    }
}

// Metropolis in the box; `burn_in` proposals before the first particle.
template <typename Density, typename Emit>
void sample_cell_metropolis(const glm::vec3& origin, const glm::vec3& size,
                            const Density& density, CellRandom& random, const Emit& emit,
                            int burn_in = 4) {
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
