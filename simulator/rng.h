#pragma once
// Counter-based random numbers: Philox4x32-10 (Salmon et al., "Parallel random numbers:
// as easy as 1, 2, 3", SC 2011). The output is a pure function of (key, counter), so a
// particle's random numbers depend only on (seed, line, particle, event) and never on
// which thread traced it or in what order: results are identical on any thread count.
#include <array>
#include <cstdint>

namespace sonotrace::simulator {

class Philox4x32 {
  public:
    using Block = std::array<uint32_t, 4>;

    // One 128-bit block of random bits for counter (c0..c3) under key (k0, k1).
    static Block generate(Block counter, uint32_t k0, uint32_t k1) {
        constexpr uint32_t kMul0 = 0xD2511F53u, kMul1 = 0xCD9E8D57u;
        constexpr uint32_t kWeyl0 = 0x9E3779B9u, kWeyl1 = 0xBB67AE85u;
        for (int round = 0; round < 10; ++round) {
            const uint64_t p0 = uint64_t(kMul0) * counter[0];
            const uint64_t p1 = uint64_t(kMul1) * counter[2];
            counter = {uint32_t(p1 >> 32) ^ counter[1] ^ k0, uint32_t(p1),
                       uint32_t(p0 >> 32) ^ counter[3] ^ k1, uint32_t(p0)};
            k0 += kWeyl0;
            k1 += kWeyl1;
        }
        return counter;
    }
};

// Uniform float in [0, 1) from the top 24 bits (every value exactly representable).
inline float to_unit_float(uint32_t bits) {
    return float(bits >> 8) * (1.0f / 16777216.0f);
}

// The random stream of one particle: Philox keyed by the seed, counter = (line, particle,
// event, 0). Each draw4() consumes one event number and yields four uniforms.
class ParticleRng {
  public:
    ParticleRng() = default;
    ParticleRng(uint64_t seed, uint32_t line, uint32_t particle)
        : k0_(uint32_t(seed)), k1_(uint32_t(seed >> 32)), line_(line), particle_(particle) {}

    std::array<float, 4> draw4() {
        const auto bits = Philox4x32::generate({line_, particle_, event_++, 0u}, k0_, k1_);
        return {to_unit_float(bits[0]), to_unit_float(bits[1]), to_unit_float(bits[2]),
                to_unit_float(bits[3])};
    }
    float uniform() { return draw4()[0]; }
    uint32_t events_used() const { return event_; }

  private:
    uint32_t k0_ = 0, k1_ = 0, line_ = 0, particle_ = 0, event_ = 0;
};

}  // namespace sonotrace::simulator
