#include "ui/cli/dataset_command.h"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <iostream>

#include "tissue/base/error.h"
#include "ui/dataset/mpi.h"

namespace sonotrace::ui {

namespace {

constexpr ParameterDoc kSpecDoc = {
    "spec", "",
    "JSON file of the dataset: frames, frames_per_shard, seed, image {width, height} (pixels), "
    "sources [{scene | phantom | volume, weight}], probes, transducer {any numeric "
    "parameter of simulate's, e.g. frequency, depth, focus, f-number}, gain_db, "
    "dynamic_range_db, noise_snr_db (each a number or [low, high], drawn uniformly per "
    "frame), tgc {slope, sliders, slider_db}, tissues {TISSUE: {PROPERTY: [low, high] or "
    "{spread}}}, pose {lateral_mm, elevation_mm, rotation_deg, tilt_deg} (half-ranges about "
    "the source's start), disable, quality, write [bmode, labels, labels_echo, envelope, rf, "
    "energy]; every drawn value is a column of the frame table; see ui/dataset/spec.h"};
constexpr ParameterDoc kDatasetOutDoc = {
    "--out", "",
    "directory of the shards (shard_NNNNN.h5) and manifest.json; a run into a directory that "
    "holds some shards of the same spec makes only the missing ones"};

constexpr ParameterDoc kVerifyDoc = {
    "--verify", "",
    "check the finished dataset in this directory instead of making one: every shard its "
    "manifest names is there, whole and unchanged (header, content checksum, the manifest's "
    "checksum); exit 1 naming each damaged or missing shard (a run of its spec into the same "
    "--out makes them again)"};

// SIGINT and SIGTERM stop after the frame in flight (its shard is abandoned and made
// again by the next run); a second signal exits at once.
std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) {
    if (g_stop.exchange(true)) _exit(130);
}

std::string duration_text(double seconds) {
    if (!std::isfinite(seconds)) return "?";
    const long s = std::lround(seconds);
    if (s >= 3600) return std::to_string(s / 3600) + " h " + std::to_string(s % 3600 / 60) + " min";
    if (s >= 60) return std::to_string(s / 60) + " min " + std::to_string(s % 60) + " s";
    return std::to_string(s) + " s";
}

}  // namespace

CLI::App* add_dataset_command(CLI::App& app, DatasetOptions& o) {
    CLI::App* cmd = app.add_subcommand(
        "dataset",
        "Make a dataset of B-mode frames with exact ground truth (labels, pose, probe, "
        "parameters) from a JSON spec: frame i is a pure function of the spec and i, frames are "
        "stored in HDF5 shards (h5py reads them) with a manifest. Interrupted runs resume.");
    CLI::Option* spec = cmd->add_option(kSpecDoc.flag, o.spec, kSpecDoc.description);
    CLI::Option* verify = add_parameter(*cmd, kVerifyDoc, o.verify);
    spec->excludes(verify);
    add_parameter(*cmd, kDatasetOutDoc, o.out_dir);
    add_parameter(*cmd, kThreadsDoc, o.threads)->check(CLI::Range(0, 1024));
    cmd->add_flag("-q,--quiet", o.quiet, "no progress on stderr");
    return cmd;
}

namespace {

int run_verify(const DatasetOptions& o) {
    ProgressBar bar("verifying " + o.verify, o.quiet);
    const dataset::VerifyReport report = dataset::verify_dataset(
        o.verify, [&](uint64_t done, uint64_t total) { bar.update(done, total, ""); });
    bar.finish();
    for (const std::string& problem : report.problems)
        std::cerr << "sonotrace: " << problem << "\n";
    if (!report.problems.empty())
        throw base::InputError(o.verify, "",
                               std::to_string(report.problems.size()) + " of " +
                                   std::to_string(report.shards) +
                                   " shards are damaged or missing; a run of the dataset's "
                                   "spec into this directory makes them again");
    if (!o.quiet)
        std::cerr << "sonotrace: " << o.verify << ": all " << report.shards << " shards verified\n";
    return 0;
}

}  // namespace

int run_dataset_command(const DatasetOptions& o) {
    if (!o.verify.empty()) return run_verify(o);
    if (o.spec.empty())
        throw base::InputError("spec", "",
                               "missing: give a dataset spec (a JSON file), or "
                               "--verify DIR to check a finished dataset");
    const auto thread_limit = limit_threads(o.threads);
    const dataset::Spec spec = dataset::read_spec(o.spec);
    // Under MPI only rank 0 draws the progress (make_dataset_mpi calls it there alone).
    ProgressBar bar("dataset of " + std::to_string(spec.frames) + " frames", o.quiet);
    const auto start = std::chrono::steady_clock::now();
    dataset::RunOptions run;
    run.out_dir = o.out_dir;
    run.progress = [&](uint64_t done, uint64_t total) {
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double rate = done / std::max(seconds, 1e-9);
        char note[96];
        std::snprintf(note, sizeof note, "%.2f frames/s, %s left", rate,
                      duration_text(double(total - done) / rate).c_str());
        bar.update(done, total, note);
    };
    g_stop = false;
    run.stop = [] { return g_stop.load(); };
    const auto previous_int = std::signal(SIGINT, on_signal);
    const auto previous_term = std::signal(SIGTERM, on_signal);
    int rank = 0;
    const dataset::RunReport report = dataset::launched_by_mpi()
                                          ? dataset::make_dataset_mpi(spec, run, &rank)
                                          : dataset::make_dataset(spec, run);
    std::signal(SIGINT, previous_int);
    std::signal(SIGTERM, previous_term);
    bar.finish();
    for (const std::string& damaged : report.damaged)
        std::cerr << "sonotrace: " << damaged << "; made again\n";
    if (rank != 0) return report.failed ? 1 : report.stopped ? 130 : 0;  // rank 0 reports
    if (report.stopped) {
        std::cerr << "sonotrace: stopped; " << report.shards_written
                  << " shards written this run, the rest follow when the same command runs "
                     "again\n";
        return 130;
    }
    if (!o.quiet)
        std::cerr << "sonotrace: " << report.shards_written << " shards written, "
                  << report.shards_kept << " kept; " << report.manifest << "\n";
    return 0;
}

}  // namespace sonotrace::ui
