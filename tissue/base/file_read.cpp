#include "tissue/base/file_read.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "tissue/base/error.h"
#include "tissue/base/hash.h"
#include "tissue/base/memory.h"

namespace sonotrace::base {

namespace {

// A regular file opened for reading without blocking (opening a FIFO for reading would
// otherwise wait for a writer), closed when it goes out of scope; its size.
struct RegularFile {
    int fd = -1;
    std::size_t size = 0;
    RegularFile(const std::string& path, const std::string& field) {
        auto fail = [&](const std::string& what) { throw InputError(path, field, what); };
        if (path.find('\0') != std::string::npos) fail("the name holds a NUL character");
        fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
        if (fd < 0) fail(errno == ENOENT ? "file not found" : std::string(std::strerror(errno)));
        struct stat info {};
        if (::fstat(fd, &info) != 0 || !S_ISREG(info.st_mode)) {
            const std::string why =
                S_ISREG(info.st_mode) ? std::strerror(errno) : "is not a regular file";
            ::close(fd);
            fail(why);
        }
        size = std::size_t(info.st_size);
    }
    RegularFile(const RegularFile&) = delete;
    RegularFile& operator=(const RegularFile&) = delete;
    ~RegularFile() { ::close(fd); }
};

}  // namespace

namespace {

// Up to `limit` bytes from the start of an open file (one more when `whole`, so that a file
// that grows while it is read is caught).
std::string read_up_to(int fd, std::size_t limit, const std::string& path,
                       const std::string& field) {
    std::string bytes(limit, '\0');
    std::size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0)
            throw InputError(path, field, std::string("read error: ") + std::strerror(errno));
        if (n == 0) break;
        done += std::size_t(n);
    }
    bytes.resize(done);
    return bytes;
}

}  // namespace

std::string read_regular_file(const std::string& path, std::size_t max_bytes,
                              const std::string& field) {
    auto fail = [&](const std::string& what) { throw InputError(path, field, what); };
    const RegularFile file(path, field);
    if (file.size > max_bytes)
        fail("is " + std::to_string(file.size) + " bytes; this input is limited to " +
             std::to_string(max_bytes) + " bytes");
    check_allocation(double(file.size), path, field);
    // One byte more than the size: a file that grows while it is read is caught.
    std::string bytes = read_up_to(file.fd, file.size + 1, path, field);
    if (bytes.size() > max_bytes) fail("grew beyond the size limit while it was read");
    return bytes;
}

std::string read_regular_file_head(const std::string& path, std::size_t bytes,
                                   const std::string& field) {
    const RegularFile file(path, field);
    return read_up_to(file.fd, std::min(bytes, file.size), path, field);
}

namespace {

uint64_t file_digest(const std::string& path, const std::string& field, uint64_t h) {
    auto fail = [&](const std::string& what) { throw InputError(path, field, what); };
    const RegularFile file(path, field);
    const int fd = file.fd;
    std::vector<unsigned char> buffer(std::size_t(1) << 20);
    uint64_t length = 0;
    for (;;) {
        const ssize_t n = ::read(fd, buffer.data(), buffer.size());
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) fail(std::string("read error: ") + std::strerror(errno));
        if (n == 0) break;
        // Eight bytes at a time (the tail zero-padded), the length last.
        for (std::size_t i = 0; i < std::size_t(n); i += 8) {
            uint64_t word = 0;
            std::memcpy(&word, buffer.data() + i, std::min<std::size_t>(8, std::size_t(n) - i));
            h = mix64(h ^ word);
        }
        length += uint64_t(n);
    }
    return mix64(h ^ length);
}

}  // namespace

uint64_t content_digest(const std::string& path, const std::string& field) {
    uint64_t h = 0x636f6e74656e74ull;
    std::error_code error;
    if (!std::filesystem::is_directory(path, error)) return file_digest(path, field, h);
    std::vector<std::string> files;
    for (std::filesystem::recursive_directory_iterator it(path, error), end; !error && it != end;
         it.increment(error))
        if (it->is_regular_file(error)) files.push_back(it->path().string());
    if (error) throw InputError(path, field, "cannot list the directory: " + error.message());
    std::sort(files.begin(), files.end());
    for (const std::string& file : files) {
        for (const char c : file.substr(path.size())) h = mix64(h ^ uint8_t(c));
        h = file_digest(file, field, h);
    }
    return h;
}

}  // namespace sonotrace::base
