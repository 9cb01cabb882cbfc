#pragma once
// The surfaces a transmit's coherent echoes come from, smoothed below the map's texel.
//
// A traced specular reflection becomes a secondary source where the tracer found the
// interface in its map (imaging/channel_frame.h). On an oblique surface that is a
// staircase of the map's texels: on a 10-degree tilted plane at 0.25 mm texels the
// sources lie 0.044 mm (rms) off the plane, up to 0.09 mm. Their coherent sum needs a
// tenth of a wavelength (0.03 mm at 5 MHz): the staircase scatters the mirrored wave
// (-5 dB, arrivals 5-8 samples late: ChannelFrames.AFlatReflectorEchoesAsItsImageSources).
// Smoothed: 0.009 mm rms (99 % within 0.043), the echo within 0.2 dB.
//
// Each echo is moved along its particle's ray onto the surface its neighbours describe:
//   - chains: echoes of particles launched next to each other (at most `max_gap` apart in
//     launch order), with the same number of bounces, within `link_mm` of each other;
//   - per echo, the chain's echoes within `window_mm` of arc in all, in their principal
//     axes (u along, v across), fitted by v = a + b u + c u^2 (least squares, again
//     without those three median deviations off: the staircase's corners, where the
//     tracer's crossings stray most);
//   - the move s along the ray direction d solves v(p + s d) = a + b u + c u^2 (Newton,
//     from s = 0), kept when the ray meets the fit at more than ~12 degrees and |s| is
//     under `link_mm`.
// Two passes (the second fits the moved echoes). A chain shorter than 5 echoes, or a
// window of fewer than 5, stays as traced. The
// quadratic follows a curved wall (a 5 mm radius bends 0.22 mm over +-1.5 mm, which a line
// would flatten); the window spans several steps of the staircase at any tilt above ~10
// degrees, and below that the steps are long flat runs that reflect coherently already.
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

namespace sonotrace::imaging {

struct SurfaceEcho {
    uint32_t particle = 0;  // launch order along the face
    int bounces = 0;
    glm::dvec2 position{0.0};   // the secondary source (mm)
    glm::dvec2 direction{0.0};  // unit; the source moves along it
};

struct SurfaceSmoothing {
    double link_mm = 1.0;    // the farthest two neighbouring echoes of a chain lie apart
    double window_mm = 3.0;  // the fit's window of arc (total)
    uint32_t max_gap = 8;    // launch indices a chain may skip
    int passes = 2;          // fits of the moved echoes again (the corners' strays settle)
};

// What an echo becomes: moved onto its chain's fitted surface, it stands for the piece of
// that surface one launched particle wide (halfway to its neighbours, a gap's share
// excluded: a facet, imaging/channel_data.h).
struct SurfacePatch {
    double move_mm = 0.0;   // along the echo's direction
    double width_mm = 0.0;  // 0: not fitted, a point as traced
    glm::dvec2 tangent{1.0, 0.0};
    // The next echo of its chain (index into the echoes; -1: none). Where its launch index
    // is more than one on, the tracer let the particles between through the interface
    // without an echo (at the staircase's corners): imaging/channel_frame.cpp fills them.
    int next = -1;
};

// The patch of each echo. `echoes` in launch order (a particle's echoes in their own order).
std::vector<SurfacePatch> surface_patches(std::vector<SurfaceEcho> echoes,
                                          const SurfaceSmoothing& settings);

}  // namespace sonotrace::imaging
