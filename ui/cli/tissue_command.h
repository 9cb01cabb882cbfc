#pragma once
// `sonotrace tissue`: slice a volume under a probe pose, apply a transfer function and
// write the slice and every acoustic field as pictures with a JSON sidecar.
#include <limits>
#include <string>

#include "ui/cli/command_common.h"

namespace sonotrace::ui {

struct TissueOptions {
    std::string volume = "default";
    std::string spacing;
    std::string tf;
    std::string pose = "default";
    double width_mm = 0.0;
    double depth_mm = 0.0;
    double resolution_mm = 0.25;
    double elevation_mm = 0.0;
    double outside = std::numeric_limits<double>::quiet_NaN();
    std::string out_dir = "out/tissue";
    std::string json_path;
    int threads = 0;
    bool write_nifti = false;
    bool list_tissues = false;
    bool quiet = false;
};

CLI::App* add_tissue_command(CLI::App& app, TissueOptions& options);
// The property and tissue tables as Markdown (also in README.md, checked by a test).
std::string tissue_tables_markdown();
// Returns the process exit code; throws tissue::InputError on bad input.
int run_tissue_command(const TissueOptions& options);

}  // namespace sonotrace::ui
