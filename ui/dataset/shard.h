#pragma once
// HDF5 shards of a dataset (libhdf5, readable with h5py and nothing else):
//
//   /bmode     uint8 [n, H, W]   the frames' grey levels (as simulate's png8)
//   /labels    uint8 [n, H, W]   tissue index per pixel (1-based, the manifest's legend)
//   /labels_echo  uint8 [n, H, W]  the same where the echoes show it (on request)
//   /frames    [n] table         per frame: index, seed, source, probe, frequency_mhz,
//                                depth_mm, focus_mm, gain_db, dynamic_range_db, position,
//                                lateral, axial, elevation (world mm / unit), pixel_mm,
//                                origin_mm, valid_width, valid_height, then a column per
//                                value the spec draws (drawn_values: "transducer.focus",
//                                "tgc.slope", "noise_snr_db", "tissues.brain.attenuation")
//   /envelope/NNNNNNNN, /rf/NNNNNNNN    float32 [lines, samples] per frame (on request)
//   /energy/NNNNNNNN                    float32 [rows, cols] per frame (on request)
//   /channels/NNNNNNNN  float32 [transmits, elements, samples] per frame (on request, with
//                       the spec's "transmit"): each element's RF; attributes
//                       sampling_frequency_hz, start_time_s, speed_of_sound_m_s,
//                       centre_frequency_hz, pitch_mm (elements at (e - (E - 1) / 2) pitch)
//   attributes: spec (the spec, canonical JSON), spec_digest, shard, first_frame,
//               frame_count, version
//
// Images are chunked a frame at a time and deflate-compressed. Nothing time-dependent is
// stored, so the same frames give the same bytes.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "ui/dataset/frames.h"

namespace sonotrace::dataset {

// Writes `frames` (shard `shard` of `spec`, in frame order) to `path`. Throws
// base::InputError naming `output_name` on any write failure.
void write_shard(const std::string& path, const std::string& output_name, const Spec& spec,
                 uint64_t shard, const std::vector<DatasetFrame>& frames);

// The largest shard file that is read back (into memory, whole).
inline constexpr std::size_t kMaxShardBytes = std::size_t(16) << 30;

// Every shard begins with a header of kShardHeaderBytes (an HDF5 user block, which h5py
// and HDF5 skip) that says whose it is and what it holds:
//   "sonotrace shard\nspec_digest %016x\nshard %u\ncontent_checksum %016x\n", zero padded,
// the checksum over every byte after the header (and the file's length). A shard is kept
// only when all of it agrees, so a flipped byte, a truncated file or a shard copied under
// another number is remade, never trusted.
inline constexpr std::size_t kShardHeaderBytes = 512;
uint64_t content_checksum(const std::string& file);
std::string shard_header(uint64_t spec_digest, uint64_t shard, uint64_t checksum);

// What a shard's header says.
struct ShardHeader {
    uint64_t spec_digest = 0, shard = 0, content_checksum = 0;
};
// The header in a shard's first kShardHeaderBytes, if they hold a sound one.
std::optional<ShardHeader> parse_shard_header(std::string_view head);
struct ShardCheck {
    enum Verdict { ok, damaged, foreign } verdict;
    std::string why;  // for damaged and foreign
    ShardHeader header{};
};
// Checks a shard's bytes: its header, its content against the header's checksum, and,
// when given, that it is shard `shard` of the spec of `spec_digest` (a header naming
// another spec is `foreign`, whatever its content).
ShardCheck check_shard_bytes(const std::string& bytes, std::optional<uint64_t> spec_digest,
                             std::optional<uint64_t> shard);
// Reads and checks shard file `shard` of the spec of `spec_digest`. Throws
// base::InputError naming `path` if it is not a regular file or cannot be read.
ShardCheck check_shard(const std::string& path, uint64_t spec_digest, uint64_t shard);
// A sound shard holds nothing larger than its bytes inflate to (deflate stops near
// 1032:1) and stores each dataset a frame a chunk.
inline constexpr double kShardReadExpansion = 1100.0;
inline constexpr long kMaxShardChunks = 1L << 16;
// Why HDF5 cannot read every dataset and attribute of a shard's bytes (each checked
// against what the file can hold before it is read), or nullopt if it can: read in a
// child process, so that a malformed file HDF5 crashes on is a refusal, not a crash (what
// read_shard() in Python checks before h5py sees the bytes).
std::optional<std::string> unreadable_shard(const std::string& bytes);
// The header of the shard at `path`, read alone (its content is not checked: for shards
// this run has checked or written). Throws base::InputError naming `path` if it has none.
ShardHeader read_shard_header(const std::string& path);

}  // namespace sonotrace::dataset
