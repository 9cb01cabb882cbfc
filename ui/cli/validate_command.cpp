#include "ui/cli/validate_command.h"
#include "tissue/base/data_dir.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "phantoms/validation/validation.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"

namespace sonotrace::ui {

namespace {

constexpr ParameterDoc kCaseDoc = {
    "--case", "", "run only this case (repeatable); --list shows the names. Default: every case"};
constexpr ParameterDoc kReportDoc = {
    "--report", "",
    "directory for an HTML report (index.html with the frames, profiles and plots of each case)"};
constexpr ParameterDoc kJsonDoc = {
    "--json", "",
    "file for machine-readable records {case, quantity, measured, expected, tolerance, unit, "
    "check, pass}; '-' = stdout"};
constexpr ParameterDoc kPhantomsDoc = {"--phantoms", "",
                                       "directory of the phantom catalogue (phantoms/*.json)"};
constexpr ParameterDoc kSeedDoc = {
    "--seed", "",
    "random seed of the simulated frames; the expectations do not depend on it, so other seeds "
    "show the Monte Carlo spread of each measurement"};

std::string format(double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.4g", v);
    return buffer;
}

}  // namespace

CLI::App* add_validate_command(CLI::App& app, ValidateOptions& options) {
    CLI::App* cmd = app.add_subcommand(
        "validate",
        "Prove the physics with numbers: each case simulates a phantom, measures a quantity from "
        "the images, echo events or energy maps, and compares it with what physics or geometry "
        "predicts from the phantom's parameters. Prints PASS/FAIL per quantity; exit status 0 "
        "when every case passes, 2 otherwise.");
    options.phantom_dir = base::phantom_catalogue_dir();
    add_parameter(*cmd, kCaseDoc, options.cases);
    add_parameter(*cmd, kReportDoc, options.report_dir);
    add_parameter(*cmd, kJsonDoc, options.json_path);
    add_parameter(*cmd, kPhantomsDoc, options.phantom_dir);
    add_parameter(*cmd, kSeedDoc, options.seed);
    add_parameter(*cmd, kThreadsDoc, options.threads)->check(CLI::Range(0, 1024));
    cmd->add_flag("--list", options.list, "list the cases and exit");
    cmd->add_flag("-q,--quiet", options.quiet, "print only the summary line per case");
    return cmd;
}

int run_validate_command(const ValidateOptions& o) {
    const auto& all = validation::cases();
    if (o.list) {
        for (const auto& c : all) std::cout << c.name << "  " << c.title << "\n";
        return 0;
    }
    // ---- validate the request before any work ----
    std::vector<const validation::Case*> run;
    for (const std::string& name : o.cases) {
        const auto it = std::find_if(all.begin(), all.end(),
                                     [&](const validation::Case& c) { return c.name == name; });
        if (it == all.end()) {
            std::string known;
            for (const auto& c : all) known += (known.empty() ? "" : ", ") + c.name;
            throw base::InputError("--case", "",
                                   "unknown case '" + name + "' (known: " + known + ")");
        }
        run.push_back(&*it);
    }
    if (o.cases.empty())
        for (const auto& c : all) run.push_back(&c);
    if (!std::filesystem::is_directory(o.phantom_dir))
        throw base::InputError("--phantoms", "", "'" + o.phantom_dir + "' is not a directory");
    if (!o.report_dir.empty() && std::filesystem::exists(o.report_dir) &&
        !std::filesystem::is_directory(o.report_dir))
        throw base::InputError("--report", "", "'" + o.report_dir + "' is not a directory");
    const auto thread_limit = limit_threads(o.threads);

    validation::CaseContext ctx;
    ctx.phantom_dir = o.phantom_dir;
    ctx.pictures = !o.report_dir.empty();
    ctx.seed = o.seed;
    std::vector<validation::CaseResult> results;
    int failed = 0;
    for (const validation::Case* c : run) {
        if (!o.quiet) std::cerr << "sonotrace: validating " << c->name << " ..." << std::flush;
        const auto start = std::chrono::steady_clock::now();
        validation::CaseResult r = c->run(ctx);
        r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        if (!o.quiet) std::cerr << " " << format(r.seconds) << " s\n";
        std::cout << (r.pass() ? "PASS " : "FAIL ") << c->name << ": " << c->title << "\n";
        for (const auto& m : r.measurements) {
            if (o.quiet && m.pass()) continue;
            std::cout << "  " << (m.pass() ? "pass " : "FAIL ") << m.quantity << ": "
                      << format(m.measured) << " " << m.unit << " (expected ";
            if (m.check == validation::Check::within)
                std::cout << format(m.expected) << " +- " << format(m.tolerance);
            else
                std::cout << (m.check == validation::Check::at_most ? "<= " : ">= ")
                          << format(m.expected);
            std::cout << (m.unit.empty() ? "" : " " + m.unit) << ")\n";
        }
        failed += r.pass() ? 0 : 1;
        results.push_back(std::move(r));
    }
    std::cout << results.size() - std::size_t(failed) << " of " << results.size()
              << " cases pass\n";

    base::OutputTransaction outputs;
    if (!o.json_path.empty()) {
        const nlohmann::json records = validation::to_json(run, results);
        write_json(records, o.json_path == "-" ? "-" : outputs.stage(o.json_path));
    }
    if (!o.report_dir.empty()) {
        validation::write_report(
            o.report_dir, run, results,
            [&](const std::string& path) { return outputs.stage(path); },
            "Command: sonotrace validate" + std::string(o.cases.empty() ? "" : " --case ...") +
                " --report " + o.report_dir);
    }
    outputs.commit();
    return failed == 0 ? 0 : 2;
}

}  // namespace sonotrace::ui
