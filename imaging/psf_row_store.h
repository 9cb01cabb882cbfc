#pragma once
// The rows PSF tables share (imaging/psf.h): psf.cpp reads them, psf_build.cpp makes them.
#include <memory>
#include <mutex>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "imaging/psf.h"

namespace sonotrace::imaging {

// Rows shared by the tables of probe settings that differ in their imaging depth alone
// (a dataset drawing the depth per frame): a deeper table adds rows, a shallower one
// takes a prefix. With them the plane echoes and the fields of the lines that made rows.
struct PsfTable::RowStore {
    static constexpr double kSnapFraction = 0.125;  // lines share rows at offsets 1/8 pitch apart
    std::mutex build;                               // one table's missing rows at a time
    // Rows in chunks (stable addresses: tables point into them), allocated a chunk at a
    // time (one allocation per row was a tenth of a table's build) and left raw: a row is
    // constructed where it is filled (start), so the threads that fill the rows, not the
    // set-up that numbers them, take the first touch of their pages.
    struct Rows {
        static_assert(std::is_trivially_destructible_v<Row>);
        static constexpr std::size_t kChunk = 64;  // 40 kB: under malloc's mmap threshold
        std::vector<Row*> chunks;
        std::size_t count = 0;
        Rows() = default;
        Rows(const Rows&) = delete;
        Rows& operator=(const Rows&) = delete;
        ~Rows() {
            for (Row* chunk : chunks) std::allocator<Row>().deallocate(chunk, kChunk);
        }
        Row& operator[](std::size_t r) { return chunks[r / kChunk][r % kChunk]; }
        std::size_t size() const { return count; }
        void emplace_back() {
            if (count == chunks.size() * kChunk)
                chunks.push_back(std::allocator<Row>().allocate(kChunk));
            ++count;
        }
        static Row& start(Row* row) { return *std::construct_at(row); }
    };
    Rows rows;
    std::vector<int> line;  // the line that made each row (read under `build` only)
    std::vector<std::vector<int>> row_of_depth;  // [depth index][line] -> rows
    tbb::concurrent_unordered_map<uint64_t, std::complex<double>, MixedKey> plane_echoes;
    std::mutex fields_mutex;
    std::unordered_map<int, std::shared_ptr<const probe::LineFields>> fields;  // by line
};

}  // namespace sonotrace::imaging
