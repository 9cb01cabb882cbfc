#pragma once
// The volume -> slice -> acoustic properties pipeline shared by `sonotrace tissue` and
// `sonotrace trace`: options (documented once), validation before anything heavy, and
// the stages themselves.
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "probe/pose.h"
#include "tissue/property_maps.h"
#include "tissue/resample.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"
#include "ui/cli/command_common.h"

namespace sonotrace::ui {

struct SliceOptions {
    std::string volume = "default";
    std::string spacing;
    std::string tf;
    std::string pose = "default";
    double width_mm = 0.0;
    double depth_mm = 0.0;
    double resolution_mm = 0.25;
    double elevation_mm = 0.0;
    double outside = std::numeric_limits<double>::quiet_NaN();
};

void add_slice_options(CLI::App& cmd, SliceOptions& options, bool with_elevation);
// Only the volume options: --volume, --spacing, --tf, --pose, --outside.
void add_volume_options(CLI::App& cmd, SliceOptions& options);

// Default pose for a volume other than the embedded head: on the top face of its
// bounding box, centred, beam along +j, lateral along +i.
probe::Pose top_centre_pose(const tissue::VolumeGeometry& g);

// A loaded volume with its transfer function bound to it.
struct VolumeSource {
    tissue::LoadedVolume loaded;
    std::unique_ptr<tissue::TransferFunction> tf;
    bool is_default = false;  // the embedded Colin27 head
    float outside = 0.0f;     // value assumed outside the volume
    float value_min = 0.0f, value_max = 0.0f;

    // Resamples the volume on `grid` (trilinear, or nearest for label maps).
    tissue::Volume resample(const tissue::VolumeGeometry& grid) const;
    // The acoustic properties on `grid` (and its tissue labels, on request), with the
    // membranes the embedded head's MRI cannot show (imaging::add_colin27_membranes).
    tissue::PropertyMaps plane_properties(const tissue::VolumeGeometry& grid,
                                          tissue::Volume* labels) const;
};

// Validates the volume options (--volume, --spacing, --tf, --outside), loads the volume
// and binds the transfer function.
VolumeSource load_volume_source(const SliceOptions& options, StageTimer& timer);

// A pose in a sidecar: its text form and its axes in world coordinates.
nlohmann::json pose_json(const probe::Pose& pose);

// The volume-related part of a sidecar.
nlohmann::json volume_source_json(const VolumeSource& source, const SliceOptions& options);

struct Slice {
    tissue::LoadedVolume loaded;
    std::unique_ptr<tissue::TransferFunction> tf;
    probe::Pose pose;
    tissue::GridExtent extent;
    tissue::VolumeGeometry grid;
    float outside = 0.0f;
    float value_min = 0.0f, value_max = 0.0f;
    tissue::Volume values;      // resampled voxel values
    tissue::PropertyMaps maps;  // acoustic properties on the grid
};

// Validates every option, then loads, slices and classifies (timed stages on `timer`).
Slice make_slice(const SliceOptions& options, StageTimer& timer);

// The sidecar description of a slice (volume, transfer function, pose, grid).
nlohmann::json slice_json(const Slice& slice, const SliceOptions& options);

}  // namespace sonotrace::ui
