#pragma once
// Frames of the embedded head (Colin27) with the truth to measure them against: its
// tissue labels and acoustic map on the frame's plane. Shared by the head cases of
// `sonotrace validate` (cases_head.cpp) and the head tests.
#include <cstdint>
#include <memory>
#include <string>

#include "imaging/anatomy_truth.h"
#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "tissue/volume.h"

namespace sonotrace::validation {

// One frame of a head scene, its labels and map.
struct TruthFrame {
    imaging::PlaneGrid grid;
    tissue::Volume labels;
    tissue::AcousticMap<2> map;
    imaging::Frame frame;
    probe::Transducer transducer;
    // imaging::clear_samples() of the frame's envelope against these labels.
    imaging::ClearSamples samples(int inside, int outside, const imaging::Clearance& clear_mm,
                                  double from_mm, double to_mm) const;
};

// A view of the embedded head ("craniotomy", the default frame's, or "temporal"); `s`
// gets the view's probe, imaging to `depth_mm` (0: the preset's depth), what the scene
// sets (Scene::apply_to), and the display `simulate` makes: the scene's gain and the
// automatic TGC.
std::shared_ptr<const scene::Scene> head_view(const std::string& view,
                                              imaging::SimulationSettings* s,
                                              double depth_mm = 0.0);

// The frame of `head` with settings `s` and seed `seed`: traced in the plane, or in the
// elevation beam's slab when s.trace_dimensions is 3 (as `--trace 3d`).
TruthFrame truth_frame(const scene::Scene& head, imaging::SimulationSettings s, uint64_t seed);

// How scan line `line` meets the near skull, from the map alone (Snell's law, independent
// of the trace): the angle between the line and the skull's normal where the line enters
// bone (speed above 2000 m/s within its first 40 mm; the normal is grad Z summed over
// the 2 mm around the entry), and the longitudinal critical angle there, asin(c1 / c2)
// with c1 the speed 1 mm before the entry and c2 the fastest speed within 3 mm after it.
struct NearSkull {
    bool found = false;
    double incidence_deg = 0.0, critical_deg = 0.0;
};
NearSkull near_skull(const TruthFrame& truth, int line);

}  // namespace sonotrace::validation
