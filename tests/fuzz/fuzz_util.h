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

// Writes the input to scratch()/name and returns the path.
inline std::string as_file(const uint8_t* data, std::size_t size, const std::string& name) {
    const std::string path = (scratch() / name).string();
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) __builtin_trap();
    if (size > 0 && std::fwrite(data, 1, size, f) != size) __builtin_trap();
    std::fclose(f);
    return path;
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
