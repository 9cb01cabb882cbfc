#pragma once
// Making a dataset: the shards of a spec that DIR does not hold yet, then its manifest.
// A shard is written under a hidden name and renamed when complete, so a run that is
// stopped or killed leaves only complete shards; running the same spec into the same
// directory again makes only the missing ones, and the result is byte-identical to an
// uninterrupted run. A directory that holds shards of another spec is refused.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "imaging/dataset/spec.h"

namespace sonotrace::imaging::dataset {

// The file of shard k in `dir`.
std::string shard_path(const std::string& dir, uint64_t shard);

struct RunOptions {
    std::string out_dir;
    // Called after every frame with the frames made and to make in this run.
    std::function<void(uint64_t done, uint64_t total)> progress;
    // Polled between frames: true abandons the shard in flight (nothing of it is kept).
    std::function<bool()> stop;
};

struct RunReport {
    uint64_t shards_kept = 0;     // complete before this run
    uint64_t shards_written = 0;  // by this run
    bool stopped = false;         // by RunOptions::stop, before the manifest
    std::string manifest;         // its path, once every shard is there
};

RunReport make_dataset(const Spec& spec, const RunOptions& options);

}  // namespace sonotrace::imaging::dataset
