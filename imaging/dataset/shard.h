#pragma once
// HDF5 shards of a dataset (libhdf5, readable with h5py and nothing else):
//
//   /bmode     uint8 [n, H, W]   the frames' grey levels (as simulate's png8)
//   /labels    uint8 [n, H, W]   tissue index per pixel (1-based, the manifest's legend)
//   /frames    [n] table         per frame: index, seed, source, probe, frequency_mhz,
//                                depth_mm, focus_mm, gain_db, dynamic_range_db, position,
//                                lateral, axial, elevation (world mm / unit), pixel_mm,
//                                origin_mm, valid_width, valid_height
//   /envelope/NNNNNNNN, /rf/NNNNNNNN    float32 [lines, samples] per frame (on request)
//   /energy/NNNNNNNN                    float32 [rows, cols] per frame (on request)
//   attributes: spec (the spec, canonical JSON), spec_digest, shard, first_frame,
//               frame_count, version
//
// Images are chunked a frame at a time and deflate-compressed. Nothing time-dependent is
// stored, so the same frames give the same bytes.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "imaging/dataset/frames.h"

namespace sonotrace::imaging::dataset {

// Writes `frames` (shard `shard` of `spec`, in frame order) to `path`. Throws
// base::InputError naming `output_name` on any write failure.
void write_shard(const std::string& path, const std::string& output_name, const Spec& spec,
                 uint64_t shard, const std::vector<DatasetFrame>& frames);

// The largest shard file that is read back (into memory, whole).
inline constexpr std::size_t kMaxShardBytes = std::size_t(16) << 30;

// The spec digest a shard file was written for; nullopt if it is not a readable shard.
// Throws base::InputError naming `path` if it is not a regular file or cannot be read.
std::optional<uint64_t> shard_digest(const std::string& path);

}  // namespace sonotrace::imaging::dataset
