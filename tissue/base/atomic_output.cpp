#include "tissue/base/atomic_output.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string_view>
#include <system_error>

#include "tissue/base/error.h"
#include "tissue/base/hash.h"

namespace sonotrace::base {

namespace fs = std::filesystem;

namespace {
constexpr std::string_view kStagedPrefix = ".partial-";

// This machine, as 16 hex digits (a host name may hold '-', the names' separator): a
// temporary names its process by "PID.HOST", so that a run on another host sharing the
// directory (NFS, a cluster's scratch) never judges a temporary by a process id of its own.
const std::string& host_tag() {
    static const std::string tag = [] {
        char name[256] = {};
        if (::gethostname(name, sizeof name - 1) != 0) name[0] = '\0';
        uint64_t h = 0x686f73742d746167ull;
        for (const char* c = name; *c; ++c) h = mix64(h ^ uint8_t(*c));
        char text[17];
        std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h));
        return std::string(text);
    }();
    return tag;
}
}  // namespace

std::string temporary_owner(long pid) {
    return std::to_string(pid) + "." + host_tag();
}

std::string output_name(const std::string& path) {
    const fs::path p(path);
    const std::string name = p.filename().string();
    if (name.rfind(kStagedPrefix, 0) != 0) return path;
    // .partial-PID.HOST-COUNTER-NAME
    std::size_t at = kStagedPrefix.size();
    for (int dash = 0; dash < 2 && at != std::string::npos; ++dash) {
        at = name.find('-', at);
        if (at != std::string::npos) ++at;
    }
    if (at == std::string::npos) return path;
    return (p.parent_path() / name.substr(at)).string();
}

void write_file(const std::string& path, const void* data, std::size_t size,
                Durability durability) {
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
    if (durability == Durability::synced && ::fsync(fd) != 0) {
        const int error = errno;
        ::close(fd);
        fail("cannot write the file", error);
    }
    if (::close(fd) != 0) fail("cannot write the file", errno);
}

void sync_directory(const std::string& dir) {
    const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0)
        throw InputError(dir, "",
                         std::string("cannot open the directory: ") + std::strerror(errno));
    const int status = ::fsync(fd), error = errno;
    ::close(fd);
    if (status != 0)
        throw InputError(dir, "",
                         std::string("cannot sync the directory: ") + std::strerror(error));
}

OutputTransaction::~OutputTransaction() {
    if (committed_) return;
    for (const auto& [temporary, final_path] : staged_) {
        std::error_code ignored;
        fs::remove(temporary, ignored);
    }
}

namespace {

// Removes the staged temporaries (and commit backups) that a process of this host no longer
// running left in `dir`: a run killed mid-way cannot clean up after itself, the next one
// does. Another host's temporaries are left alone: its process ids mean nothing here.
void remove_stale_temporaries(const fs::path& dir) {
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.rfind(kStagedPrefix, 0) != 0) continue;
        const std::string owner = name.substr(
            kStagedPrefix.size(), name.find('-', kStagedPrefix.size()) - kStagedPrefix.size());
        const std::size_t dot = owner.find('.');
        const std::string pid_text = owner.substr(0, dot);
        if (dot == std::string::npos || owner != temporary_owner(std::atol(pid_text.c_str())))
            continue;
        char* end_of_pid = nullptr;
        const long pid = std::strtol(pid_text.c_str(), &end_of_pid, 10);
        if (pid_text.empty() || *end_of_pid != '\0' || pid <= 0) continue;
        if (pid == long(getpid())) continue;
        if (::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;  // alive (or not ours)
        std::error_code ignored;
        fs::remove(it->path(), ignored);
    }
}

std::string staged_name(const fs::path& dir, const std::string& name) {
    static std::atomic<unsigned> counter{0};
    return (dir / (std::string(kStagedPrefix) + temporary_owner(getpid()) + "-" +
                   std::to_string(counter++) + "-" + name))
        .string();
}

}  // namespace

std::string OutputTransaction::stage(const std::string& final_path) {
    const fs::path target(final_path);
    const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw InputError(dir.string(), "", "cannot create output directory: " + ec.message());
    if (std::find(cleaned_.begin(), cleaned_.end(), dir.string()) == cleaned_.end()) {
        remove_stale_temporaries(dir);
        cleaned_.push_back(dir.string());
    }
    if (!canonical_finals_.insert(fs::weakly_canonical(target, ec).string()).second) {
        throw InputError(final_path, "",
                         "two outputs of this run have this name; give them different names");
    }
    const std::string temporary = staged_name(dir, target.filename().string());
    staged_.emplace_back(temporary, final_path);
    return temporary;
}

// All or nothing: the files the outputs replace are moved aside first, then every
// temporary is renamed into place; if any step fails, what was done is undone (new files
// removed, old ones restored) and nothing of this run is left.
void OutputTransaction::commit() {
    struct Done {
        std::string final_path, backup;  // backup empty: nothing was there
    };
    std::vector<Done> done;
    auto undo = [&] {
        for (auto it = done.rbegin(); it != done.rend(); ++it) {
            std::error_code ignored;
            fs::remove(it->final_path, ignored);
            if (!it->backup.empty()) fs::rename(it->backup, it->final_path, ignored);
        }
    };
    for (const auto& [temporary, final_path] : staged_) {
        std::error_code ec;
        std::string backup;
        if (fs::is_regular_file(fs::symlink_status(final_path, ec))) {
            const fs::path target(final_path);
            backup = staged_name(target.has_parent_path() ? target.parent_path() : fs::path("."),
                                 "previous-" + target.filename().string());
            fs::rename(final_path, backup, ec);
            if (ec) {
                undo();
                throw InputError(final_path, "",
                                 "cannot replace the existing file: " + ec.message());
            }
        }
        fs::rename(temporary, final_path, ec);
        if (ec) {
            std::error_code ignored;
            if (!backup.empty()) fs::rename(backup, final_path, ignored);
            undo();
            throw InputError(final_path, "", "cannot move output into place: " + ec.message());
        }
        done.push_back({final_path, backup});
    }
    for (const Done& d : done) {
        std::error_code ignored;
        if (!d.backup.empty()) fs::remove(d.backup, ignored);
    }
    committed_ = true;
}

std::vector<std::string> OutputTransaction::final_paths() const {
    std::vector<std::string> paths;
    for (const auto& entry : staged_) paths.push_back(entry.second);
    return paths;
}

}  // namespace sonotrace::base
