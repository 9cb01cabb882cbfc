#pragma once
// The tracer's deposit maps (fluence and absorbed energy), private to simulator/tracer.cpp:
// per thread, in tiles allocated when first written, on huge pages kept between traces,
// summed in fixed point so that the merged maps do not depend on the threads' order.
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <new>
#include <vector>

#include <tbb/parallel_for.h>
#include <glm/glm.hpp>

#include "simulator/batch.h"
#include "tissue/base/memory.h"
#include "tissue/volume.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

// Deposit maps in 64-bit fixed point: sums are exact and order-independent.
constexpr double kFixedScale = double(int64_t(1) << 36);
inline int64_t to_fixed(double v) {
    return int64_t(v * kFixedScale + 0.5);
}

// One cell per texel, both maps side by side: a step touches one cache line, not two.
struct DepositCell {
    int64_t fluence = 0, absorbed = 0;
};

// 2 MiB blocks on huge pages for deposit tiles, kept for the next trace: the kernel
// clears a new huge page at its first touch, a large share of a 3D trace when every
// trace allocated its own (docs/log). At most kKept blocks (256 MiB) wait between
// traces; they are freed at exit.
class DepositChunks {
  public:
    static constexpr std::size_t kBytes = std::size_t(2) << 20;
    static void* take() {
        Pool& pool = the_pool();
        {
            const std::lock_guard lock(pool.mutex);
            if (!pool.kept.empty()) {
                void* chunk = pool.kept.back();
                pool.kept.pop_back();
                return chunk;
            }
        }
        return base::allocate_huge(kBytes);
    }
    static void give(void* chunk) {
        Pool& pool = the_pool();
        {
            const std::lock_guard lock(pool.mutex);
            if (pool.kept.size() < kKept) {
                pool.kept.push_back(chunk);
                return;
            }
        }
        base::free_huge(chunk, kBytes);
    }

  private:
    static constexpr std::size_t kKept = 128;
    struct Pool {
        std::mutex mutex;
        std::vector<void*> kept;
        ~Pool() {
            for (void* chunk : kept) base::free_huge(chunk, kBytes);
        }
    };
    static Pool& the_pool() {
        static Pool pool;
        return pool;
    }
};

// A thread's deposit maps in tiles of 8^Dim texels, allocated when first written: a fan
// lights part of a volume, and zeroing and merging whole maps per thread cost more than
// the deposits themselves in 3D (page faults, clearing, a pass over every texel). Texels
// are numbered tile by tile, so a particle's deposits stay within one tile for 8 rows.
template <int Dim>
class DepositTiles {
  public:
    static constexpr int kShift = kDepositTileShift, kSide = 1 << kShift;
    static constexpr uint32_t kCells = 1u << (kShift * Dim);
    using Tile = std::array<DepositCell, kCells>;

    explicit DepositTiles(const glm::ivec3& dims) {
        for (int a = 0; a < 3; ++a) tiles_per_axis_[a] = tiles_along(dims[a]);
        tiles_.resize(std::size_t(tiles_per_axis_.x) * std::size_t(tiles_per_axis_.y) *
                      std::size_t(tiles_per_axis_.z));
    }
    // Tiles along an axis of n texels.
    static int tiles_along(int n) { return (n + kSide - 1) >> kShift; }
    // The cell number of texel i (inside the map).
    uint32_t index(const glm::vec<Dim, int>& i) const {
        uint32_t tile = 0, offset = 0;
        for (int a = Dim - 1; a >= 0; --a) {
            tile = tile * uint32_t(tiles_per_axis_[a]) + uint32_t(i[a] >> kShift);
            offset = (offset << kShift) | uint32_t(i[a] & (kSide - 1));
        }
        return tile << (kShift * Dim) | offset;
    }
    DepositCell& operator[](uint32_t cell) {
        Tile*& tile = tiles_[cell >> (kShift * Dim)];
        if (tile == nullptr) tile = new_tile();
        return (*tile)[cell & (kCells - 1)];
    }
    // A hint that `cell` will be written soon (nothing if its tile is not there yet).
    void prefetch(uint32_t cell) const {
        if (const Tile* tile = tiles_[cell >> (kShift * Dim)])
            __builtin_prefetch(&(*tile)[cell & (kCells - 1)], 1);
    }
    std::size_t tile_count() const { return tiles_.size(); }
    const Tile* tile(std::size_t t) const { return tiles_[t]; }
    // The texel of tile t's first cell (cells follow x fastest, then y, then z).
    glm::ivec3 tile_origin(std::size_t t) const {
        glm::ivec3 i(0);
        for (int a = 0; a < Dim; ++a) {
            i[a] = int(t % std::size_t(tiles_per_axis_[a])) * kSide;
            t /= std::size_t(tiles_per_axis_[a]);
        }
        return i;
    }

  private:
    // Tiles come from 2 MiB chunks on huge pages (DepositChunks): deposits land all over
    // the lit part of the map, and 4 KiB pages missed the TLB.
    static constexpr std::size_t kChunkTiles = DepositChunks::kBytes / sizeof(Tile);
    Tile* new_tile() {
        if (chunks_.empty() || chunk_used_ == kChunkTiles) {
            chunks_.emplace_back(static_cast<Tile*>(DepositChunks::take()));
            chunk_used_ = 0;
        }
        return new (chunks_.back().get() + chunk_used_++) Tile{};
    }
    struct FreeChunk {
        void operator()(Tile* chunk) const { DepositChunks::give(chunk); }
    };
    glm::ivec3 tiles_per_axis_{1};
    std::vector<Tile*, base::HugePageAllocator<Tile*>> tiles_;
    std::vector<std::unique_ptr<Tile, FreeChunk>> chunks_;
    std::size_t chunk_used_ = 0;
};

// The threads' tiles summed into the result maps, tile by tile in parallel; integer sums,
// so the order of the threads does not matter. `per_texel`: fixed-point fluence to
// intensity (energy mm per texel to per mm^Dim). Untouched tiles stay zero.
template <int Dim>
void merge_deposits(const std::vector<const DepositTiles<Dim>*>& maps, double per_texel,
                    tissue::Volume& fluence, tissue::Volume& absorbed) {
    if (maps.empty()) return;
    const glm::ivec3 dims = fluence.geometry().dims;
    const std::size_t tiles = maps[0]->tile_count();
    tbb::parallel_for(std::size_t(0), tiles, [&](std::size_t t) {
        if (std::none_of(maps.begin(), maps.end(), [t](auto* m) { return m->tile(t) != nullptr; }))
            return;  // nothing deposited: the result is zero there already
        // Row by row of the tile (cells x fastest), within the map's edge.
        constexpr int side = DepositTiles<Dim>::kSide;
        // The next tile's first half, prefetched: tiles lie anywhere in their chunks, and
        // the hardware's stream prefetch restarts at each.
        for (const DepositTiles<Dim>* m : maps) {
            const auto* next = t + 1 < tiles ? m->tile(t + 1) : nullptr;
            if (next == nullptr) continue;
            for (std::size_t line = 0; line < sizeof(*next) / 128; ++line)
                __builtin_prefetch(reinterpret_cast<const char*>(next->data()) + 64 * line);
        }
        const glm::ivec3 origin = maps[0]->tile_origin(t);
        const int width = std::min(side, dims.x - origin.x);
        const int height = std::min(side, dims.y - origin.y);
        const int depth = Dim == 3 ? std::min(side, dims.z - origin.z) : 1;
        for (int z = 0; z < depth; ++z) {
            for (int y = 0; y < height; ++y) {
                const auto first = uint32_t((z * side + y) * side);
                const std::size_t to = fluence.linear_index(origin.x, origin.y + y, origin.z + z);
                for (int x = 0; x < width; ++x) {
                    const uint32_t c = first + uint32_t(x);
                    int64_t fluence_sum = 0, absorbed_sum = 0;
                    for (const DepositTiles<Dim>* m : maps) {
                        if (const auto* tile = m->tile(t))
                            fluence_sum += (*tile)[c].fluence, absorbed_sum += (*tile)[c].absorbed;
                    }
                    fluence.voxels()[to + std::size_t(x)] = float(double(fluence_sum) * per_texel);
                    absorbed.voxels()[to + std::size_t(x)] =
                        float(double(absorbed_sum) / kFixedScale);
                }
            }
        }
    });
}

}  // namespace
}  // namespace sonotrace::simulator::detail
