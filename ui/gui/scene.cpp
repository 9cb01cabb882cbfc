#include "ui/gui/scene.h"

#include <algorithm>
#include <filesystem>
#include <set>

#include "imaging/colin27.h"
#include "phantoms/phantom.h"
#include "probe/placement.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"
#include "tissue/property_maps.h"
#include "tissue/tissue_table.h"
#include "ui/cli/volume_slice.h"

namespace sonotrace::gui {

namespace {

bool ends_with(const std::string& s, const std::string& tail) {
    return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// The table's properties of the tissue labels present.
std::vector<tissue::AcousticProperties> materials_of_labels(const std::set<int>& labels) {
    std::vector<tissue::AcousticProperties> out;
    const auto table = tissue::tissue_table();
    for (int l : labels)
        if (l >= 1 && l <= int(table.size())) out.push_back(table[std::size_t(l) - 1].properties);
    return out;
}

std::shared_ptr<Scene> volume_scene(const std::string& spec, const std::string& view) {
    auto scene = std::make_shared<Scene>();
    ui::SliceOptions options;
    options.volume = spec;
    ui::StageTimer quiet(true);
    auto source = std::make_shared<ui::VolumeSource>(ui::load_volume_source(options, quiet));
    const tissue::Volume& volume = source->loaded.volume;
    const tissue::VolumeGeometry& g = volume.geometry();
    const glm::dvec3 corners[2] = {g.index_to_world(glm::dvec3(0.0)),
                                   g.index_to_world(glm::dvec3(g.dims - 1))};
    scene->box_low = glm::min(corners[0], corners[1]);
    scene->box_high = glm::max(corners[0], corners[1]);
    scene->interface_reach_mm = 3.0 * std::max({g.spacing.x, g.spacing.y, g.spacing.z});
    scene->mapper = [source](const tissue::VolumeGeometry& grid, tissue::Volume* labels) {
        return source->plane_properties(grid, labels);
    };
    const tissue::TransferFunction& tf = *source->tf;
    if (source->is_default) {
        scene->start = view == "temporal" ? imaging::temporal_scene(volume, tf)
                                          : imaging::craniotomy_scene(volume, tf);
        scene->probe_preset = view == "temporal" ? "phased" : "convex";
        scene->name = "head-" + view;
        scene->title = view == "temporal" ? "Colin27 head: transtemporal (phased probe)"
                                          : "Colin27 head: intraoperative (convex probe)";
        scene->context_tf = imaging::pbvr::load_colour_tf("head");
        scene->context_zoom = 1.3;
    } else {
        scene->start.pose = ui::top_centre_pose(g);
        scene->start.description = "probe on the top face of " + spec;
        scene->probe_preset = "linear";
        scene->name = spec;
        scene->title = std::filesystem::path(spec).filename().string();
        scene->context_tf = imaging::pbvr::load_colour_tf("ramp");
    }
    scene->description = scene->start.description;
    // Laid back on the surface along the beam: the cortex under the craniotomy (skull
    // and CSF, then brain), else the skin.
    const bool cortex = scene->start.craniotomy_radius_mm > 0.0;
    scene->settle = [source, cortex](const probe::Pose& pose) {
        const tissue::Volume& v = source->loaded.volume;
        const tissue::TransferFunction& f = *source->tf;
        const glm::dvec3 beam = pose.axial();
        const glm::dvec3 outside = pose.position - 60.0 * beam;
        const float background = source->outside;  // no scan of the volume per move
        std::optional<probe::RayHit> hit =
            probe::skin_surface(v, f, outside, beam, 100.0, 0.5, background);
        if (hit && cortex) {
            const int brain = tissue::tissue_label_of("brain"),
                      csf = tissue::tissue_label_of("csf"),
                      bone = tissue::tissue_label_of("cortical_bone");
            hit = probe::after_gap(
                v, f, hit->point + beam, beam, 60.0,
                [&](const tissue::AcousticProperties&, int l) { return l == csf || l == bone; },
                2.0, [&](const tissue::AcousticProperties&, int l) { return l == brain; }, 3.0,
                background);
        }
        probe::Pose out = pose;
        // As craniotomy_scene: the face 0.5 mm into the cortex, in full contact.
        if (hit) out.position = hit->point + (cortex ? 0.5 : 0.0) * beam;
        return out;
    };
    // The tissues present: the labels of every 7th voxel (no label volume needed).
    std::set<int> labels;
    for (std::size_t n = 0; n < volume.size(); n += 7)
        labels.insert(tf.tissue_label(volume.voxels()[n]));
    if (source->is_default) {  // the membranes placed by anatomy
        labels.insert(tissue::tissue_label_of("dura"));
        labels.insert(tissue::tissue_label_of("choroid_plexus"));
    }
    scene->materials = materials_of_labels(labels);
    auto context = std::make_shared<tissue::Volume>(volume);
    scene->context_tf.bind(*context);
    scene->context = std::move(context);
    return scene;
}

std::shared_ptr<Scene> phantom_scene(const std::string& path) {
    auto phantom = std::make_shared<phantoms::Phantom>(phantoms::load_phantom(path));
    auto scene = std::make_shared<Scene>();
    scene->name = path;
    scene->title = "phantom: " + phantom->name;
    scene->description = phantom->description;
    scene->start.pose = phantom->pose;
    scene->start.description = "phantom " + phantom->name;
    scene->probe_preset = phantom->probe_preset.empty() ? "linear" : phantom->probe_preset;
    scene->interface_reach_mm = std::max(2.0 * phantom->smoothing_mm, 1.0);
    scene->box_low = glm::dvec3(0.0);
    scene->box_high = phantom->size;
    scene->mapper = [phantom](const tissue::VolumeGeometry& grid, tissue::Volume* labels) {
        return phantoms::rasterise(*phantom, grid, labels);
    };
    // A phantom's top face is flat: a moved probe stays at its depth.
    scene->settle = [](const probe::Pose& pose) { return pose; };
    scene->materials.push_back(phantom->background);
    for (const phantoms::Shape& s : phantom->shapes) scene->materials.push_back(s.properties);
    // The 3D context: acoustic impedance on a 1 mm grid (at most 160 samples a side).
    const double h =
        std::max({1.0, phantom->size.x / 160.0, phantom->size.y / 160.0, phantom->size.z / 160.0});
    tissue::VolumeGeometry grid;
    grid.dims = glm::max(glm::ivec3(phantom->size / h) + 1, glm::ivec3(2));
    grid.spacing = glm::dvec3(h);
    const tissue::PropertyMaps maps = phantoms::rasterise(*phantom, grid);
    auto impedance = std::make_shared<tissue::Volume>(grid);
    const auto& rho = maps[tissue::Property::density].voxels();
    const auto& c = maps[tissue::Property::speed_of_sound].voxels();
    for (std::size_t n = 0; n < impedance->size(); ++n)
        impedance->voxels()[n] = rho[n] * c[n] * 1e-6f;  // MRayl
    scene->context_tf = imaging::pbvr::load_colour_tf("ramp");
    scene->context_tf.bind(*impedance);
    scene->context = std::move(impedance);
    return scene;
}

}  // namespace

std::vector<SceneEntry> scene_catalogue(const std::string& phantom_dir) {
    std::vector<SceneEntry> out = {
        {"head-craniotomy", "Colin27 head: intraoperative (convex probe)"},
        {"head-temporal", "Colin27 head: transtemporal (phased probe)"},
    };
    std::vector<std::string> names;
    std::error_code error;
    for (const auto& entry : std::filesystem::directory_iterator(phantom_dir, error)) {
        if (entry.path().extension() == ".json") names.push_back(entry.path().stem().string());
    }
    std::sort(names.begin(), names.end());
    for (const std::string& n : names) out.push_back({"phantom:" + n, "phantom: " + n});
    return out;
}

std::shared_ptr<const Scene> load_scene(const std::string& spec, const std::string& phantom_dir) {
    if (spec == "head-craniotomy" || spec == "head" || spec == "default")
        return volume_scene(tissue::kDefaultVolumeName, "craniotomy");
    if (spec == "head-temporal") return volume_scene(tissue::kDefaultVolumeName, "temporal");
    if (spec.rfind("phantom:", 0) == 0) {
        const std::string name = spec.substr(8);
        const std::string path = phantom_dir + "/" + name + ".json";
        if (name.empty() || name.find('/') != std::string::npos || !std::filesystem::exists(path))
            throw base::InputError(spec, "", "no phantom of that name in " + phantom_dir);
        return phantom_scene(path);
    }
    if (!std::filesystem::exists(spec))
        throw base::InputError(spec, "",
                               "no such file (scenes: head-craniotomy, head-temporal, "
                               "phantom:NAME, or a volume or phantom file)");
    if (ends_with(spec, ".json")) {
        // A phantom, unless it is a raw volume's header (which names its data file).
        const nlohmann::json j = base::jsonio::read_file(spec);
        if (j.is_object() && j.contains("shapes")) return phantom_scene(spec);
    }
    return volume_scene(spec, "");
}

probe::Pose clamp_to_scene(const Scene& scene, const probe::Pose& pose) {
    probe::Pose out = pose;
    out.position = glm::clamp(pose.position, scene.box_low, scene.box_high);
    return out;
}

}  // namespace sonotrace::gui
