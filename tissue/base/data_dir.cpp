#include "tissue/base/data_dir.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace sonotrace::base {

namespace fs = std::filesystem;

std::string data_dir() {
    if (const char* env = std::getenv("SONOTRACE_DATA"); env && *env) return env;
    std::error_code error;
    const fs::path exe = fs::read_symlink("/proc/self/exe", error);
    if (!error) {
        const fs::path installed = exe.parent_path().parent_path() / "share" / "sonotrace";
        if (fs::is_directory(installed / "phantoms", error)) return installed.string();
        std::ifstream marker(exe.parent_path() / "sonotrace-source-dir");
        std::string source;
        if (marker && std::getline(marker, source) && fs::is_directory(source, error))
            return source;
    }
    return ".";
}

std::string phantom_catalogue_dir() {
    return (fs::path(data_dir()) / "phantoms").string();
}

}  // namespace sonotrace::base
