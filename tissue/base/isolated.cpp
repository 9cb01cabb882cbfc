#include "tissue/base/isolated.h"

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <new>
#include <stdexcept>

// A sanitizer build (the fuzzers', ASan's): the child's death must stay the child's.
#if defined(__SANITIZE_ADDRESS__)
#define SONOTRACE_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SONOTRACE_ASAN 1
#endif
#endif
#ifdef SONOTRACE_ASAN
#include <sanitizer/common_interface_defs.h>
#endif

namespace sonotrace::base {

namespace {
// The whole message through the pipe; false if the reader went away.
bool write_all(int fd, const char* p, std::size_t n) {
    while (n > 0) {
        const ssize_t written = ::write(fd, p, n);
        if (written < 0 && errno == EINTR) continue;
        if (written <= 0) return false;
        p += written;
        n -= std::size_t(written);
    }
    return true;
}
}  // namespace

std::optional<std::string> in_child_process(const std::function<std::optional<std::string>()>& work,
                                            std::size_t memory_limit_bytes) {
    int fds[2];
    if (::pipe(fds) != 0)
        throw std::runtime_error("pipe() failed: " + std::string(std::strerror(errno)));
    const pid_t child = ::fork();
    if (child < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw std::runtime_error("fork() failed: " + std::string(std::strerror(errno)));
    }
    if (child == 0) {
        ::close(fds[0]);
        // A crash ends the child quietly, whatever handlers the parent installed (a
        // fuzzer's would record the child's death as its own finding).
        for (const int deadly : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL})
            std::signal(deadly, SIG_DFL);
#ifdef SONOTRACE_ASAN
        __sanitizer_set_death_callback(nullptr);
        (void)memory_limit_bytes;
#else
        if (memory_limit_bytes > 0) {
            const rlimit limit{memory_limit_bytes, memory_limit_bytes};
            ::setrlimit(RLIMIT_AS, &limit);
        }
#endif
        std::uint8_t status = 0;
        std::string message;
        try {
            if (const std::optional<std::string> why = work()) status = 1, message = *why;
        } catch (const std::bad_alloc&) {
            status = 2;
        } catch (const std::exception& e) {
            status = 1, message = e.what();
        }
        const std::uint64_t size = message.size();
        const bool sent = write_all(fds[1], reinterpret_cast<const char*>(&status), 1) &&
                          write_all(fds[1], reinterpret_cast<const char*>(&size), sizeof size) &&
                          write_all(fds[1], message.data(), message.size());
        _exit(sent ? 0 : 3);  // no destructors or exit handlers of the parent's state
    }
    ::close(fds[1]);
    std::string answer;
    char buffer[4096];
    for (;;) {
        const ssize_t got = ::read(fds[0], buffer, sizeof buffer);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) break;
        answer.append(buffer, std::size_t(got));
    }
    ::close(fds[0]);
    int exit_status = 0;
    while (::waitpid(child, &exit_status, 0) < 0 && errno == EINTR) {
    }
    if (WIFSIGNALED(exit_status))
        return "crashed (signal " + std::string(strsignal(WTERMSIG(exit_status))) + ")";
    if (answer.size() < 1 + sizeof(std::uint64_t) || !WIFEXITED(exit_status) ||
        WEXITSTATUS(exit_status) != 0)
        return "ended without an answer (exit status " +
               std::to_string(WIFEXITED(exit_status) ? WEXITSTATUS(exit_status) : -1) + ")";
    const auto status = std::uint8_t(answer[0]);
    if (status == 0) return std::nullopt;
    if (status == 2) return std::string("ran out of memory");
    return answer.substr(1 + sizeof(std::uint64_t));
}

}  // namespace sonotrace::base
