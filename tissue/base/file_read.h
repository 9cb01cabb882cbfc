#pragma once
// Reading a whole input file the user named, safely: only a regular file is read (a FIFO
// or a device could block for ever or never end), it is opened without blocking, and its
// size is checked against a cap before anything is allocated.
#include <cstddef>
#include <cstdint>
#include <string>

namespace sonotrace::base {

// The bytes of `path`. Throws InputError naming `path` (and `field`, if any) when the file
// is missing, not a regular file, larger than `max_bytes`, or cannot be read.
std::string read_regular_file(const std::string& path, std::size_t max_bytes,
                              const std::string& field = "");

// The first `bytes` bytes of `path` (fewer if it is shorter), with read_regular_file's
// checks of what `path` is.
std::string read_regular_file_head(const std::string& path, std::size_t bytes,
                                   const std::string& field = "");

// A 64-bit digest of what `path` holds, read in pieces (any size): a regular file's bytes;
// a directory's regular files (recursively, by name), each name and its bytes. Throws
// InputError as read_regular_file does for what is neither (a FIFO, a device).
uint64_t content_digest(const std::string& path, const std::string& field = "");

}  // namespace sonotrace::base
