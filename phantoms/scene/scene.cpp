#include "phantoms/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <set>

#include "imaging/colin27.h"
#include "imaging/sulcal_membranes.h"
#include "probe/placement.h"
#include "tissue/base/error.h"
#include "tissue/base/memory.h"
#include "tissue/base/number_list.h"
#include "tissue/property_maps.h"
#include "tissue/resample.h"
#include "tissue/tissue_table.h"

namespace sonotrace::scene {

namespace {

// A stage reported to the observer, if any, for the lifetime of this object.
class Stage {
  public:
    Stage(StageObserver* stages, const std::string& name) : stages_(stages) {
        if (stages_) stages_->begin(name);
    }
    ~Stage() {
        if (stages_) stages_->end();
    }
    Stage(const Stage&) = delete;
    Stage& operator=(const Stage&) = delete;

  private:
    StageObserver* stages_;
};

std::shared_ptr<Scene> volume_scene(std::shared_ptr<const VolumeSource> source,
                                    const SceneOptions& options, StageObserver* stages) {
    auto scene = std::make_shared<Scene>();
    const tissue::Volume& volume = source->loaded.volume;
    const tissue::VolumeGeometry& g = volume.geometry();
    // The interfaces of a resampled volume blend over about a voxel either side.
    scene->interface_reach_mm = 3.0 * std::max({g.spacing.x, g.spacing.y, g.spacing.z});
    const bool temporal = options.view == "temporal";
    // Over a craniotomy the scalp is turned back; the view keeps the MRI's values there
    // (CSF- and brain-like, near the saline a surgeon fills the window with).
    const bool craniotomy = source->is_default && !options.pose && !temporal;
    scene->mapper = [source, craniotomy](const tissue::VolumeGeometry& grid,
                                         tissue::Volume* labels) {
        return source->plane_properties(grid, labels, craniotomy);
    };
    if (source->is_default) {
        scene->name = temporal ? "head-temporal" : "head-craniotomy";
        scene->title = temporal ? "Colin27 head: transtemporal (phased probe)"
                                : "Colin27 head: intraoperative (convex probe)";
        scene->probe_preset = temporal ? "phased" : "convex";
        if (temporal) scene->gain_db = kTemporalGainDb;
    } else {
        scene->name = options.volume;
        scene->title = std::filesystem::path(options.volume).filename().string();
        scene->probe_preset = "linear";
    }
    {
        const Stage stage(stages, "placing the probe (" + options.view + ")");
        if (options.pose) {
            scene->start.pose = *options.pose;
            scene->start.description = "probe at --pose";
        } else if (source->is_default) {
            scene->start = temporal ? imaging::temporal_scene(volume, *source->tf)
                                    : imaging::craniotomy_scene(volume, *source->tf);
        } else {
            scene->start.pose = default_volume_pose(*source);
            scene->start.description =
                source->loaded.anatomical
                    ? "probe on the superior surface, looking down (coronal plane)"
                    : "probe on the top face of the volume";
        }
    }
    scene->description = scene->start.description;
    scene->volume = std::move(source);
    return scene;
}

}  // namespace

probe::Pose top_centre_pose(const tissue::VolumeGeometry& g) {
    const glm::dvec3 centre = glm::dvec3(g.dims - 1) * 0.5;
    const glm::dvec3 top = g.index_to_world({centre.x, -0.5, centre.z});
    return probe::Pose::looking(top, g.direction[1], g.direction[0]);
}

probe::Pose default_volume_pose(const VolumeSource& source) {
    const tissue::Volume& v = source.loaded.volume;
    const tissue::VolumeGeometry& g = v.geometry();
    if (!source.loaded.anatomical) return top_centre_pose(g);
    glm::dvec3 low(std::numeric_limits<double>::max()), high(-std::numeric_limits<double>::max());
    for (int corner = 0; corner < 8; ++corner) {
        const glm::dvec3 ijk((corner & 1) ? g.dims.x - 1 : 0, (corner & 2) ? g.dims.y - 1 : 0,
                             (corner & 4) ? g.dims.z - 1 : 0);
        low = glm::min(low, g.index_to_world(ijk));
        high = glm::max(high, g.index_to_world(ijk));
    }
    const glm::dvec3 inferior(0.0, 0.0, -1.0), right(1.0, 0.0, 0.0);
    const glm::dvec3 above(0.5 * (low.x + high.x), 0.5 * (low.y + high.y), high.z);
    probe::Pose pose = probe::Pose::looking(above, inferior, right);
    if (const auto hit = probe::skin_surface(v, *source.tf, above, inferior, high.z - low.z, 0.5,
                                             source.outside))
        pose.position = hit->point;
    return pose;
}

VolumeSource load_volume_source(const VolumeOptions& options, StageObserver* stages) {
    VolumeSource source;
    source.is_default = options.volume == tissue::kDefaultVolumeName;
    tissue::VolumeRequest request{options.volume, std::nullopt};
    if (!options.spacing.empty()) {
        double s[3];
        if (auto error = base::parse_spacing(options.spacing, s))
            throw base::InputError("--spacing", "", *error);
        request.image_spacing = glm::dvec3(s[0], s[1], s[2]);
    }
    if (!std::isnan(options.outside) && !std::isfinite(options.outside)) {
        throw base::InputError("--outside", "", "must be finite");
    }
    // A transfer function asked for is read before the volume (its errors come first);
    // the default depends on what the volume is: the head's, CT's Hounsfield units for a
    // CT series, else the generic one.
    if (!options.tf.empty()) {
        const Stage stage(stages, "transfer function " + options.tf);
        source.tf = tissue::load_transfer_function(options.tf);
    }
    {
        const Stage stage(stages, "loading " + options.volume);
        source.loaded = tissue::load_volume(request);
    }
    if (!source.tf) {
        const std::string tf_spec = source.is_default                ? "mri-t1-head"
                                    : source.loaded.modality == "CT" ? "ct-hounsfield"
                                                                     : "generic-soft-tissue";
        const Stage stage(stages, "transfer function " + tf_spec);
        source.tf = tissue::load_transfer_function(tf_spec);
    }
    for (const auto& w : source.loaded.warnings) std::cerr << "sonotrace: warning: " << w << "\n";
    const auto [vmin, vmax] = source.loaded.volume.value_range();
    source.outside = std::isnan(options.outside) ? vmin : float(options.outside);
    source.value_min = vmin;
    source.value_max = vmax;
    {
        const Stage stage(stages, "binding the transfer function to the volume");
        source.tf->bind(source.loaded.volume);
    }
    return source;
}

tissue::Volume VolumeSource::resample(const tissue::VolumeGeometry& grid) const {
    base::check_allocation(double(grid.voxel_count()) * 4.0 * 24.0, "--resolution",
                           "grid of " + std::to_string(grid.voxel_count()) + " samples");
    const auto interpolation = tf->uses_nearest_sampling() ? tissue::Interpolation::nearest
                                                           : tissue::Interpolation::trilinear;
    return tissue::resample(loaded.volume, grid, interpolation, outside);
}

tissue::PropertyMaps VolumeSource::plane_properties(const tissue::VolumeGeometry& grid,
                                                    tissue::Volume* labels,
                                                    bool scalp_turned_back) const {
    const tissue::Volume values = resample(grid);
    if (labels) *labels = tissue::tissue_labels(values, *tf);
    tissue::PropertyMaps maps = tissue::classify(values, *tf);
    if (is_default)
        imaging::add_colin27_anatomy(loaded.volume, *tf, outside, grid, maps, labels,
                                     !scalp_turned_back);
    imaging::add_sulcal_membranes(maps, labels);
    return maps;
}

void Scene::apply_to(SimulationSettings& settings) const {
    settings.trace.interface_reach_mm = interface_reach_mm;
    settings.targets = targets;
    // A painted core blends over the smoothing width, sampled on the map's texels.
    if (phantom)
        settings.target_margin_mm =
            target_smoothing_mm + quality_level(settings.quality).map_pixel_mm;
}

void Scene::require_inside(const probe::Pose& pose, const std::string& source) const {
    // The position along the box's own axes (a volume's may be oblique to the world's).
    glm::dvec3 along, size;
    if (volume) {
        const tissue::VolumeGeometry& g = volume->loaded.volume.geometry();
        along = g.world_to_index(pose.position) * g.spacing;
        size = glm::dvec3(g.dims - 1) * g.spacing;
    } else {
        along = pose.position;
        size = phantom->size;
    }
    for (int a = 0; a < 3; ++a) {
        const double margin = 10.0;  // coupling gel, a stand-off
        if (!(along[a] >= -margin && along[a] <= size[a] + margin)) {
            throw base::InputError(source, "pose",
                                   "the probe at (" + base::number_text(pose.position.x) + ", " +
                                       base::number_text(pose.position.y) + ", " +
                                       base::number_text(pose.position.z) + ") mm is outside the " +
                                       (volume ? "volume" : "phantom"));
        }
    }
}

glm::dvec3 Scene::box_low() const {
    if (phantom) return glm::dvec3(0.0);
    const tissue::VolumeGeometry& g = volume->loaded.volume.geometry();
    return glm::min(g.index_to_world(glm::dvec3(0.0)), g.index_to_world(glm::dvec3(g.dims - 1)));
}

glm::dvec3 Scene::box_high() const {
    if (phantom) return phantom->size;
    const tissue::VolumeGeometry& g = volume->loaded.volume.geometry();
    return glm::max(g.index_to_world(glm::dvec3(0.0)), g.index_to_world(glm::dvec3(g.dims - 1)));
}

probe::Pose Scene::clamp(const probe::Pose& pose) const {
    probe::Pose out = pose;
    out.position = glm::clamp(pose.position, box_low(), box_high());
    return out;
}

probe::Pose Scene::settle(const probe::Pose& pose) const {
    if (!volume) return pose;  // a phantom's top face is flat: the probe stays at its depth
    const tissue::Volume& v = volume->loaded.volume;
    const tissue::TransferFunction& f = *volume->tf;
    const bool cortex = start.craniotomy_radius_mm > 0.0;
    const glm::dvec3 beam = pose.axial();
    const glm::dvec3 outside = pose.position - 60.0 * beam;
    const float background = volume->outside;  // no scan of the volume per move
    std::optional<probe::RayHit> hit =
        probe::skin_surface(v, f, outside, beam, 100.0, 0.5, background);
    if (hit && cortex) {
        // Under the craniotomy: through skull and CSF, then the first millimetres of brain.
        const int brain = tissue::tissue_label_of("brain"), csf = tissue::tissue_label_of("csf"),
                  bone = tissue::tissue_label_of("cortical_bone");
        hit = probe::after_gap(
            v, f, hit->point + beam, beam, 60.0,
            [&](const tissue::AcousticProperties&, int l) { return l == csf || l == bone; }, 2.0,
            [&](const tissue::AcousticProperties&, int l) { return l == brain; }, 3.0, background);
    }
    probe::Pose out = pose;
    // As craniotomy_scene: the face 0.5 mm into the cortex, in full contact.
    if (hit) out.position = hit->point + (cortex ? 0.5 : 0.0) * beam;
    return out;
}

std::vector<Scene::Material> Scene::materials() const {
    const auto table = tissue::tissue_table();
    auto tissue_name = [&](int label) {
        return label >= 1 && label <= int(table.size())
                   ? std::string(table[std::size_t(label) - 1].name)
                   : std::string();
    };
    std::vector<Material> out;
    if (phantom) {
        const std::string background = tissue_name(phantom->background_label);
        out.push_back({background.empty() ? "background" : background, phantom->background});
        for (std::size_t k = 0; k < phantom->shapes.size(); ++k) {
            const phantoms::Shape& s = phantom->shapes[k];
            const std::string tissue = tissue_name(s.label);
            out.push_back(
                {tissue.empty() ? "shape " + std::to_string(k + 1) : tissue, s.properties});
        }
        return out;
    }
    // The labels of every 7th voxel (no label volume needed), and the membranes the
    // default head gains by anatomy.
    const tissue::Volume& v = volume->loaded.volume;
    std::set<int> labels;
    for (std::size_t n = 0; n < v.size(); n += 7)
        labels.insert(volume->tf->tissue_label(v.voxels()[n]));
    if (volume->is_default) {
        labels.insert(tissue::tissue_label_of("dura"));
        labels.insert(tissue::tissue_label_of("choroid_plexus"));
    }
    // The sulci's membranes, where brain meets CSF (add_sulcal_membranes).
    if (labels.count(tissue::tissue_label_of("brain")) &&
        labels.count(tissue::tissue_label_of("csf")))
        labels.insert(tissue::tissue_label_of("pia_arachnoid"));
    for (int l : labels)
        if (l >= 1 && l <= int(table.size()))
            out.push_back({tissue_name(l), table[std::size_t(l) - 1].properties});
    return out;
}

tissue::VolumeGeometry phantom_context_grid(const phantoms::Phantom& phantom) {
    const glm::dvec3 size = phantom.size;
    const double h = std::max({1.0, size.x / 160.0, size.y / 160.0, size.z / 160.0});
    tissue::VolumeGeometry grid;
    grid.dims = glm::max(glm::ivec3(size / h) + 1, glm::ivec3(2));
    grid.spacing = glm::dvec3(h);
    return grid;
}

std::shared_ptr<const tissue::Volume> Scene::context_volume() const {
    if (volume) return {volume, &volume->loaded.volume};  // shares the loaded volume
    const tissue::VolumeGeometry grid = phantom_context_grid(*phantom);
    const tissue::PropertyMaps maps = phantoms::rasterise(*phantom, grid);
    auto impedance = std::make_shared<tissue::Volume>(grid);
    const auto& rho = maps[tissue::Property::density].voxels();
    const auto& c = maps[tissue::Property::speed_of_sound].voxels();
    for (std::size_t n = 0; n < impedance->size(); ++n)
        impedance->voxels()[n] = rho[n] * c[n] * 1e-6f;  // MRayl
    return impedance;
}

std::shared_ptr<const Scene> phantom_scene(phantoms::Phantom phantom,
                                           std::optional<probe::Pose> pose) {
    auto ph = std::make_shared<const phantoms::Phantom>(std::move(phantom));
    auto scene = std::make_shared<Scene>();
    scene->name = ph->source;
    scene->title = "phantom: " + ph->name;
    scene->description = ph->description;
    scene->start.pose = pose ? *pose : ph->pose;
    scene->start.description = "phantom " + ph->name + (pose ? ", probe at --pose" : "");
    scene->probe_preset = ph->probe_preset.empty() ? "linear" : ph->probe_preset;
    // Interfaces blend over the phantom's smoothing width; plateaus lie beyond it.
    scene->interface_reach_mm = std::max(2.0 * ph->smoothing_mm, 1.0);
    scene->targets = ph->targets;
    scene->target_smoothing_mm = ph->smoothing_mm;
    scene->mapper = [ph](const tissue::VolumeGeometry& grid, tissue::Volume* labels) {
        return phantoms::rasterise(*ph, grid, labels);
    };
    scene->instances = [ph](const tissue::VolumeGeometry& grid) {
        tissue::Volume instances;
        phantoms::rasterise(*ph, grid, nullptr, &instances);
        return instances;
    };
    scene->phantom = std::move(ph);
    return scene;
}

cv::Mat instance_map(const Scene& scene, const imaging::SimulatedFrame& frame) {
    const imaging::ScanConverted& image = frame.frame.image;
    if (!scene.instances) return cv::Mat(image.image.rows, image.image.cols, CV_16U, cv::Scalar(0));
    return imaging::scan_convert_instances(scene.instances(frame.grid.geometry), frame.grid, image);
}

void SceneOptions::validate() const {
    if (view != "craniotomy" && view != "temporal")
        throw base::InputError("--view", "", "must be craniotomy or temporal, got '" + view + "'");
    if (!phantom.empty() && volume != tissue::kDefaultVolumeName)
        throw base::InputError("--phantom", "", "cannot be combined with --volume");
}

std::string SceneOptions::volume_probe_preset() const {
    if (volume != tissue::kDefaultVolumeName) return "linear";
    return view == "temporal" ? "phased" : "convex";
}

std::shared_ptr<const Scene> load_scene(const SceneOptions& options, StageObserver* stages) {
    options.validate();
    if (!options.phantom.empty())
        return phantom_scene(phantoms::load_phantom(options.phantom), options.pose);
    auto source = std::make_shared<const VolumeSource>(load_volume_source(options, stages));
    return volume_scene(std::move(source), options, stages);
}

}  // namespace sonotrace::scene
