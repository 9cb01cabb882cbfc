#pragma once
// `sonotrace tissue`: slice a volume under a probe pose, apply a transfer function and
// write the slice and every acoustic field as pictures with a JSON sidecar.
#include <limits>
#include <string>

#include "ui/cli/command_common.h"
#include "ui/cli/volume_slice.h"

namespace sonotrace::ui {

struct TissueOptions {
    SliceOptions slice;
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
// Returns the process exit code; throws base::InputError on bad input.
int run_tissue_command(const TissueOptions& options);

}  // namespace sonotrace::ui
