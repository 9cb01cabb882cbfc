#pragma once
// BENCHMARK_MAIN() with malloc keeping freed memory first, as the sonotrace program does
// (base::keep_freed_memory): the benchmarks measure what the program runs.
#include <benchmark/benchmark.h>

#include "tissue/base/memory.h"

#define SONOTRACE_BENCHMARK_MAIN()                                        \
    int main(int argc, char** argv) {                                     \
        sonotrace::base::keep_freed_memory();                             \
        benchmark::Initialize(&argc, argv);                               \
        if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1; \
        benchmark::RunSpecifiedBenchmarks();                              \
        benchmark::Shutdown();                                            \
        return 0;                                                         \
    }
