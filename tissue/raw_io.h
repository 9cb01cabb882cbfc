#pragma once
// Raw voxel files described by a JSON sidecar, for data that has no standard header.
//
//   {
//     "file": "head.raw",            // relative to the sidecar; default: same stem + .raw
//     "dims": [181, 217, 181],       // voxels along i, j, k
//     "spacing": [1, 1, 1],          // mm
//     "origin": [0, 0, 0],           // mm, world position of voxel (0,0,0); default 0
//     "direction": [[1,0,0],[0,1,0],[0,0,1]],  // world unit vectors of i, j, k; default identity
//     "datatype": "uint8",           // uint8 int8 uint16 int16 uint32 int32 float32 float64
//     "byte_order": "little",        // or "big"; default little
//     "header_bytes": 0              // bytes to skip at the start of the raw file
//   }
#include <string>

#include "tissue/volume.h"

namespace sonotrace::tissue {

// `path` is the sidecar (.json) or the raw file whose sidecar has the same stem.
Volume read_raw(const std::string& path);
// Writes float32 little-endian voxels and the sidecar (both atomic). `raw_path` ends in .raw.
void write_raw(const Volume& volume, const std::string& raw_path);

}  // namespace sonotrace::tissue
