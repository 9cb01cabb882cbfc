#pragma once
// The volume -> slice -> acoustic properties pipeline shared by `sonotrace tissue` and
// `sonotrace trace`: options (documented once), validation before anything heavy, and
// the stages themselves.
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "phantoms/scene/records.h"
#include "phantoms/scene/scene.h"
#include "probe/pose.h"
#include "tissue/property_maps.h"
#include "tissue/resample.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"
#include "ui/cli/command_common.h"

namespace sonotrace::ui {

// The volume options (scene::VolumeOptions) and the slice under the probe.
struct SliceOptions : scene::VolumeOptions {
    std::string pose = "default";
    double width_mm = 0.0;
    double depth_mm = 0.0;
    double resolution_mm = 0.25;
    double elevation_mm = 0.0;
};

void add_slice_options(CLI::App& cmd, SliceOptions& options, bool with_elevation);
// Only the volume options: --volume, --spacing, --tf, --pose, --outside.
void add_volume_options(CLI::App& cmd, SliceOptions& options);

using scene::geometry_json;
using scene::pose_json;
using scene::volume_source_json;

struct Slice {
    scene::VolumeSource source;
    probe::Pose pose;
    tissue::GridExtent extent;
    tissue::VolumeGeometry grid;
    tissue::Volume values;      // resampled voxel values
    tissue::PropertyMaps maps;  // acoustic properties on the grid
};

// Validates every option, then loads, slices and classifies (timed stages on `timer`).
Slice make_slice(const SliceOptions& options, StageTimer& timer);

// The sidecar description of a slice (volume, transfer function, pose, grid).
nlohmann::json slice_json(const Slice& slice, const SliceOptions& options);

}  // namespace sonotrace::ui
