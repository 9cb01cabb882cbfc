#pragma once
// `sonotrace validate`: runs the validation suite (phantoms/validation), prints PASS/FAIL
// with measured, expected and tolerance per quantity, and writes an HTML report and JSON
// records on request.
#include <cstdint>
#include <string>
#include <vector>

#include "ui/cli/command_common.h"

namespace sonotrace::ui {

struct ValidateOptions {
    std::vector<std::string> cases;  // empty = all
    std::string report_dir;          // empty = no report
    std::string json_path;           // empty = none; "-" = stdout
    std::string phantom_dir;         // the catalogue (default: the source tree's phantoms/)
    uint64_t seed = 1;
    bool list = false;
    int threads = 0;
    bool quiet = false;
};

CLI::App* add_validate_command(CLI::App& app, ValidateOptions& options);
// 0 when every case passes, 2 when a case fails (1 = bad input, as everywhere).
int run_validate_command(const ValidateOptions& options);

}  // namespace sonotrace::ui
