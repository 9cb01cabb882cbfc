#pragma once
// What every sonotrace subcommand shares: parameters documented once (name, unit,
// default, meaning) and turned into CLI11 options, stage timing with progress lines on
// stderr, thread control, and JSON output.
#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <tbb/global_control.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "tissue/base/json_util.h"
#include "tissue/base/number_list.h"
#include "tissue/base/stages.h"

namespace sonotrace::ui {

// One documented parameter. The CLI help shows "description [unit] (default: ...)".
struct ParameterDoc {
    const char* flag;         // "--depth"
    const char* unit;         // "mm", or "" for none
    const char* description;  // what it means
};

// Adds an option whose help text is built from the doc and the variable's current value.
template <typename T>
CLI::Option* add_parameter(CLI::App& app, const ParameterDoc& doc, T& variable) {
    std::string help = doc.description;
    if (doc.unit[0] != '\0') help += std::string(" [") + doc.unit + "]";
    return app.add_option(doc.flag, variable, help)->capture_default_str();
}

// Documented once for every command.
inline constexpr ParameterDoc kThreadsDoc = {"--threads", "", "worker threads; 0 = all cores"};
inline constexpr ParameterDoc kJsonRecordDoc = {
    "--json", "",
    "also write the run record (parameters, outputs, timings) to this file; '-' prints it on "
    "stdout"};

// Every floating-point option of `app` and its subcommands refuses NaN and infinities
// (CLI11's ranges let NaN through: every comparison with it is false), and every unsigned
// one what is not a whole number it can hold (CLI11 read -1, 2^64 and 1e23 as 2^64 - 1).
void refuse_bad_numbers(CLI::App& app);

// The options most commands end with: --json FILE, --threads N, -q/--quiet.
void add_run_options(CLI::App& command, std::string& json_path, int& threads, bool& quiet);

// Times named stages and prints "sonotrace: <stage> ... 0.42 s" lines to stderr.
class StageTimer : public base::StageObserver {
  public:
    explicit StageTimer(bool quiet) : quiet_(quiet) {}
    void begin(const std::string& stage) override;
    void end() override;
    // Ends an unfinished progress line (before an error message is printed).
    static void break_line();
    const nlohmann::json& timings() const { return timings_; }  // seconds per stage

  private:
    bool quiet_;
    std::string stage_;
    std::chrono::steady_clock::time_point start_;
    nlohmann::json timings_ = nlohmann::json::object();
};

// A progress bar on stderr ("tracing [#####.....] 12/40"), safe to call from worker
// threads; silent when quiet. When stderr is not a terminal (a log), a line per quarter.
class ProgressBar {
  public:
    ProgressBar(std::string label, bool quiet);
    // `note` follows the counts (a rate, the time left).
    void update(std::size_t done, std::size_t total, const std::string& note = "");
    void finish();

  private:
    std::string label_;
    bool quiet_;
    bool terminal_;
    std::mutex mutex_;
    int last_drawn_ = -1;
};

// Limits TBB to `threads` workers for the lifetime of the returned object (0 = all cores).
std::unique_ptr<tbb::global_control> limit_threads(int threads);

using base::jsonio::write_json;

using base::parse_number_list;
using base::parse_numbers;
using base::parse_spacing;

}  // namespace sonotrace::ui
