#pragma once
// A stateless 64-bit mixer (splitmix64's finaliser) for counter-based randomness keyed by
// integers: beams (probe/) and the scatterer field (imaging/) derive their numbers from
// it, so results do not depend on evaluation order or thread count.
#include <cstdint>

namespace sonotrace::tissue {

inline uint64_t mix64(uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

}  // namespace sonotrace::tissue
