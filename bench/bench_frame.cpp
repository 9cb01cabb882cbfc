// The default scene's frame (Colin27, convex probe on the cortex through the craniotomy,
// coronal plane through the lateral ventricles, with the falx and choroid plexus the CLI
// adds), 128 lines, 60 degrees, 8 cm, 3.5 MHz, at the three quality presets. Reports the
// time of a whole frame (plane resampling, map, beams, trace, RF, envelope, compression,
// scan conversion) with the probe's PSF table already built, the mean time of each
// stage, and particle steps per second of the trace.
//   ./build/bench/bench_frame --benchmark_repetitions=20 --benchmark_report_aggregates_only
#include "bench/benchmark_main.h"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <string>

#include "imaging/psf.h"
#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "tissue/property_maps.h"

namespace {

using namespace sonotrace;

const scene::Scene& scene() {
    static const auto s = scene::load_scene({});  // the default: Colin27, craniotomy view
    return *s;
}

// new_seeds: each frame with its own seed, as a dataset makes them: the receive weights
// (kept between frames of one seed) are made again every frame.
void frame(benchmark::State& state, imaging::Quality quality, bool new_seeds = false) {
    const scene::Scene& s = scene();
    imaging::SimulationSettings settings;
    settings.transducer = probe::find_transducer("convex", "bench");
    settings.quality = quality;
    s.apply_to(settings);
    settings.imaging.gain_db = 36.0;
    settings.trace.deposition_maps = false;  // as `sonotrace simulate` without --energy
    const imaging::QualityLevel level = imaging::quality_level(quality);
    uint64_t steps = 0;
    double plane_s = 0.0;
    std::map<std::string, double> stage_s;  // the frame's own stage timings, summed
    // The probe's PSF table is built once per probe set-up and kept (a sweep, the GUI):
    // not part of a frame.
    imaging::PsfTable::of(settings.transducer);
    for (auto _ : state) {
        if (new_seeds) settings.seed++;
        const auto start = std::chrono::steady_clock::now();
        const imaging::PlaneGrid grid =
            imaging::plane_grid(settings.transducer, s.start.pose, level.map_pixel_mm);
        // With the falx and choroid plexus, as `sonotrace simulate` adds them.
        tissue::PropertyMaps maps = s.mapper(grid.geometry, nullptr);
        imaging::prepare_plane(maps, grid, s.start);
        const auto map = imaging::frame_map(maps, settings);
        plane_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const imaging::Frame f = imaging::simulate_frame(map, grid, s.start.pose, settings);
        steps += f.stats.steps;
        for (const auto& [name, seconds] : f.timings.items())
            stage_s[name] += seconds.get<double>();
        benchmark::DoNotOptimize(f.image.image.data);
    }
    state.counters["steps/s"] = benchmark::Counter(double(steps), benchmark::Counter::kIsRate);
    // Mean seconds per frame of the main stages (the rest: beams, envelope, scan conversion).
    const double n = double(std::max<int64_t>(state.iterations(), 1));
    state.counters["plane_ms"] = 1e3 * plane_s / n;
    for (const auto& [name, seconds] : stage_s) {
        std::string key = name;
        std::replace(key.begin(), key.end(), ' ', '_');
        state.counters[key + "_ms"] = 1e3 * seconds / n;
    }
    state.counters["frames/s"] =
        benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}

BENCHMARK_CAPTURE(frame, interactive, imaging::Quality::interactive)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(frame, standard, imaging::Quality::standard)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(frame, standard_new_seeds, imaging::Quality::standard, true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(frame, high, imaging::Quality::high)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The whole frame as `sonotrace simulate` makes it (simulate_plane: the plane's or the
// slab's maps, then the frame), traced in the plane or in the slab of the elevation beam,
// at the standard quality: their ratio is the cost of --trace 3d. peak_rss_mb: the
// process's peak so far (the 3D runs come last).
void whole_frame(benchmark::State& state, int dimensions) {
    const scene::Scene& s = scene();
    imaging::SimulationSettings settings;
    settings.transducer = probe::find_transducer("convex", "bench");
    settings.quality = imaging::Quality::standard;
    settings.trace_dimensions = dimensions;
    s.apply_to(settings);
    settings.imaging.gain_db = 36.0;
    settings.trace.deposition_maps = false;
    imaging::PsfTable::of(settings.transducer);
    imaging::simulate_plane(s.mapper, s.start, settings, false);  // tables of the probe set-up
    for (auto _ : state) {
        const imaging::SimulatedFrame f =
            imaging::simulate_plane(s.mapper, s.start, settings, false);
        benchmark::DoNotOptimize(f.frame.image.image.data);
    }
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    state.counters["peak_rss_mb"] = double(usage.ru_maxrss) / 1024.0;
}

BENCHMARK_CAPTURE(whole_frame, trace_2d, 2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(whole_frame, trace_3d, 3)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

SONOTRACE_BENCHMARK_MAIN()
