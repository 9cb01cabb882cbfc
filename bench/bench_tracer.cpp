// Particle-steps per second of the tracer with full acoustic physics and event recording
// (refraction, interfaces with eq. 10 decisions, diffuse lobes, attenuation, scattering,
// roulette, echo records), on all cores.
//
//   build/bench/bench_tracer --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//   build/bench/bench_tracer --digest     # one hash per scene: do two builds trace the same bits?
#include "bench/benchmark_main.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <string_view>
#include <type_traits>

#include "probe/pose.h"
#include "simulator/trace_setups.h"
#include "simulator/tracer.h"
#include "tissue/resample.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"

namespace {

using namespace sonotrace;

// 1024 x 1024 texels of 0.1 mm: soft tissue with round inclusions (fat, liver, a cyst,
// a bone plate), smoothed over 2 texels.
tissue::PropertyMaps synthetic_1024() {
    const int n = 1024;
    const double h = 0.1;
    auto maps =
        simulator::homogeneous(n, n, h, tissue::find_tissue("soft_tissue", "", "").properties);
    struct Blob {
        double x, y, r;
        const char* tissue;
    };
    const Blob blobs[] = {{30, 30, 12, "fat"},
                          {70, 40, 15, "liver"},
                          {50, 70, 8, "water"},
                          {25, 80, 6, "cortical_bone"},
                          {80, 85, 10, "kidney"}};
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            for (const Blob& b : blobs) {
                const double d = std::hypot(i * h - b.x, j * h - b.y) - b.r;
                const double t = std::clamp(0.5 - d / (2 * h), 0.0, 1.0);
                if (t <= 0.0) continue;
                const auto p = tissue::find_tissue(b.tissue, "", "").properties;
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f) {
                    float& v = maps.fields[f].at(i, j);
                    v = float(v * (1 - t) + p.values[f] * t);
                }
            }
        }
    }
    return maps;
}

tissue::PropertyMaps colin27_maps(double pixel_mm, double elevation_mm) {
    static const tissue::Volume head =
        tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt}).volume;
    auto tf = tissue::load_transfer_function("mri-t1-head");
    tf->bind(head);
    const auto grid = tissue::probe_grid(probe::colin27_temporal_pose().frame(),
                                         {140.0, 160.0, elevation_mm, pixel_mm}, "bench");
    return tissue::classify(tissue::resample(head, grid, tissue::Interpolation::trilinear, 0.0f),
                            *tf);
}

// A fan of `lines` scan lines from the top centre, `per_line` particles each.
simulator::Sources<2> fan_2d(const tissue::AcousticMap<2>& map, int lines, int per_line) {
    simulator::Sources<2> sources;
    const glm::vec2 origin(0.5f * map.extent_mm().x, 0.01f);
    for (int l = 0; l < lines; ++l) {
        const float a = glm::radians(-35.0f + 70.0f * (l + 0.5f) / lines);
        auto beam =
            simulator::fan_beam(origin, {std::sin(a), std::cos(a)}, 1.0f, per_line, uint32_t(l));
        sources.insert(sources.end(), beam.begin(), beam.end());
    }
    return sources;
}

simulator::Sources<3> fan_3d(const tissue::AcousticMap<3>& map, int lines, int per_line) {
    simulator::Sources<3> sources;
    const glm::vec3 e = map.extent_mm();
    const glm::vec3 origin(0.5f * e.x, 0.01f, 0.5f * e.z);
    const int side = std::max(1, int(std::sqrt(double(per_line))));
    for (int l = 0; l < lines; ++l) {
        const float a = glm::radians(-35.0f + 70.0f * (l + 0.5f) / lines);
        auto beam = simulator::fan_beam_3d(origin, {std::sin(a), std::cos(a), 0.0f}, 1.0f, side,
                                           uint32_t(l));
        sources.insert(sources.end(), beam.begin(), beam.end());
    }
    return sources;
}

template <int Dim>
void run(benchmark::State& state, const tissue::AcousticMap<Dim>& map,
         const simulator::Sources<Dim>& sources) {
    simulator::TraceSettings settings;  // full acoustic physics, echoes recorded
    settings.frequency_mhz = 3.5;
    uint64_t steps = 0, uniform_steps = 0, vector_steps = 0;
    std::size_t echoes = 0;
    for (auto _ : state) {
        const auto result = simulator::trace(map, sources, settings);
        steps += result.stats.steps;
        uniform_steps += result.stats.uniform_steps;
        vector_steps += result.stats.vector_steps;
        echoes = result.echoes.size();
        benchmark::DoNotOptimize(result.echoes.data());
    }
    state.counters["steps/s"] = benchmark::Counter(double(steps), benchmark::Counter::kIsRate);
    state.counters["echoes"] = double(echoes);
    state.counters["uniform_steps"] = double(uniform_steps) / double(std::max<uint64_t>(steps, 1));
    state.counters["vector_steps"] = double(vector_steps) / double(std::max<uint64_t>(steps, 1));
    state.counters["uniform_blocks"] = map.uniform_block_fraction();
}

void BM_Trace2D_Synthetic1024(benchmark::State& state) {
    static const auto map = tissue::AcousticMap<2>::build(synthetic_1024());
    static const auto sources = fan_2d(map, 64, 256);
    run<2>(state, map, sources);
}
BENCHMARK(BM_Trace2D_Synthetic1024)->Unit(benchmark::kMillisecond)->UseRealTime();

// The same fan in plain soft tissue: every step on the uniform-block path.
void BM_Trace2D_Uniform1024(benchmark::State& state) {
    static const auto map = tissue::AcousticMap<2>::build(simulator::homogeneous(
        1024, 1024, 0.1, tissue::find_tissue("soft_tissue", "", "").properties));
    static const auto sources = fan_2d(map, 64, 256);
    run<2>(state, map, sources);
}
BENCHMARK(BM_Trace2D_Uniform1024)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_Trace2D_Colin27(benchmark::State& state) {
    static const auto map = tissue::AcousticMap<2>::build(colin27_maps(0.25, 0.0));
    static const auto sources = fan_2d(map, 64, 256);
    run<2>(state, map, sources);
}
BENCHMARK(BM_Trace2D_Colin27)->Unit(benchmark::kMillisecond)->UseRealTime();

// The yardstick: a bare bilinear stepping loop, the same fan on the same map,
// both cores. Straight paths in half-texel steps until they leave the map, every field of
// the texel sampled (summed so that nothing is optimised away), no physics. The tracer's
// 2D target (100 M) was set against this loop's ~118 M; run beside the tracer, it tells
// how fast the machine is that hour (bench/README.md).
void BM_BareBilinearSteps2D_Colin27(benchmark::State& state) {
    static const auto map = tissue::AcousticMap<2>::build(colin27_maps(0.25, 0.0));
    static const auto sources = fan_2d(map, 64, 256);
    const std::size_t lines = 64, per_line = sources.size() / lines;
    const float step = 0.5f * std::min(map.spacing().x, map.spacing().y);
    uint64_t steps = 0;
    for (auto _ : state) {
        std::atomic<uint64_t> taken{0};
        std::atomic<double> checksum{0.0};  // keeps the samples live
        tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
            uint64_t n = 0;
            float sum = 0.0f;
            for (std::size_t p = l * per_line; p < (l + 1) * per_line; ++p) {
                glm::vec2 x = sources[p].position;
                const glm::vec2 r = glm::normalize(sources[p].direction);
                for (; map.inside(x); x += step * r, ++n) {
                    const auto t = map.sample(x);
                    sum += t.impedance + t.grad_impedance[0] + t.grad_impedance[1] +
                           t.refractive_index + t.grad_refractive_index[0] +
                           t.grad_refractive_index[1] + t.attenuation + t.backscatter;
                }
            }
            taken += n;
            checksum.fetch_add(double(sum));
        });
        steps += taken;
        benchmark::DoNotOptimize(checksum.load());
    }
    state.counters["steps/s"] = benchmark::Counter(double(steps), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BareBilinearSteps2D_Colin27)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_Trace3D_Colin27(benchmark::State& state) {
    static const auto map = tissue::AcousticMap<3>::build(colin27_maps(0.5, 20.0));
    static const auto sources = fan_3d(map, 32, 256);
    run<3>(state, map, sources);
}
BENCHMARK(BM_Trace3D_Colin27)->Unit(benchmark::kMillisecond)->UseRealTime();

// --digest: one hash per scene and tracer configuration of everything a trace returns
// (echoes, energy maps, paths, echo profile, ledger, step counts). Two builds that print
// the same lines trace the same bits: the check for a change that claims to change no
// result (bench/README.md).
class Digest {
  public:
    template <class T>
    void add(const T& value) {
        static_assert(std::is_trivially_copyable_v<T>);
        const auto* bytes = reinterpret_cast<const unsigned char*>(&value);
        for (std::size_t i = 0; i < sizeof value; ++i)
            hash_ = (hash_ ^ bytes[i]) * 0x100000001b3ull;
    }
    template <class Range>
    void add_all(const Range& values) {
        for (const auto& v : values) add(v);
    }
    uint64_t value() const { return hash_; }

  private:
    uint64_t hash_ = 0xcbf29ce484222325ull;  // FNV-1a
};

template <int Dim>
uint64_t digest_of(const simulator::TraceResult<Dim>& r) {
    Digest d;
    for (const auto& e : r.echoes) {  // field by field: the record has padding
        d.add(e.line), d.add(e.particle), d.add(e.time_s), d.add(e.energy), d.add(e.weight);
        d.add(e.position), d.add(e.bounces), d.add(e.kind), d.add(e.cos_incidence);
        d.add(e.lobe_exponent), d.add(e.return_weight), d.add(e.normal);
    }
    d.add_all(r.fluence.voxels()), d.add_all(r.absorbed.voxels());
    for (const auto& p : r.paths) d.add(p.line), d.add(p.particle), d.add_all(p.vertices);
    d.add_all(r.echo_profile.intensity), d.add_all(r.echo_profile.position);
    d.add_all(r.echo_profile.illumination);
    d.add_all(r.echo_profile.illuminated_position);
    d.add(r.ledger), d.add(r.stats);
    return d.value();
}

template <int Dim>
void print_digests(const char* scene, const tissue::AcousticMap<Dim>& map,
                   const simulator::Sources<Dim>& sources) {
    struct Variant {
        const char* name;
        bool vector_steps, uniform_runs;
    };
    for (const Variant v : {Variant{"vector", true, true}, Variant{"scalar", false, true},
                            Variant{"no-uniform-runs", true, false}}) {
        simulator::TraceSettings settings;
        settings.frequency_mhz = 3.5;
        settings.vector_steps = v.vector_steps;
        settings.uniform_runs = v.uniform_runs;
        settings.record_paths = 4;
        settings.echo_profile = simulator::EchoProfileSettings{2e-7, 1200};
        std::printf(
            "%-12s %-16s %016llx\n", scene, v.name,
            static_cast<unsigned long long>(digest_of(simulator::trace(map, sources, settings))));
    }
}

void print_all_digests() {
    const auto synthetic = tissue::AcousticMap<2>::build(synthetic_1024());
    print_digests("synthetic2d", synthetic, fan_2d(synthetic, 64, 64));
    const auto uniform = tissue::AcousticMap<2>::build(simulator::homogeneous(
        1024, 1024, 0.1, tissue::find_tissue("soft_tissue", "", "").properties));
    print_digests("uniform2d", uniform, fan_2d(uniform, 64, 64));
    const auto colin = tissue::AcousticMap<2>::build(colin27_maps(0.25, 0.0));
    print_digests("colin27-2d", colin, fan_2d(colin, 64, 64));
    const auto colin3 = tissue::AcousticMap<3>::build(colin27_maps(0.5, 20.0));
    print_digests("colin27-3d", colin3, fan_3d(colin3, 16, 64));
}

}  // namespace

int main(int argc, char** argv) {
    sonotrace::base::keep_freed_memory();
    if (argc == 2 && std::string_view(argv[1]) == "--digest") {
        print_all_digests();
        return 0;
    }
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
