#pragma once
// What every fuzz target shares (libFuzzer, built with -DSONOTRACE_FUZZ=ON and clang):
// the input as a file of a given name (the parsers read files), and the contract that a
// parser may refuse input only with base::InputError. Any other exception escapes
// LLVMFuzzerTestOneInput and libFuzzer reports it as a crash, like a sanitizer error.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "tissue/base/error.h"

namespace sonotrace::fuzz {

// A scratch directory of this process, removed at exit.
inline const std::filesystem::path& scratch() {
    static const struct Dir {
        std::filesystem::path path;
        Dir() {
            path = std::filesystem::temp_directory_path() /
                   ("sonotrace-fuzz-" + std::to_string(getpid()));
            std::filesystem::create_directories(path);
        }
        ~Dir() {
            std::error_code ignored;
            std::filesystem::remove_all(path, ignored);
        }
    } dir;
    return dir.path;
}

inline void write_bytes(const std::filesystem::path& path, const std::string& bytes) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) __builtin_trap();
    if (!bytes.empty() && std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size())
        __builtin_trap();
    std::fclose(f);
}

// Writes the input to scratch()/name and returns the path.
inline std::string as_file(const uint8_t* data, std::size_t size, const std::string& name) {
    const std::string path = (scratch() / name).string();
    write_bytes(path, std::string(reinterpret_cast<const char*>(data), size));
    return path;
}

// Inputs of several files (a DICOM series, a dataset's manifest and shards): the fuzzer's
// bytes cut at each kFileSeparator, at most `max_files` pieces (the last keeps the rest).
inline constexpr std::string_view kFileSeparator = "\n#sonotrace-next-file#\n";
inline std::vector<std::string> split_files(const uint8_t* data, std::size_t size,
                                            std::size_t max_files) {
    const std::string_view all(reinterpret_cast<const char*>(data), size);
    std::vector<std::string> files;
    std::size_t at = 0;
    while (files.size() + 1 < max_files) {
        const std::size_t next = all.find(kFileSeparator, at);
        if (next == std::string_view::npos) break;
        files.emplace_back(all.substr(at, next - at));
        at = next + kFileSeparator.size();
    }
    files.emplace_back(all.substr(at));
    return files;
}

// An empty directory scratch()/name (emptied of the previous input's files).
inline std::filesystem::path fresh_dir(const std::string& name) {
    const std::filesystem::path dir = scratch() / name;
    std::error_code ignored;
    std::filesystem::remove_all(dir, ignored);
    std::filesystem::create_directories(dir);
    return dir;
}

// Runs `parse`; an InputError is a valid answer to bad input, anything else escapes.
template <class Parse>
int only_input_errors(Parse&& parse) {
    try {
        parse();
    } catch (const base::InputError&) {
    }
    return 0;
}

}  // namespace sonotrace::fuzz
