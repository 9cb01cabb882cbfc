#include "tissue/base/file_read.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "tissue/base/error.h"
#include "tissue/base/memory.h"

namespace sonotrace::base {

std::string read_regular_file(const std::string& path, std::size_t max_bytes,
                              const std::string& field) {
    auto fail = [&](const std::string& what) { throw InputError(path, field, what); };
    if (path.find('\0') != std::string::npos) fail("the name holds a NUL character");
    // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer.
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) fail(errno == ENOENT ? "file not found" : std::string(std::strerror(errno)));
    struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
    } closer{fd};
    struct stat info {};
    if (::fstat(fd, &info) != 0) fail(std::strerror(errno));
    if (!S_ISREG(info.st_mode)) fail("is not a regular file");
    if (std::size_t(info.st_size) > max_bytes)
        fail("is " + std::to_string(info.st_size) + " bytes; this input is limited to " +
             std::to_string(max_bytes) + " bytes");
    check_allocation(double(info.st_size), path, field);
    // One byte more than the size: a file that grows while it is read is caught.
    std::string bytes(std::size_t(info.st_size) + 1, '\0');
    std::size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) fail(std::string("read error: ") + std::strerror(errno));
        if (n == 0) break;
        done += std::size_t(n);
    }
    if (done > max_bytes) fail("grew beyond the size limit while it was read");
    bytes.resize(done);
    return bytes;
}

}  // namespace sonotrace::base
