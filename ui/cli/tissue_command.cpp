#include "ui/cli/tissue_command.h"

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <limits>
#include <sstream>

#include <tbb/parallel_for.h>

#include "imaging/picture.h"
#include "probe/pose.h"
#include "sonotrace_version.h"
#include "tissue/acoustic_map.h"
#include "tissue/atomic_output.h"
#include "tissue/error.h"
#include "tissue/memory.h"
#include "tissue/nifti_io.h"
#include "tissue/property_maps.h"
#include "tissue/resample.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"

namespace sonotrace::ui {

namespace {

using nlohmann::json;
using tissue::Property;

// Parameters of `sonotrace tissue`, documented once.
constexpr ParameterDoc kVolumeDoc = {
    "--volume", "",
    "volume to load: 'default' (Colin27 T1 head MRI from mricron-data), a NIfTI file "
    "(.nii/.nii.gz), a raw sidecar (.json), an image (PNG/TIFF/JPEG/EXR), a directory of "
    "numbered images or a printf pattern (img_%03d.png)"};
constexpr ParameterDoc kSpacingDoc = {
    "--spacing", "mm",
    "pixel spacing of image inputs as 'SX,SY' or 'SX,SY,SZ' (SZ = slice spacing of a stack); "
    "required for images, ignored for NIfTI and raw volumes"};
constexpr ParameterDoc kTfDoc = {
    "--tf", "",
    "transfer function: a preset name (mri-t1-head, generic-soft-tissue) or a JSON file; "
    "empty = mri-t1-head for the default volume, generic-soft-tissue otherwise"};
constexpr ParameterDoc kPoseDoc = {"--pose", "mm, degrees", probe::kPoseHelp};
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
constexpr ParameterDoc kOutsideDoc = {"--outside", "volume units",
                                      "value assumed outside the volume; default: the volume's "
                                      "minimum (air for MRI)"};
constexpr ParameterDoc kOutDoc = {"--out", "", "output directory"};
constexpr ParameterDoc kJsonDoc = {"--json", "",
                                   "also write the run record (parameters, outputs, timings) to "
                                   "this file; '-' prints it on stdout"};
constexpr ParameterDoc kThreadsDoc = {"--threads", "", "worker threads; 0 = all cores"};

struct FieldOutput {
    std::string key;
    imaging::FieldStyle style;
    tissue::Volume field;
};

json geometry_json(const tissue::VolumeGeometry& g) {
    json direction = json::array();
    for (int c = 0; c < 3; ++c)
        direction.push_back({g.direction[c].x, g.direction[c].y, g.direction[c].z});
    return {{"dims", {g.dims.x, g.dims.y, g.dims.z}},
            {"spacing_mm", {g.spacing.x, g.spacing.y, g.spacing.z}},
            {"origin_mm", {g.origin.x, g.origin.y, g.origin.z}},
            {"direction", direction}};
}

tissue::Volume central_plane(const tissue::Volume& v) {
    if (v.is_2d()) return v;
    tissue::VolumeGeometry g = v.geometry();
    const int k = g.dims.z / 2;
    g.origin = g.index_to_world({0.0, 0.0, double(k)});
    g.dims.z = 1;
    tissue::Volume plane(g);
    for (int j = 0; j < g.dims.y; ++j) {
        for (int i = 0; i < g.dims.x; ++i) plane.at(i, j) = v.at(i, j, k);
    }
    return plane;
}

// Default pose for a non-default volume: on the top face of the bounding box, centred,
// beam along +j (image rows run downwards), lateral along +i.
probe::Pose top_centre_pose(const tissue::VolumeGeometry& g) {
    const glm::dvec3 centre = glm::dvec3(g.dims - 1) * 0.5;
    const glm::dvec3 top = g.index_to_world({centre.x, -0.5, centre.z});
    return probe::Pose::looking(top, g.direction[1], g.direction[0]);
}

}  // namespace

std::string tissue_tables_markdown() {
    std::ostringstream out;
    out << "| property | unit | range | meaning |\n|---|---|---|---|\n";
    for (const auto& p : tissue::kPropertyInfo) {
        out << "| `" << p.key << "` | " << p.unit << " | " << p.min << " .. " << p.max << " | "
            << p.description << " |\n";
    }
    out << "\n| tissue |";
    for (const auto& p : tissue::kPropertyInfo) out << " " << p.key << " |";
    out << " Z [MRayl] | source |\n|---|";
    for (std::size_t n = 0; n <= tissue::kPropertyCount; ++n) out << "---|";
    out << "---|\n";
    for (const auto& t : tissue::tissue_table()) {
        out << "| `" << t.key << "` |";
        for (float v : t.properties.values) out << " " << v << " |";
        out << " " << std::setprecision(3) << t.properties.impedance_mrayl() << std::setprecision(6)
            << " | " << t.source << " |\n";
    }
    return out.str();
}

CLI::App* add_tissue_command(CLI::App& app, TissueOptions& options) {
    CLI::App* cmd = app.add_subcommand(
        "tissue",
        "Show what the simulator will see: slice a volume under the probe pose, apply the "
        "transfer function and write the slice and every acoustic field as colour-mapped PNGs "
        "with a JSON sidecar (tissue.json).");
    add_parameter(*cmd, kVolumeDoc, options.volume);
    add_parameter(*cmd, kSpacingDoc, options.spacing);
    add_parameter(*cmd, kTfDoc, options.tf);
    add_parameter(*cmd, kPoseDoc, options.pose);
    add_parameter(*cmd, kWidthDoc, options.width_mm);
    add_parameter(*cmd, kDepthDoc, options.depth_mm);
    add_parameter(*cmd, kResolutionDoc, options.resolution_mm);
    add_parameter(*cmd, kElevationDoc, options.elevation_mm);
    add_parameter(*cmd, kOutsideDoc, options.outside);
    add_parameter(*cmd, kOutDoc, options.out_dir);
    add_parameter(*cmd, kJsonDoc, options.json_path);
    add_parameter(*cmd, kThreadsDoc, options.threads)->check(CLI::Range(0, 1024));
    cmd->add_flag("--nifti", options.write_nifti,
                  "also write every field as float NIfTI (.nii.gz) with the grid's geometry");
    cmd->add_flag("--list-tissues", options.list_tissues,
                  "print the acoustic properties (units, ranges) and the tissue table (literature "
                  "values) as Markdown and exit");
    cmd->add_flag("-q,--quiet", options.quiet, "no progress lines on stderr");
    return cmd;
}

int run_tissue_command(const TissueOptions& options) {
    if (options.list_tissues) {
        std::cout << tissue_tables_markdown();
        return 0;
    }

    StageTimer timer(options.quiet);
    const auto thread_limit = limit_threads(options.threads);
    const bool is_default = options.volume == tissue::kDefaultVolumeName;

    // ---- validate every parameter before loading anything heavy ----
    tissue::VolumeRequest request{options.volume, std::nullopt};
    if (!options.spacing.empty()) {
        double s[3];
        if (auto error = parse_spacing(options.spacing, s))
            throw tissue::InputError("--spacing", "", *error);
        request.image_spacing = glm::dvec3(s[0], s[1], s[2]);
    }
    auto nonnegative = [](double v, const char* flag) {
        if (!(std::isfinite(v) && v >= 0.0)) {
            throw tissue::InputError(flag, "",
                                     "must be a finite number >= 0 (mm), got " + std::to_string(v));
        }
    };
    nonnegative(options.width_mm, "--width");
    nonnegative(options.depth_mm, "--depth");
    nonnegative(options.elevation_mm, "--elevation");
    if (!(std::isfinite(options.resolution_mm) && options.resolution_mm > 0.0)) {
        throw tissue::InputError("--resolution", "", "must be a positive number of mm per pixel");
    }
    if (!std::isnan(options.outside) && !std::isfinite(options.outside)) {
        throw tissue::InputError("--outside", "", "must be finite");
    }
    std::optional<probe::Pose> pose;
    if (options.pose != "default") pose = probe::parse_pose(options.pose, "--pose");
    const std::string tf_spec =
        !options.tf.empty() ? options.tf : (is_default ? "mri-t1-head" : "generic-soft-tissue");
    timer.begin("transfer function " + tf_spec);
    auto tf = tissue::load_transfer_function(tf_spec);
    timer.end();

    // ---- load ----
    timer.begin("loading " + options.volume);
    tissue::LoadedVolume loaded = tissue::load_volume(request);
    timer.end();
    for (const auto& w : loaded.warnings) std::cerr << "sonotrace: warning: " << w << "\n";
    const tissue::Volume& volume = loaded.volume;
    const auto [vmin, vmax] = volume.value_range();
    const float outside = std::isnan(options.outside) ? vmin : float(options.outside);

    // ---- grid under the probe ----
    if (!pose)
        pose = is_default ? probe::colin27_temporal_pose() : top_centre_pose(volume.geometry());
    tissue::GridExtent extent;
    const glm::dvec3 size_mm = glm::dvec3(volume.dims()) * volume.geometry().spacing;
    extent.width_mm = options.width_mm > 0 ? options.width_mm : (is_default ? 140.0 : size_mm.x);
    extent.depth_mm = options.depth_mm > 0 ? options.depth_mm : (is_default ? 160.0 : size_mm.y);
    extent.elevation_mm = options.elevation_mm;
    extent.pixel_mm = options.resolution_mm;
    const tissue::VolumeGeometry grid =
        tissue::probe_grid(pose->frame(), extent, "--width/--depth/--resolution");
    tissue::check_allocation(double(grid.voxel_count()) * 4.0 * 24.0, "--resolution",
                             "grid of " + std::to_string(grid.voxel_count()) + " samples");

    timer.begin("binding the transfer function to the volume");
    tf->bind(volume);
    timer.end();
    timer.begin("resampling " + std::to_string(grid.dims.x) + "x" + std::to_string(grid.dims.y) +
                "x" + std::to_string(grid.dims.z) + " samples");
    const auto interpolation = tf->uses_nearest_sampling() ? tissue::Interpolation::nearest
                                                           : tissue::Interpolation::trilinear;
    const tissue::Volume values = tissue::resample(volume, grid, interpolation, outside);
    timer.end();
    timer.begin("classifying");
    const tissue::PropertyMaps maps = tissue::classify(values, *tf);
    timer.end();
    timer.begin("acoustic map and gradients");
    tissue::Volume grad_n(grid), grad_z(grid);
    auto store_gradients = [&](const auto& map) {
        for (int k = 0; k < grid.dims.z; ++k) {
            for (int j = 0; j < grid.dims.y; ++j) {
                for (int i = 0; i < grid.dims.x; ++i) {
                    const auto& t =
                        map.texel(typename std::decay_t<decltype(map)>::IVec(glm::ivec3(i, j, k)));
                    double gn = 0.0, gz = 0.0;
                    for (int a = 0; a < int(std::size(t.grad_impedance)); ++a) {
                        gn += double(t.grad_refractive_index[a]) * t.grad_refractive_index[a];
                        gz += double(t.grad_impedance[a]) * t.grad_impedance[a];
                    }
                    grad_n.at(i, j, k) = float(std::sqrt(gn));
                    grad_z.at(i, j, k) = float(std::sqrt(gz));
                }
            }
        }
    };
    if (grid.dims.z == 1)
        store_gradients(tissue::AcousticMap<2>::build(maps));
    else
        store_gradients(tissue::AcousticMap<3>::build(maps));
    timer.end();

    // ---- pictures ----
    timer.begin("writing pictures");
    std::vector<FieldOutput> fields;
    const double px = extent.pixel_mm;
    fields.push_back({"slice",
                      {"intensity", "volume units", imaging::Colormap::gray,
                       std::pair<double, double>(vmin, vmax), false, px},
                      values});
    const imaging::Colormap maps_cmap[] = {imaging::Colormap::turbo,   imaging::Colormap::viridis,
                                           imaging::Colormap::inferno, imaging::Colormap::bone,
                                           imaging::Colormap::magma,   imaging::Colormap::cividis};
    for (std::size_t n = 0; n < tissue::kPropertyCount; ++n) {
        const auto& info = tissue::kPropertyInfo[n];
        fields.push_back({std::string(info.key),
                          {std::string(info.label), std::string(info.unit), maps_cmap[n],
                           std::nullopt, false, px},
                          maps.fields[n]});
        if (n == 1) {
            fields.push_back({"impedance",
                              {"impedance Z", std::string(tissue::kImpedanceUnit),
                               imaging::Colormap::viridis, std::nullopt, false, px},
                              maps.impedance()});
        }
    }
    fields.push_back({"impedance_gradient",
                      {"|grad Z|", "MRayl/mm", imaging::Colormap::inferno, std::nullopt, true, px},
                      grad_z});
    fields.push_back({"refractive_index_gradient",
                      {"|grad n|", "1/mm", imaging::Colormap::inferno, std::nullopt, true, px},
                      grad_n});

    // Stage every path first (the transaction is not thread-safe), then render and encode
    // the pictures in parallel; each task writes only its own files.
    tissue::OutputTransaction transaction;
    json outputs = json::array();
    std::vector<std::string> png_staged(fields.size()), nii_staged(fields.size());
    for (std::size_t n = 0; n < fields.size(); ++n) {
        const FieldOutput& f = fields[n];
        const std::filesystem::path stem = std::filesystem::path(options.out_dir) / f.key;
        const auto [lo, hi] = f.field.value_range();
        json entry = {{"field", f.key},
                      {"unit", f.style.unit},
                      {"png", stem.string() + ".png"},
                      {"min", lo},
                      {"max", hi}};
        png_staged[n] = transaction.stage(stem.string() + ".png");
        if (options.write_nifti) {
            nii_staged[n] = transaction.stage(stem.string() + ".nii.gz");
            entry["nifti"] = stem.string() + ".nii.gz";
        }
        outputs.push_back(entry);
    }
    std::vector<cv::Mat> panels(fields.size());
    tbb::parallel_for(std::size_t(0), fields.size(), [&](std::size_t n) {
        panels[n] = imaging::render_field(central_plane(fields[n].field), fields[n].style);
        imaging::write_png(panels[n], png_staged[n]);
        if (options.write_nifti) tissue::write_nifti(fields[n].field, nii_staged[n]);
    });
    const std::string overview = (std::filesystem::path(options.out_dir) / "overview.png").string();
    imaging::write_png(imaging::montage(panels, 4), transaction.stage(overview));
    timer.end();

    // ---- sidecar ----
    const auto& vg = volume.geometry();
    json record = {
        {"command", "tissue"},
        {"software", {{"name", "sonotrace"}, {"version", SONOTRACE_VERSION}}},
        {"volume",
         {{"spec", options.volume},
          {"path", loaded.path},
          {"format", loaded.format},
          {"geometry", geometry_json(vg)},
          {"value_range", {vmin, vmax}},
          {"outside_value", outside}}},
        {"transfer_function", tf->describe()},
        {"pose",
         {{"text", pose->to_string()},
          {"position_mm", {pose->position.x, pose->position.y, pose->position.z}},
          {"lateral", {pose->lateral().x, pose->lateral().y, pose->lateral().z}},
          {"axial", {pose->axial().x, pose->axial().y, pose->axial().z}},
          {"elevation", {pose->elevation().x, pose->elevation().y, pose->elevation().z}}}},
        {"grid",
         {{"geometry", geometry_json(grid)},
          {"width_mm", extent.width_mm},
          {"depth_mm", extent.depth_mm},
          {"elevation_mm", extent.elevation_mm},
          {"pixel_mm", extent.pixel_mm},
          {"interpolation", tf->uses_nearest_sampling() ? "nearest" : "trilinear"},
          {"axes", "i = lateral, j = depth (axial), k = elevation"}}},
        {"outputs", outputs},
        {"overview", overview},
        {"warnings", loaded.warnings},
        {"timings_s", timer.timings()},
    };
    const std::string sidecar = (std::filesystem::path(options.out_dir) / "tissue.json").string();
    write_json(record, transaction.stage(sidecar));
    if (!options.json_path.empty() && options.json_path != "-") {
        write_json(record, transaction.stage(options.json_path));
    }
    transaction.commit();
    if (options.json_path == "-") write_json(record, "-");
    if (!options.quiet) {
        std::cerr << "sonotrace: wrote " << outputs.size() + 1 << " pictures and tissue.json to "
                  << options.out_dir << " (overview: " << overview << ")\n";
    }
    return 0;
}

}  // namespace sonotrace::ui
