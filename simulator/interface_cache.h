#pragma once
// What an interface event knows of the transition around a point (InterfaceSides) and the
// table that keeps it per texel for one trace (InterfaceCache), private to
// simulator/tracer.cpp, whose LineTracer searches the transitions.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "simulator/interactions.h"
#include "tissue/base/memory.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

// A plateau's values that the reflection decision reads.
struct Plateau {
    float refractive_index = 1.0f, impedance = 1.0f;
};

// What an interface event needs to know of the transition around a point: whether it is
// sharp (a plateau on each side within reach) or graded, and if sharp its patch normal,
// its middle, the plateaus' values and roughness. A function of the point alone, so the
// tracer finds it once per texel and trace (InterfaceCache): in the head, 22 (2D) and 5
// (3D) interface events share each texel, and each search took 40-80 samples.
template <int Dim>
struct InterfaceSides {
    // from_position: the texel's centre is not steep, so a point of it that is searches
    // from itself (InterfaceCache keeps only what a texel's centre gives).
    enum class Kind : uint8_t { graded, sharp, from_position };
    Kind kind = Kind::graded;
    float roughness = 0.0f;       // the rougher plateau's (sharp)
    Plateau low, high;            // the plateaus at lower and higher Z (sharp)
    Vec<Dim> normal{0.0f};        // the zone's normal, towards higher Z (sharp)
    Vec<Dim> patch_normal{0.0f};  // the patch's own, before the zone's average
    Vec<Dim> middle{0.0f};        // where Z is halfway between the plateaus
};

// InterfaceSides per texel, shared by the threads of one trace. An open-addressing table:
// a slot's key is 0 (empty), texel + 1 with kBusy while its owner fills it, then texel + 1.
// Whoever claims a slot fills it; a thread that finds it busy, or finds no free slot
// within kProbes, computes the entry itself. Entries depend on the texel only, so what
// the table holds never changes a result, whatever the threads' timing.
template <int Dim>
class InterfaceCache {
  public:
    // `particles`: sources of the trace; the table holds up to 4 entries per particle
    // (2^12 to 2^18), on huge pages (slots are touched at random). Not `enabled`: it
    // holds nothing and every get() computes.
    InterfaceCache(std::size_t particles, bool enabled) {
        if (!enabled) return;
        int bits = 12;
        while (bits < 18 && (std::size_t(1) << bits) < 4 * particles) ++bits;
        shift_ = 32 - bits;
        capacity_ = std::size_t(1) << bits;
        keys_ = std::make_unique<std::atomic<uint32_t>[]>(capacity_);  // zero: empty
        entries_ = static_cast<InterfaceSides<Dim>*>(
            base::allocate_huge(capacity_ * sizeof(InterfaceSides<Dim>)));
    }
    ~InterfaceCache() {
        if (entries_) base::free_huge(entries_, capacity_ * sizeof(InterfaceSides<Dim>));
    }
    InterfaceCache(const InterfaceCache&) = delete;
    InterfaceCache& operator=(const InterfaceCache&) = delete;

    // The entry of `texel`; `find(entry)` fills one when it is not in the table yet.
    template <class Find>
    const InterfaceSides<Dim>& get(uint32_t texel, InterfaceSides<Dim>& scratch, Find&& find) {
        const uint32_t key = texel + 1;
        if (capacity_ == 0 || key >= kBusy) return find(scratch), scratch;
        std::size_t slot = std::size_t((key * 0x9E3779B1u) >> shift_);
        for (int probe = 0; probe < kProbes; ++probe, slot = (slot + 1) & (capacity_ - 1)) {
            uint32_t seen = keys_[slot].load(std::memory_order_acquire);
            if (seen == 0) {
                if (keys_[slot].compare_exchange_strong(seen, key | kBusy,
                                                        std::memory_order_acquire)) {
                    InterfaceSides<Dim>& entry = entries_[slot];
                    find(entry);
                    keys_[slot].store(key, std::memory_order_release);
                    return entry;
                }
                // Claimed meanwhile: `seen` now holds the claimant's key.
            }
            if (seen == key) return entries_[slot];
            if (seen == (key | kBusy)) break;  // being filled: do not wait
        }
        find(scratch);
        return scratch;
    }

  private:
    static constexpr uint32_t kBusy = 0x80000000u;
    static constexpr int kProbes = 16;
    std::size_t capacity_ = 0;
    int shift_ = 0;
    std::unique_ptr<std::atomic<uint32_t>[]> keys_;
    InterfaceSides<Dim>* entries_ = nullptr;
};

}  // namespace
}  // namespace sonotrace::simulator::detail
