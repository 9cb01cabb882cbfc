#pragma once
// What one scan line of the tracer produces (simulator/tracer.cpp, private to it), and how
// the lines' echoes and echo profiles are put in order: lines are traced in parallel and
// merged in line order, so the result does not depend on the threads.
#include <array>
#include <cstdint>
#include <numeric>
#include <vector>

#include <tbb/parallel_for.h>

#include "simulator/records.h"
#include "simulator/trace_settings.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

// One bin of a line's echo profile: a sum and its first moment, in double (sums of
// millions of small steps). The illumination's and the scattered intensity's bins lie in
// two arrays: a frame lit by its map touches only the first, half the memory.
template <int Dim>
struct ProfileBin {
    double sum;
    std::array<double, Dim> first;  // sum of value x

    void add(double value, const Vec<Dim>& x) {
        sum += value;
        for (int a = 0; a < Dim; ++a) first[std::size_t(a)] += value * double(x[a]);
    }
};

// Everything one scan line produces.
template <int Dim>
struct LineOutput {
    std::vector<EchoEvent<Dim>> echoes;
    std::vector<Path<Dim>> paths;
    std::vector<double> ring;
    // The echo profile's bins of this line: the illumination and the scattered intensity
    // w (EchoProfile); the second empty without EchoProfileSettings::scattered.
    std::vector<ProfileBin<Dim>> lit, scattered;
    EnergyLedger ledger;
    TraceStats stats;

    // A step's terms at x into the bin of its echo: `step_bins`, the step's time in bins,
    // is doubled (there and back). `scattered_term` 0: the step scattered nothing.
    void add_profile(const Vec<Dim>& x, double step_bins, float lit_term, float scattered_term) {
        const double bin = 2.0 * step_bins;
        if (!(bin >= 0.0) || bin >= double(lit.size())) return;
        // The line's next bins fetched ahead: each particle of the batch walks its own.
        const auto at = std::size_t(bin);
        if (at + 8 < lit.size()) __builtin_prefetch(lit.data() + at + 8);
        lit[at].add(double(lit_term), x);
        if (scattered_term > 0.0f && !scattered.empty())
            scattered[at].add(double(scattered_term), x);
    }
};

// A line's echoes ordered by particle (its index within the line, < `particles`), each
// particle's in the order recorded (time order): a counting sort, what std::stable_sort
// gives, in two passes instead of a merge sort's log2(n).
template <int Dim>
void sort_by_particle(std::vector<EchoEvent<Dim>>& echoes, std::size_t particles) {
    std::vector<uint32_t> first(particles + 1, 0);
    for (const EchoEvent<Dim>& e : echoes) ++first[e.particle + 1];
    std::partial_sum(first.begin(), first.end(), first.begin());
    std::vector<EchoEvent<Dim>> sorted(echoes.size());
    for (const EchoEvent<Dim>& e : echoes) sorted[first[e.particle]++] = e;
    echoes = std::move(sorted);
}

// The lines' profiles as one EchoProfile: row `line_ids[l]` holds outputs[l]'s bins; line
// ids without particles keep empty rows. `step_mm`: the tracer's full step.
template <int Dim>
EchoProfile<Dim> merge_echo_profiles(const std::vector<LineOutput<Dim>>& outputs,
                                     const std::vector<uint32_t>& line_ids,
                                     const EchoProfileSettings& settings, double step_mm) {
    EchoProfile<Dim> p;
    uint32_t max_line = 0;
    for (const uint32_t id : line_ids) max_line = std::max(max_line, id);
    p.lines = line_ids.empty() ? 0 : int(max_line) + 1;
    p.bins = settings.bins;
    p.bin_s = settings.bin_s;
    p.step_mm = step_mm;
    p.intensity.assign(std::size_t(p.lines) * std::size_t(p.bins), 0.0f);
    p.illumination.assign(p.intensity.size(), 0.0f);
    p.illuminated_position.assign(p.intensity.size(), Vec<Dim>(0.0f));
    p.position.assign(p.intensity.size(), Vec<Dim>(0.0f));
    tbb::parallel_for(std::size_t(0), outputs.size(), [&](std::size_t l) {
        const std::size_t row = std::size_t(line_ids[l]) * std::size_t(p.bins);
        const LineOutput<Dim>& o = outputs[l];
        for (int i = 0; i < p.bins; ++i) {
            const std::size_t at = row + std::size_t(i);
            const ProfileBin<Dim>& lit = o.lit[std::size_t(i)];
            p.illumination[at] = float(lit.sum);
            if (lit.sum > 0.0)
                for (int a = 0; a < Dim; ++a)
                    p.illuminated_position[at][a] = float(lit.first[std::size_t(a)] / lit.sum);
            if (o.scattered.empty()) continue;
            const ProfileBin<Dim>& w = o.scattered[std::size_t(i)];
            p.intensity[at] = float(w.sum);
            if (!(w.sum > 0.0)) continue;
            const double inverse_w = 1.0 / w.sum;
            for (int a = 0; a < Dim; ++a)
                p.position[at][a] = float(w.first[std::size_t(a)] * inverse_w);
        }
    });
    return p;
}

}  // namespace
}  // namespace sonotrace::simulator::detail
