#include "tissue/atomic_output.h"

#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <system_error>

#include "tissue/error.h"

namespace sonotrace::tissue {

namespace fs = std::filesystem;

OutputTransaction::~OutputTransaction() {
    if (committed_) return;
    for (const auto& [temporary, final_path] : staged_) {
        std::error_code ignored;
        fs::remove(temporary, ignored);
    }
}

std::string OutputTransaction::stage(const std::string& final_path) {
    static std::atomic<unsigned> counter{0};
    const fs::path target(final_path);
    const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw InputError(dir.string(), "", "cannot create output directory: " + ec.message());
    const std::string temporary =
        (dir / (".partial-" + std::to_string(getpid()) + "-" + std::to_string(counter++) + "-" +
                target.filename().string()))
            .string();
    staged_.emplace_back(temporary, final_path);
    return temporary;
}

void OutputTransaction::commit() {
    for (const auto& [temporary, final_path] : staged_) {
        std::error_code ec;
        fs::rename(temporary, final_path, ec);
        if (ec) throw InputError(final_path, "", "cannot move output into place: " + ec.message());
    }
    committed_ = true;
}

std::vector<std::string> OutputTransaction::final_paths() const {
    std::vector<std::string> paths;
    for (const auto& entry : staged_) paths.push_back(entry.second);
    return paths;
}

}  // namespace sonotrace::tissue
