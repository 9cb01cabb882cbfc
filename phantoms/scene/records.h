#pragma once
// What a sidecar says about a scene's parts (a pose, a volume and its transfer function,
// a transducer), written the same by `simulate`, `trace`, `tissue`, the GUI's snapshots
// and Python's frames.
#include <nlohmann/json.hpp>

#include "phantoms/scene/scene.h"
#include "probe/pose.h"
#include "probe/transducer.h"
#include "tissue/volume.h"

namespace sonotrace::scene {

// Its text form and its axes in world coordinates.
nlohmann::json pose_json(const probe::Pose& pose);
// Dimensions, spacing, origin and direction of a grid.
nlohmann::json geometry_json(const tissue::VolumeGeometry& g);
// The volume (as asked for and as loaded), its transfer function and the loader's warnings.
nlohmann::json volume_source_json(const VolumeSource& source, const VolumeOptions& options);
// Name, description and every parameter under its record key (with its unit).
nlohmann::json transducer_json(const probe::Transducer& t);

}  // namespace sonotrace::scene
