#pragma once
// `sonotrace dataset`: many frames with ground truth from a JSON spec, in HDF5 shards.
#include <string>

#include "ui/cli/command_common.h"

namespace sonotrace::ui {

struct DatasetOptions {
    std::string spec;
    std::string out_dir = "out/dataset";
    std::string verify;  // a finished dataset's directory, checked instead of made
    int threads = 0;
    bool quiet = false;
};

CLI::App* add_dataset_command(CLI::App& app, DatasetOptions& options);
int run_dataset_command(const DatasetOptions& options);

}  // namespace sonotrace::ui
