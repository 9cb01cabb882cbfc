#pragma once
// Where the probe is: a rigid transform in the volume's world frame (mm).
//
// Probe-local axes: x = lateral (along the array), y = axial (the beam, into the
// tissue), z = elevation = x cross y. The position is the centre of the transducer face.
#include <string>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "tissue/resample.h"

namespace sonotrace::probe {

struct Pose {
    glm::dvec3 position{0.0};            // mm, world
    glm::dquat orientation{1, 0, 0, 0};  // probe-local -> world rotation

    glm::dvec3 lateral() const { return orientation * glm::dvec3(1, 0, 0); }
    glm::dvec3 axial() const { return orientation * glm::dvec3(0, 1, 0); }
    glm::dvec3 elevation() const { return orientation * glm::dvec3(0, 0, 1); }
    tissue::ProbeFrame frame() const { return {position, lateral(), axial()}; }

    // A probe at `position` whose beam points along `beam`, with the lateral axis as close
    // to `lateral_hint` as orthogonality allows. Throws std::invalid_argument if they are
    // parallel or zero.
    static Pose looking(const glm::dvec3& position, const glm::dvec3& beam,
                        const glm::dvec3& lateral_hint);
    // Rotated about its own beam axis (turns the image plane), degrees.
    Pose rotated(double degrees) const;
    // Tilted about its own lateral axis (rocks the beam out of plane), degrees.
    Pose tilted(double degrees) const;

    // "at=x,y,z beam=dx,dy,dz lateral=dx,dy,dz rotate=deg tilt=deg" (the format parse_pose reads).
    std::string to_string() const;
};

// Text of the --pose option, for help output (units and defaults).
inline constexpr const char* kPoseHelp =
    "probe pose in the volume's world frame (mm): 'at=X,Y,Z beam=DX,DY,DZ [lateral=DX,DY,DZ] "
    "[rotate=DEG] [tilt=DEG]'. at = centre of the probe face (mm); beam = direction of the "
    "beam into the tissue; lateral = direction of the array (default: the world axis most "
    "perpendicular to the beam, preferring +Y then +X); rotate = turn about the beam axis; "
    "tilt = rock about the lateral axis. 'default' = the volume's default pose.";

// Parses kPoseHelp's format; `source` (e.g. "--pose") names the option in errors.
Pose parse_pose(const std::string& text, const std::string& source);

// The pose `sonotrace` uses for the embedded Colin27 volume: on the right temple (the
// transtemporal bone window), beam pointing medially, axial image plane through the
// midbrain, lateral axis pointing anterior.
Pose colin27_temporal_pose();

}  // namespace sonotrace::probe
