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

#include "ui/dataset/frames.h"
#include "ui/dataset/spec.h"

namespace sonotrace::dataset {

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
    uint64_t shards_kept = 0;          // complete before this run
    uint64_t shards_written = 0;       // by this run
    bool stopped = false;              // by RunOptions::stop, before the manifest
    std::vector<std::string> damaged;  // shards found damaged and made again ("path: why")
    bool failed = false;               // under MPI, on ranks other than 0: the job failed, and
                                       // rank 0 throws its one error message
    std::string manifest;              // its path, once every shard is there
};

RunReport make_dataset(const Spec& spec, const RunOptions& options);

// Checks a finished dataset in `dir` against its manifest: every shard the manifest names
// is there, sound (header, content checksum), of the manifest's spec, under its own number,
// with the checksum the manifest lists. Throws InputError naming manifest.json (and the
// field) when the manifest is missing or malformed; damaged shards are listed, not thrown.
struct VerifyReport {
    uint64_t shards = 0;                // named by the manifest
    std::vector<std::string> problems;  // "path: why", one per unsound shard
};
VerifyReport verify_dataset(const std::string& dir,
                            const std::function<void(uint64_t done, uint64_t total)>& progress);

// Throws InputError (field frames_per_shard) when one shard's frames cannot be held in the
// memory this machine has free: checked before the first frame, not found out by swapping.
void check_shard_fits_memory(const Spec& spec);

// The pieces make_dataset is made of, for runs that spread shards over processes
// (ui/dataset/mpi.h):
// the shards `dir` lacks or holds damaged (shard.h's checks); throws InputError for a
// shard of another spec. `kept` counts the sound ones; `damaged` receives "path: why" of
// each damaged one.
std::vector<uint64_t> missing_shards(const Spec& spec, const std::string& dir, uint64_t* kept,
                                     std::vector<std::string>* damaged = nullptr);
// Frames first .. end of shard k, made and written (under a hidden name, renamed when
// complete). Returns false, writing nothing, if `stop` asks to stop between frames;
// `frame_done` is called after each frame.
bool write_one_shard(const FrameMaker& maker, uint64_t k, const std::string& dir,
                     const std::function<bool()>& stop, const std::function<void()>& frame_done);
// The manifest, once every shard is there; returns its path.
std::string write_manifest(const Spec& spec, const std::string& dir);

}  // namespace sonotrace::dataset
