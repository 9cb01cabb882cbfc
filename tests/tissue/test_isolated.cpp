// base::in_child_process: work on untrusted bytes whose crash must stay the child's.
#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <new>
#include <string>
#include <vector>

#include "tissue/base/isolated.h"

namespace sonotrace {
namespace {

TEST(InChildProcess, ReportsTheAnswerOrHowTheChildEnded) {
    EXPECT_EQ(base::in_child_process([] { return std::optional<std::string>(); }), std::nullopt);
    EXPECT_EQ(base::in_child_process([] { return std::optional<std::string>("a reason"); }),
              "a reason");
    EXPECT_EQ(base::in_child_process(
                  []() -> std::optional<std::string> { throw std::runtime_error("thrown"); }),
              "thrown");
    // A crash of the work is the child's: the caller is told, and goes on.
    const std::optional<std::string> crashed =
        base::in_child_process([]() -> std::optional<std::string> {
            std::raise(SIGSEGV);
            return std::nullopt;
        });
    ASSERT_TRUE(crashed.has_value());
    EXPECT_NE(crashed->find("crashed (signal"), std::string::npos) << *crashed;
}

// A child that never ends (a reader looping on a malformed file) is ended by its CPU
// limit: the caller is told, after about that much time, instead of waiting for ever.
TEST(RunForked, AChildThatRunsAwayIsEndedByItsCpuLimit) {
    const auto start = std::chrono::steady_clock::now();
    const std::optional<std::string> ended = base::run_forked(
        [](int) {
            volatile uint64_t spin = 0;
            for (;;) spin = spin + 1;
        },
        [](int) {}, 0, true, 1);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ASSERT_TRUE(ended.has_value());
    EXPECT_NE(ended->find("CPU time limit"), std::string::npos) << *ended;
    EXPECT_LT(seconds, 30.0);  // 1 s of CPU; wall time on a loaded machine more
}

#if !defined(__SANITIZE_ADDRESS__)
// The memory cap: 8 GB asked of a child limited to 1 GB fails there, not on the machine.
TEST(InChildProcess, AnAllocationBeyondTheCapFailsInTheChild) {
    const std::optional<std::string> why = base::in_child_process(
        []() -> std::optional<std::string> {
            std::vector<char> huge(std::size_t(8) << 30, 1);
            return std::to_string(huge[12345]);
        },
        std::size_t(1) << 30);
    EXPECT_EQ(why, "ran out of memory");
}
#endif

}  // namespace
}  // namespace sonotrace
