// The aperture tables of a new probe setting (imaging/psf.h), built afresh for each
// preset: what a dataset that varies the probe pays per new setting, and a simulation
// pays on its first frame. Reports the rows built (lines share rows) as a counter.
//   ./build/bench/bench_psf --benchmark_repetitions=5 --benchmark_report_aggregates_only
#include "bench/benchmark_main.h"

#include "imaging/psf.h"
#include "probe/transducer.h"

namespace {

using namespace sonotrace;

void table_build(benchmark::State& state, const char* preset) {
    const probe::Transducer t = probe::find_transducer(preset, "bench");
    int rows = 0, computed = 0;
    for (auto _ : state) {
        const auto table = imaging::PsfTable::build(t);
        rows = table->row_count();
        computed = table->computed_rows();
        benchmark::DoNotOptimize(table.get());
    }
    state.counters["rows"] = rows;
    state.counters["computed"] = computed;
}

// A new imaging depth of a probe whose rows other depths already made (a dataset drawing
// the depth per frame): the table is assembled from the shared rows, plus any deeper
// ones. Depths cycle through 35-50 mm in 0.37 mm steps, each one new to the table cache.
void table_new_depth(benchmark::State& state, const char* preset) {
    probe::Transducer t = probe::find_transducer(preset, "bench");
    int step = 0;
    for (auto _ : state) {
        t.depth_mm = 35.0 + 0.37 * (step++ % 41);
        benchmark::DoNotOptimize(imaging::PsfTable::of(t).get());
    }
}

}  // namespace

BENCHMARK_CAPTURE(table_new_depth, convex, "convex")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(table_build, linear, "linear")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(table_build, convex, "convex")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(table_build, phased, "phased")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(table_build, radial, "radial")->Unit(benchmark::kMillisecond)->UseRealTime();

SONOTRACE_BENCHMARK_MAIN()
