#pragma once
// Work on untrusted bytes in a child process: a C library that crashes on a malformed file
// (HDF5, GDCM's decoders) ends the child, and the caller gets a refusal instead of a
// crash of its own.
#include <functional>
#include <optional>
#include <string>

namespace sonotrace::base {

// Runs `work` in a forked child. nullopt when it returned nullopt (the input is sound);
// otherwise what it returned (why not), or how the child ended: "crashed (signal
// Segmentation fault)", "ran out of memory", ... `memory_limit_bytes` (0: none) caps the
// child's address space, so a file declaring gigabytes makes its allocation fail there
// rather than exhausting the machine (not applied in sanitizer builds, whose shadow
// memory needs the whole address space).
std::optional<std::string> in_child_process(const std::function<std::optional<std::string>()>& work,
                                            std::size_t memory_limit_bytes = 0);

}  // namespace sonotrace::base
