#include "ui/cli/volume_slice.h"

#include <cmath>
#include <iostream>

#include "imaging/colin27.h"
#include "imaging/simulation.h"
#include "phantoms/scene/request.h"
#include "tissue/base/error.h"
#include "tissue/base/memory.h"

namespace sonotrace::ui {

namespace {

using nlohmann::json;

// Parameters of the volume slice, documented once (shared by tissue and trace).
constexpr ParameterDoc kWidthDoc = {"--width", "mm",
                                    "lateral extent of the slice, centred on the probe; 0 = "
                                    "automatic (140 mm for the default volume, else the volume's "
                                    "extent)"};
constexpr ParameterDoc kDepthDoc = {"--depth", "mm",
                                    "depth of the slice from the probe face; 0 = automatic "
                                    "(160 mm for the default volume, else the volume's extent)"};
constexpr ParameterDoc kResolutionDoc = {"--resolution", "mm/pixel",
                                         "sample spacing of the slice, independent of the voxel "
                                         "size (trilinear interpolation)"};
constexpr ParameterDoc kElevationDoc = {
    "--elevation", "mm",
    "thickness of a 3D sub-volume around the image plane (for 3D tracing); 0 = a single plane. "
    "Pictures show the central plane; --nifti writes the whole sub-volume"};
// The volume options are frame parameters: their rows of the request's table.
template <typename T>
void add_request_option(CLI::App& cmd, const char* key, T& variable) {
    const scene::RequestParameter& row = scene::request_parameter(key);
    cmd.add_option("--" + row.key, variable, row.help())->capture_default_str();
}

}  // namespace

void add_volume_options(CLI::App& cmd, SliceOptions& options) {
    add_request_option(cmd, "volume", options.volume);
    add_request_option(cmd, "spacing", options.spacing);
    add_request_option(cmd, "tf", options.tf);
    add_request_option(cmd, "pose", options.pose);
    add_request_option(cmd, "outside", options.outside);
}

void add_slice_options(CLI::App& cmd, SliceOptions& options, bool with_elevation) {
    add_request_option(cmd, "volume", options.volume);
    add_request_option(cmd, "spacing", options.spacing);
    add_request_option(cmd, "tf", options.tf);
    add_request_option(cmd, "pose", options.pose);
    add_parameter(cmd, kWidthDoc, options.width_mm);
    add_parameter(cmd, kDepthDoc, options.depth_mm);
    add_parameter(cmd, kResolutionDoc, options.resolution_mm);
    if (with_elevation) add_parameter(cmd, kElevationDoc, options.elevation_mm);
    add_request_option(cmd, "outside", options.outside);
}

Slice make_slice(const SliceOptions& options, StageTimer& timer) {
    // ---- validate every parameter before loading anything heavy ----
    auto nonnegative = [](double v, const char* flag) {
        if (!(std::isfinite(v) && v >= 0.0)) {
            throw base::InputError(
                flag, "", "must be a finite number >= 0 (mm), got " + base::number_text(v));
        }
    };
    nonnegative(options.width_mm, "--width");
    nonnegative(options.depth_mm, "--depth");
    nonnegative(options.elevation_mm, "--elevation");
    if (!(std::isfinite(options.resolution_mm) && options.resolution_mm > 0.0)) {
        throw base::InputError("--resolution", "", "must be a positive number of mm per pixel");
    }
    std::optional<probe::Pose> pose;
    if (options.pose != "default") pose = probe::parse_pose(options.pose, "--pose");

    scene::VolumeSource source = scene::load_volume_source(options, &timer);
    const tissue::Volume& volume = source.loaded.volume;

    // ---- grid under the probe ----
    if (!pose)
        pose =
            source.is_default ? probe::colin27_temporal_pose() : scene::default_volume_pose(source);
    tissue::GridExtent extent;
    const glm::dvec3 size_mm = glm::dvec3(volume.dims()) * volume.geometry().spacing;
    extent.width_mm =
        options.width_mm > 0 ? options.width_mm : (source.is_default ? 140.0 : size_mm.x);
    // The default pose of an anatomical volume looks down its world z (the vertex).
    const double default_depth_mm = source.is_default          ? 160.0
                                    : source.loaded.anatomical ? size_mm.z
                                                               : size_mm.y;
    extent.depth_mm = options.depth_mm > 0 ? options.depth_mm : default_depth_mm;
    extent.elevation_mm = options.elevation_mm;
    extent.pixel_mm = options.resolution_mm;
    const tissue::VolumeGeometry grid =
        tissue::probe_grid(pose->frame(), extent, "--width/--depth/--resolution");

    Slice slice;
    timer.begin("resampling " + std::to_string(grid.dims.x) + "x" + std::to_string(grid.dims.y) +
                "x" + std::to_string(grid.dims.z) + " samples");
    slice.values = source.resample(grid);
    timer.end();
    timer.begin("classifying");
    slice.maps = tissue::classify(slice.values, *source.tf);
    timer.end();
    slice.source = std::move(source);
    slice.pose = *pose;
    slice.extent = extent;
    slice.grid = grid;
    return slice;
}

json slice_json(const Slice& slice, const SliceOptions& options) {
    json record = volume_source_json(slice.source, options);
    record["pose"] = pose_json(slice.pose);
    record["grid"] = {
        {"geometry", geometry_json(slice.grid)},
        {"width_mm", slice.extent.width_mm},
        {"depth_mm", slice.extent.depth_mm},
        {"elevation_mm", slice.extent.elevation_mm},
        {"pixel_mm", slice.extent.pixel_mm},
        {"interpolation", slice.source.tf->uses_nearest_sampling() ? "nearest" : "trilinear"},
        {"axes", "i = lateral, j = depth (axial), k = elevation"}};
    return record;
}

}  // namespace sonotrace::ui
