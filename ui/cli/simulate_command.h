#pragma once
// `sonotrace simulate`: B-mode frames from a volume and a transducer.
#include <string>

#include "phantoms/scene/request.h"
#include "ui/cli/command_common.h"

namespace sonotrace::ui {

// The frame request (phantoms/scene/request.h) and what the command line adds: the files
// it writes and how it runs.
struct SimulateOptions {
    scene::FrameRequest request;
    std::string formats = "png8";
    bool write_rf = false, write_envelope = false;
    bool resume = false;  // keep the frames a stopped sweep already wrote
    std::string video = "mp4";
    double fps = 10.0;
    std::string scene;            // --scene JSON file
    CLI::App* command = nullptr;  // set by add_simulate_command (for --scene)
    std::string out_dir = "out";
    std::string name = "bmode";
    std::string json_path;
    int threads = 0;
    bool quiet = false;
};

CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& options);

// Applies --scene to the options bound to `options.command`, then runs.
int run_simulate_command(const SimulateOptions& options);

}  // namespace sonotrace::ui
