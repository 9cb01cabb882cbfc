#pragma once
// The lane types the particle physics is written over, after Mitsuba 3's scalar and packet
// Float: a lane type `Lane` names a float type Lane::F (one particle, or eight in lockstep),
// its integer lanes Lane::I, its comparison masks Lane::Mask and its double lanes
// Lane::D, and supplies the few operations the built-in operators do not:
//
//   Lane::sqrt(F), Lane::widen(F) -> D, Lane::andnot(Mask a, Mask b) = a and not b,
//   Lane::greater(D, double) -> Mask, Lane::any(Mask) -> bool
//
// Arithmetic and comparisons are the operators (GCC's vector extensions give them to the
// eight-wide type), and `select(mask, a, b)` picks per lane. One particle is ScalarLane,
// below; eight are vector_step.cpp's, built for AVX2 and AVX-512. The same source text
// then computes both, operation for operation, so a particle takes the same bits however
// it is stepped (test: Tracer.VectorStepsTakeTheScalarStepsPaths).
#include <array>
#include <cmath>
#include <cstdint>

#define SONOTRACE_LANE_INLINE [[gnu::always_inline]] inline

namespace sonotrace::simulator {

// One particle: bool masks.
struct ScalarLane {
    using F = float;
    using I = int32_t;
    using Mask = bool;
    using D = double;
    static F sqrt(F v) { return std::sqrt(v); }
    static D widen(F v) { return D(v); }
    static Mask andnot(Mask a, Mask b) { return a && !b; }
    static Mask greater(D a, double b) { return a > b; }
    static bool any(Mask m) { return m; }
};

// Per lane: a where the mask is set, else b (the ternary operator is per lane on vectors).
template <class Mask, class A, class B>
SONOTRACE_LANE_INLINE auto select(const Mask& mask, const A& a, const B& b) {
    return mask ? a : b;
}

// A vector of Dim components, each a lane type (one array per axis across lanes).
template <class F, int Dim>
using LaneVec = std::array<F, std::size_t(Dim)>;

template <class F, std::size_t N>
SONOTRACE_LANE_INLINE F dot(const std::array<F, N>& a, const std::array<F, N>& b) {
    F sum = a[0] * b[0];  // left to right, as glm::dot
    for (std::size_t i = 1; i < N; ++i) sum = sum + a[i] * b[i];
    return sum;
}

template <class Mask, class F, std::size_t N>
SONOTRACE_LANE_INLINE std::array<F, N> select(const Mask& mask, const std::array<F, N>& a,
                                              const std::array<F, N>& b) {
    std::array<F, N> out;
    for (std::size_t i = 0; i < N; ++i) out[i] = mask ? a[i] : b[i];
    return out;
}

}  // namespace sonotrace::simulator
