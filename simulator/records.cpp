#include "simulator/records.h"

namespace sonotrace::simulator {

const char* to_string(EchoKind kind) {
    switch (kind) {
        case EchoKind::specular:
            return "specular";
        case EchoKind::diffuse:
            return "diffuse";
        case EchoKind::scatter:
            return "scatter";
        case EchoKind::returned_to_probe:
            return "returned-to-probe";
    }
    return "?";
}

EnergyLedger& EnergyLedger::operator+=(const EnergyLedger& o) {
    injected += o.injected, absorbed += o.absorbed, escaped += o.escaped, recorded += o.recorded;
    remaining += o.remaining, roulette_killed += o.roulette_killed,
        roulette_added += o.roulette_added;
    return *this;
}

TraceStats& TraceStats::operator+=(const TraceStats& o) {
    particles += o.particles, steps += o.steps, uniform_steps += o.uniform_steps;
    vector_steps += o.vector_steps;
    interface_events += o.interface_events;
    reflections += o.reflections, total_reflections += o.total_reflections;
    scatter_events += o.scatter_events, captured += o.captured;
    return *this;
}

}  // namespace sonotrace::simulator
