#include "tissue/atomic_output.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string_view>
#include <system_error>

#include "tissue/error.h"

namespace sonotrace::tissue {

namespace fs = std::filesystem;

namespace {
constexpr std::string_view kStagedPrefix = ".partial-";
}

std::string output_name(const std::string& path) {
    const fs::path p(path);
    const std::string name = p.filename().string();
    if (name.rfind(kStagedPrefix, 0) != 0) return path;
    // .partial-PID-COUNTER-NAME
    std::size_t at = kStagedPrefix.size();
    for (int dash = 0; dash < 2 && at != std::string::npos; ++dash) {
        at = name.find('-', at);
        if (at != std::string::npos) ++at;
    }
    if (at == std::string::npos) return path;
    return (p.parent_path() / name.substr(at)).string();
}

void write_file(const std::string& path, const void* data, std::size_t size) {
    auto fail = [&](const std::string& what, int error) {
        std::error_code ignored;
        if (fs::is_regular_file(path, ignored)) fs::remove(path, ignored);  // not a device
        throw InputError(output_name(path), "", what + ": " + std::strerror(error));
    };
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) fail("cannot create the file", errno);
    const auto* bytes = static_cast<const char*>(data);
    for (std::size_t done = 0; done < size;) {
        const ssize_t n = ::write(fd, bytes + done, size - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const int error = n < 0 ? errno : EIO;
            ::close(fd);
            fail("cannot write the file", error);
        }
        done += std::size_t(n);
    }
    if (::close(fd) != 0) fail("cannot write the file", errno);
}

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
        (dir / (std::string(kStagedPrefix) + std::to_string(getpid()) + "-" +
                std::to_string(counter++) + "-" + target.filename().string()))
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
