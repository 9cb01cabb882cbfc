#pragma once
// Stateless mixers (splitmix64's finaliser, lowbias32) for counter-based randomness keyed by
// integers: beams (probe/) and the scatterer field (imaging/) derive their numbers from
// it, so results do not depend on evaluation order or thread count.
#include <cstdint>

namespace sonotrace::base {

// splitmix64's finaliser alone (generators that add the golden gamma themselves).
inline uint64_t finalise64(uint64_t x) {
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

inline uint64_t mix64(uint64_t x) {
    return finalise64(x + 0x9e3779b97f4a7c15ull);
}

// A 32-bit mixer: "lowbias32" (C. Wellons).
inline uint32_t mix32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    return x ^ (x >> 16);
}

}  // namespace sonotrace::base
