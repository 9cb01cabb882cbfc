#pragma once
// `simulate --sweep`, Python's sweep=: the probe's placements along an axis or from a file
// of poses.
#include <string>
#include <vector>

#include "imaging/simulation.h"

namespace sonotrace::scene {

// One probe position of a run: where it is and what the scene does there.
struct SweepPlacement {
    imaging::ScenePlacement scene;
    double offset_mm = 0.0;  // along the sweep
};
// AXIS:LENGTH:STEP moves the scene's probe from -LENGTH/2 to +LENGTH/2 along AXIS
// (elevation, lateral, axial: the probe's own axes; or X,Y,Z in world mm); or a text file
// with one --pose per line. Empty: `base` alone. Throws base::InputError naming --sweep
// or the file and line.
std::vector<SweepPlacement> sweep_placements(const std::string& sweep,
                                             const imaging::ScenePlacement& base);

}  // namespace sonotrace::scene
