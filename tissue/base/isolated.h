#pragma once
// Work on untrusted bytes in a child process: a C library that crashes on a malformed file
// (HDF5, GDCM's decoders) ends the child, and the caller gets a refusal instead of a
// crash of its own.
#include <cstdint>
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

// The same for answers larger than a message (a volume, streamed): `child` runs in a
// forked child and writes its answer to the pipe it is given (PipeWriter), `parent` reads
// it here (PipeReader). In the child the deadly signals end it quietly whatever handlers
// the parent installed (a fuzzer's would record the child's death as its own finding),
// as does a sanitizer's death; `quiet` sends its stderr to /dev/null. nullopt when the
// child exited 0, otherwise how it ended: "signal Segmentation fault", "exit status 3".
// `cpu_limit_seconds` (0: none) ends a child that runs away (a reader looping for ever on
// a malformed file) after that much CPU time: "signal CPU time limit exceeded".
std::optional<std::string> run_forked(const std::function<void(int fd)>& child,
                                      const std::function<void(int fd)>& parent,
                                      std::size_t memory_limit_bytes = 0, bool quiet = false,
                                      unsigned cpu_limit_seconds = 0);

// A child's answer, written whole (a child whose parent went away exits with status 2).
class PipeWriter {
  public:
    explicit PipeWriter(int fd) : fd_(fd) {}
    void bytes(const void* data, std::size_t n);
    template <class T>
    void value(const T& v) {
        bytes(&v, sizeof v);
    }
    void text(const std::string& s) {
        value(std::uint64_t(s.size()));
        bytes(s.data(), s.size());
    }

  private:
    int fd_;
};

// The parent's side: each read false when the answer ends early (the child died).
class PipeReader {
  public:
    explicit PipeReader(int fd) : fd_(fd) {}
    bool bytes(void* data, std::size_t n);
    template <class T>
    bool value(T& v) {
        return bytes(&v, sizeof v);
    }
    // A text of at most `longest` bytes.
    bool text(std::string& s, std::size_t longest = std::size_t(1) << 20) {
        std::uint64_t n = 0;
        if (!value(n) || n > longest) return false;
        s.resize(n);
        return bytes(s.data(), n);
    }

  private:
    int fd_;
};

}  // namespace sonotrace::base
