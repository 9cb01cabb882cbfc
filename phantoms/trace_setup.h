#pragma once
// A phantom as a `sonotrace trace` set-up: the medium on its 2D grid (the paper's density
// d, or the acoustic map of the properties), the particles of its "source" entry, and
// the tracer settings of its "trace" entry (phantom.h documents both).
#include "phantoms/phantom.h"
#include "simulator/trace_setups.h"

namespace sonotrace::phantoms {

// `particles` > 0 overrides the source's count. Throws base::InputError naming the
// phantom file and field (no source, a bad "trace" key).
simulator::TraceSetup trace_setup(const Phantom& phantom, int particles = 0);

// The catalogue files of the particle paper's figures (`sonotrace trace --config`).
// fig5 stays built in (simulator/trace_setups.h): it is an MRI slice, not a phantom.
inline constexpr const char* kPaperFigurePhantoms[][2] = {{"fig2", "paper_fig2"},
                                                          {"fig4a", "paper_fig4a"},
                                                          {"fig4b", "paper_fig4b"},
                                                          {"fig6", "paper_fig6"}};

}  // namespace sonotrace::phantoms
