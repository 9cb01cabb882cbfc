// Benchmarks of the tissue stage: loading, slicing and classifying the Colin27 head, and
// the raw speed of bilinear/trilinear AcousticMap sampling along straight paths (the
// floor under the tracer's step rate).
//
//   build/bench/bench_tissue --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include "bench/benchmark_main.h"

#include <random>

#include "probe/pose.h"
#include "tissue/acoustic_map.h"
#include "tissue/resample.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"

namespace {

using namespace sonotrace;

const tissue::Volume& colin27() {
    static const tissue::Volume v =
        tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt}).volume;
    return v;
}

tissue::PropertyMaps colin27_maps(double pixel_mm, double elevation_mm) {
    auto tf = tissue::load_transfer_function("mri-t1-head");
    tf->bind(colin27());
    const auto grid = tissue::probe_grid(probe::colin27_temporal_pose().frame(),
                                         {140.0, 160.0, elevation_mm, pixel_mm}, "bench");
    return tissue::classify(
        tissue::resample(colin27(), grid, tissue::Interpolation::trilinear, 0.0f), *tf);
}

void BM_LoadColin27(benchmark::State& state) {
    for (auto _ : state) {
        auto v = tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt});
        benchmark::DoNotOptimize(v.volume.voxels().data());
    }
    state.counters["voxels/s"] =
        benchmark::Counter(181.0 * 217 * 181, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_LoadColin27)->Unit(benchmark::kMillisecond);

void BM_SliceAndClassify(benchmark::State& state) {
    colin27();
    const double pixel_mm = 0.25;
    std::size_t samples = 0;
    for (auto _ : state) {
        auto maps = colin27_maps(pixel_mm, 0.0);
        samples = maps.geometry().voxel_count();
        benchmark::DoNotOptimize(maps.fields[0].voxels().data());
    }
    state.counters["samples/s"] =
        benchmark::Counter(double(samples), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_SliceAndClassify)->Unit(benchmark::kMillisecond);

// Argument: the refraction smoothing's sigma in micrometres (3000: the convex probe's).
void BM_BuildAcousticMap2D(benchmark::State& state) {
    const auto maps = colin27_maps(0.25, 0.0);
    const double smoothing_mm = double(state.range(0)) * 1e-3;
    for (auto _ : state) {
        auto map = tissue::AcousticMap<2>::build(maps, smoothing_mm);
        benchmark::DoNotOptimize(&map);
    }
    state.counters["texels/s"] = benchmark::Counter(double(maps.geometry().voxel_count()),
                                                    benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_BuildAcousticMap2D)->Arg(0)->Arg(3000)->Unit(benchmark::kMillisecond);

// Straight paths of kSteps samples through the map, one thread: interpolation cost only.
// Argument: how many paths advance in lockstep.
// Paths: "random" = random starts and directions over the whole map (worst case: the
// working set is the whole map); "beams" = 8 scan lines of 32 paths each, leaving the
// probe face within +-5 degrees of the axis (the tracer's access pattern).
enum class Paths { random, beams };

template <int Dim>
void sample_paths(benchmark::State& state, const tissue::AcousticMap<Dim>& map, Paths kind) {
    using Vec = glm::vec<Dim, float>;
    std::mt19937 rng(1);
    const Vec extent = map.extent_mm();
    constexpr int kPaths = 256, kSteps = 1024;
    std::vector<Vec> starts(kPaths), directions(kPaths);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int p = 0; p < kPaths; ++p) {
        if (kind == Paths::random) {
            for (int a = 0; a < Dim; ++a) {
                starts[p][a] = (0.2f + 0.6f * u(rng)) * extent[a];
                directions[p][a] = 2.0f * u(rng) - 1.0f;
            }
        } else {
            const int line = p / 32;
            starts[p] = Vec(0.0f);
            starts[p][0] = extent[0] * (0.1f + 0.8f * float(line) / 7.0f) + 2.0f * (u(rng) - 0.5f);
            if (Dim == 3) starts[p][Dim - 1] = 0.5f * extent[Dim - 1] + (u(rng) - 0.5f);
            const float angle = glm::radians(10.0f * (u(rng) - 0.5f));
            directions[p] = Vec(0.0f);
            directions[p][0] = std::sin(angle);
            directions[p][1] = std::cos(angle);
        }
        directions[p] = glm::normalize(directions[p]) * (0.5f * map.spacing()[0]);
    }
    // Paths advance in lockstep batches, as the tracer's structure-of-arrays batches do,
    // so that independent texel fetches overlap instead of waiting one after another.
    const int batch = 16;
    float sink = 0.0f;
    std::vector<Vec> x(batch);
    for (auto _ : state) {
        for (int p0 = 0; p0 < kPaths; p0 += batch) {
            for (int b = 0; b < batch; ++b) x[b] = starts[p0 + b];
            for (int s = 0; s < kSteps; ++s) {
                for (int b = 0; b < batch; ++b) {
                    const auto t = map.sample(x[b]);
                    sink += t.impedance + t.grad_refractive_index[0];
                    x[b] += directions[p0 + b];
                }
            }
        }
    }
    benchmark::DoNotOptimize(sink);
    state.counters["samples/s"] =
        benchmark::Counter(double(kPaths) * kSteps, benchmark::Counter::kIsIterationInvariantRate);
}

const tissue::AcousticMap<2>& map2d() {
    static const auto map = tissue::AcousticMap<2>::build(colin27_maps(0.25, 0.0));  // 560x640
    return map;
}
const tissue::AcousticMap<3>& map3d() {
    static const auto map = tissue::AcousticMap<3>::build(colin27_maps(0.5, 20.0));  // 280x320x40
    return map;
}
void BM_SampleBilinear2D_Random(benchmark::State& state) {
    sample_paths<2>(state, map2d(), Paths::random);
}
void BM_SampleBilinear2D_Beams(benchmark::State& state) {
    sample_paths<2>(state, map2d(), Paths::beams);
}
void BM_SampleTrilinear3D_Random(benchmark::State& state) {
    sample_paths<3>(state, map3d(), Paths::random);
}
void BM_SampleTrilinear3D_Beams(benchmark::State& state) {
    sample_paths<3>(state, map3d(), Paths::beams);
}
BENCHMARK(BM_SampleBilinear2D_Random)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SampleBilinear2D_Beams)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SampleTrilinear3D_Random)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SampleTrilinear3D_Beams)->Unit(benchmark::kMillisecond);

}  // namespace

SONOTRACE_BENCHMARK_MAIN()
