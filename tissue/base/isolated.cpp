#include "tissue/base/isolated.h"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
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

void PipeWriter::bytes(const void* data, std::size_t n) {
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
        const ssize_t written = ::write(fd_, p, n);
        if (written < 0 && errno == EINTR) continue;
        if (written <= 0) _exit(2);  // the parent went away
        p += written;
        n -= std::size_t(written);
    }
}

bool PipeReader::bytes(void* data, std::size_t n) {
    char* p = static_cast<char*>(data);
    while (n > 0) {
        const ssize_t got = ::read(fd_, p, n);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return false;
        p += got;
        n -= std::size_t(got);
    }
    return true;
}

std::optional<std::string> run_forked(const std::function<void(int fd)>& child,
                                      const std::function<void(int fd)>& parent,
                                      std::size_t memory_limit_bytes, bool quiet,
                                      unsigned cpu_limit_seconds) {
    int fds[2];
    if (::pipe(fds) != 0)
        throw std::runtime_error("pipe() failed: " + std::string(std::strerror(errno)));
    const pid_t pid = ::fork();
    if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw std::runtime_error("fork() failed: " + std::string(std::strerror(errno)));
    }
    if (pid == 0) {
        ::close(fds[0]);
        for (const int deadly : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL})
            std::signal(deadly, SIG_DFL);
#ifdef SONOTRACE_ASAN
        // ASan's operator new dies where a memory budget makes a gigabyte allocation fail
        // (production throws bad_alloc, a refusal); the fuzzer's death callback would write
        // each such input as a crash of its own.
        __sanitizer_set_death_callback(nullptr);
        (void)memory_limit_bytes;
#else
        if (memory_limit_bytes > 0) {
            const rlimit limit{memory_limit_bytes, memory_limit_bytes};
            ::setrlimit(RLIMIT_AS, &limit);
        }
#endif
        if (cpu_limit_seconds > 0) {  // SIGXCPU at the soft limit ends the child
            const rlimit limit{cpu_limit_seconds, cpu_limit_seconds + 1};
            ::setrlimit(RLIMIT_CPU, &limit);
            std::signal(SIGXCPU, SIG_DFL);
        }
        if (quiet) {
            const int null = ::open("/dev/null", O_WRONLY);
            if (null >= 0) ::dup2(null, STDERR_FILENO);
        }
        try {
            child(fds[1]);
        } catch (...) {
            _exit(4);  // the child's work lets nothing escape; if it did, no answer
        }
        _exit(0);  // no destructors or exit handlers of the parent's state
    }
    ::close(fds[1]);
    parent(fds[0]);
    // Whatever the parent left unread: read to the end, so that the child is not left
    // blocked on a full pipe.
    for (char drain[4096];;) {
        const ssize_t got = ::read(fds[0], drain, sizeof drain);
        if (got > 0 || (got < 0 && errno == EINTR)) continue;
        break;
    }
    ::close(fds[0]);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (WIFSIGNALED(status)) return "signal " + std::string(strsignal(WTERMSIG(status)));
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
        return "exit status " + std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1);
    return std::nullopt;
}

std::optional<std::string> in_child_process(const std::function<std::optional<std::string>()>& work,
                                            std::size_t memory_limit_bytes) {
    // The answer: a status byte (0 sound, 1 why not, 2 out of memory), then the reason.
    std::uint8_t status = 255;
    std::string why;
    bool answered = false;
    const std::optional<std::string> ended = run_forked(
        [&](int fd) {
            PipeWriter out(fd);
            std::uint8_t s = 0;
            std::string message;
            try {
                if (const std::optional<std::string> reason = work()) s = 1, message = *reason;
            } catch (const std::bad_alloc&) {
                s = 2;
            } catch (const std::exception& e) {
                s = 1, message = e.what();
            }
            out.value(s);
            out.text(message);
        },
        [&](int fd) {
            PipeReader in(fd);
            answered = in.value(status) && in.text(why, std::size_t(1) << 30);
        },
        memory_limit_bytes);
    if (ended && ended->rfind("signal ", 0) == 0) return "crashed (" + *ended + ")";
    if (ended || !answered)
        return "ended without an answer (" + ended.value_or("exit status 0") + ")";
    if (status == 0) return std::nullopt;
    if (status == 2) return std::string("ran out of memory");
    return why;
}

}  // namespace sonotrace::base
