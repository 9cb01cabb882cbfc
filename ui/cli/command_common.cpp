#include "ui/cli/command_common.h"

#include <tbb/global_control.h>
#include <unistd.h>

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>

#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"

namespace sonotrace::ui {

namespace {
bool stage_line_open = false;  // a "sonotrace: <stage> ..." line awaits its time
}  // namespace

void StageTimer::break_line() {
    if (stage_line_open) std::fputc('\n', stderr);
    stage_line_open = false;
}

void StageTimer::begin(const std::string& stage) {
    stage_ = stage;
    start_ = std::chrono::steady_clock::now();
    if (!quiet_) {
        std::fprintf(stderr, "sonotrace: %s ...", stage.c_str());
        std::fflush(stderr);
        stage_line_open = true;
    }
}

void StageTimer::end() {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    timings_[stage_] = seconds;
    if (!quiet_) std::fprintf(stderr, " %.2f s\n", seconds);
    stage_line_open = false;
}

ProgressBar::ProgressBar(std::string label, bool quiet)
    : label_(std::move(label)), quiet_(quiet), terminal_(isatty(fileno(stderr)) == 1) {}

void ProgressBar::update(std::size_t done, std::size_t total, const std::string& note) {
    if (quiet_ || total == 0) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (!terminal_) {
        // A log file: a line per quarter, not thirty redraws run together on one line.
        const int quarter = int(4 * done / total);
        if (quarter == last_drawn_ || (quarter == 0 && done != total)) return;
        last_drawn_ = quarter;
        std::fprintf(stderr, "sonotrace: %s %zu/%zu%s%s\n", label_.c_str(), done, total,
                     note.empty() ? "" : ", ", note.c_str());
        return;
    }
    const int filled = int(30 * done / total);
    if (filled == last_drawn_ && done != total && note.empty()) return;
    last_drawn_ = filled;
    std::fprintf(stderr, "\rsonotrace: %s [%s%s] %zu/%zu%s%s\033[K", label_.c_str(),
                 std::string(std::size_t(filled), '#').c_str(),
                 std::string(std::size_t(30 - filled), '.').c_str(), done, total,
                 note.empty() ? "" : "  ", note.c_str());
    std::fflush(stderr);
}

void ProgressBar::finish() {
    if (!quiet_ && terminal_ && last_drawn_ >= 0) std::fprintf(stderr, "\n");
}

std::unique_ptr<tbb::global_control> limit_threads(int threads) {
    if (threads <= 0) return nullptr;
    return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                 std::size_t(threads));
}

void refuse_bad_numbers(CLI::App& app) {
    // CLI11 reports what does not parse as a number at all; these catch what does but is
    // not one (NaN, infinities), and unsigned values out of range.
    const CLI::Validator finite(
        [](std::string& value) -> std::string {
            char* end = nullptr;
            std::strtod(value.c_str(), &end);
            if (end == value.c_str()) return {};
            return base::not_a_finite_number(value).value_or("");
        },
        "");
    const CLI::Validator whole(
        [](std::string& value) -> std::string {
            return base::not_a_whole_number(value).value_or("");
        },
        "");
    for (CLI::Option* option : app.get_options()) {
        if (option->get_type_name().rfind("FLOAT", 0) == 0) option->check(finite);
        if (option->get_type_name().rfind("UINT", 0) == 0) option->check(whole);
    }
    for (CLI::App* command : app.get_subcommands({})) refuse_bad_numbers(*command);
}

void add_run_options(CLI::App& command, std::string& json_path, int& threads, bool& quiet) {
    add_parameter(command, kJsonRecordDoc, json_path);
    add_parameter(command, kThreadsDoc, threads)->check(CLI::Range(0, 1024));
    command.add_flag("-q,--quiet", quiet, "no progress on stderr");
}

}  // namespace sonotrace::ui
