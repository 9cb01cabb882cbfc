// The `sonotrace` command.
#include <filesystem>
#include <iostream>

#include <CLI/CLI.hpp>

#include "sonotrace_version.h"
#include "tissue/base/error.h"
#include "tissue/base/memory.h"
#include "ui/cli/dataset_command.h"
#include "ui/cli/render_command.h"
#include "ui/cli/simulate_command.h"
#include "ui/cli/tissue_command.h"
#include "ui/cli/trace_command.h"
#include "ui/cli/validate_command.h"

int main(int argc, char** argv) {
    using namespace sonotrace;
    base::keep_freed_memory();
    CLI::App app(
        "sonotrace " SONOTRACE_VERSION
        " - ultrasound image simulation by particle tracing through tissue maps.\n"
        "Units: lengths in mm, time in s, speed of sound in m/s, density in kg/m^3, attenuation "
        "in dB/(cm*MHz), frequency in MHz.",
        "sonotrace");
    app.set_version_flag("-V,--version", "sonotrace " SONOTRACE_VERSION);
    app.require_subcommand(1);

    ui::TissueOptions tissue_options;
    CLI::App* tissue_cmd = ui::add_tissue_command(app, tissue_options);
    ui::TraceOptions trace_options;
    CLI::App* trace_cmd = ui::add_trace_command(app, trace_options);
    ui::SimulateOptions simulate_options;
    CLI::App* simulate_cmd = ui::add_simulate_command(app, simulate_options);
    ui::ValidateOptions validate_options;
    CLI::App* validate_cmd = ui::add_validate_command(app, validate_options);
    ui::RenderOptions render_options;
    CLI::App* render_cmd = ui::add_render_command(app, render_options);
    ui::DatasetOptions dataset_options;
    CLI::App* dataset_cmd = ui::add_dataset_command(app, dataset_options);

    ui::refuse_bad_numbers(app);

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // app.exit() prints the help or the message naming the option; an option or value
        // that does not parse is bad input: 1, as for every other input (not CLI11's codes).
        return app.exit(e) == 0 ? 0 : 1;
    }
    try {
        if (tissue_cmd->parsed()) return ui::run_tissue_command(tissue_options);
        if (trace_cmd->parsed()) return ui::run_trace_command(trace_options);
        if (simulate_cmd->parsed()) return ui::run_simulate_command(simulate_options);
        if (validate_cmd->parsed()) return ui::run_validate_command(validate_options);
        if (render_cmd->parsed()) return ui::run_render_command(render_options);
        if (dataset_cmd->parsed()) return ui::run_dataset_command(dataset_options);
    } catch (const base::InputError& e) {
        ui::StageTimer::break_line();
        std::cerr << "sonotrace: error: " << e.what() << "\n";
        return 1;
    } catch (const std::filesystem::filesystem_error& e) {
        // A path the system refuses (too long, no permission, a file where a directory
        // should be) comes from the user or their machine, not from a bug.
        ui::StageTimer::break_line();
        std::cerr << "sonotrace: error: " << e.path1().string().substr(0, 300) << ": "
                  << e.code().message() << "\n";
        return 1;
    } catch (const std::exception& e) {
        ui::StageTimer::break_line();
        std::cerr << "sonotrace: internal error: " << e.what() << "\n";
        return 3;
    }
    return 0;
}
