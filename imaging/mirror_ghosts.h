#pragma once
// Mirror ghosts of point targets. A target in front of a strong reflector (bone, air) also
// echoes by way of it: the transmit beam, turned by the reflector, lights the target and
// the echo comes back the same way. Its path is as long as the straight one to the target
// mirrored through the reflector, so an image shows it there (image source), R^2 times the
// direct echo (R the reflector's pressure reflection coefficient) less the longer path's
// losses.
//
// The reflectors are found by rays from the target through the map: a ray that meets an
// interface of |R| >= kStrongReflection, at least kReflectorDepthMm thick (a neighbouring
// target's core is no mirror), turns there specularly about the impedance gradient and
// then reaches the array's face names the image: the point as far behind the face along
// the arriving ray as the whole path is long. The rays of one plane reflector name one
// image; images within kSameImageMm are one ghost. One reflection is followed (a ray that
// meets a second strong interface is dropped), and only the path that takes the reflector
// both ways: an echo that takes it one way only lands between target and ghost, weaker by
// the beam's misalignment, and is left out.
#include <vector>

#include <glm/glm.hpp>

#include "probe/transducer.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::imaging {

struct MirrorGhost {
    glm::dvec2 at{0.0};       // the image point (probe plane, mm)
    double reflection = 0.0;  // R of the reflector
    double optical = 0.0;     // attenuation along the path (as PointEcho's: nepers)
    double delay_mm = 0.0;    // integral of (n - 1) ds along the path
};

class MirrorSearch {
  public:
    static constexpr double kStrongReflection = 0.3;
    static constexpr double kReflectorDepthMm = 1.0;
    static constexpr double kSameImageMm = 0.5;
    static constexpr int kRays = 360;

    // `to_map`: the map position of the probe plane's origin (PlaneGrid::to_map).
    MirrorSearch(const tissue::AcousticMap<2>& map, const glm::dvec2& to_map,
                 const probe::Transducer& t);
    // The ghosts of a target at `target` (probe plane, mm), rays starting `start_mm` from
    // it (outside its own painted core). None when the map holds no strong contrast.
    std::vector<MirrorGhost> ghosts(const glm::dvec2& target, double start_mm) const;

  private:
    const tissue::AcousticMap<2>& map_;
    glm::dvec2 to_map_;
    double frequency_mhz_ = 0.0, step_mm_ = 0.0;
    bool contrast_ = false;
    std::vector<glm::dvec2> face_;  // the array's face as a polyline (probe plane)
    glm::dvec2 face_low_{0.0}, face_high_{0.0};
};

}  // namespace sonotrace::imaging
