#include "ui/gui/scene.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"

namespace sonotrace::gui {

namespace {

bool ends_with(const std::string& s, const std::string& tail) {
    return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// The 3D context of a phantom with mesh shapes: each texel the shape it lies in
// (Scene::instances, on scene::phantom_context_grid), each shape in
// its tissue's colour of the label maps' legend (imaging::label_colour), at an opacity
// that lets a fifth of the light through it (1 - 0.2^(1 / d) a millimetre, d the diameter
// of a ball of its volume), so that a vessel inside a liver shows through it; the layers and
// half-spaces, which fill the phantom's box, and the background clear. Each index is
// opaque within 0.2 of itself only: where trilinear sampling runs between two indices it
// passes the others' bands in a tenth of a texel. Its acoustic impedance, the context of
// other phantoms, draws an abdomen as a block with nothing inside.
void mesh_phantom_context(const phantoms::Phantom& phantom, Scene& scene) {
    const tissue::VolumeGeometry grid = scene::phantom_context_grid(phantom);
    const double h = grid.spacing.x;
    auto instances = std::make_shared<tissue::Volume>(scene.instances(grid));
    const std::size_t count = phantom.shapes.size();
    std::vector<double> texels(count + 1, 0.0);
    for (const float v : instances->voxels()) texels[std::size_t(v)] += 1.0;
    std::vector<imaging::pbvr::ColourPoint> points = {{0.0, glm::vec3(0.0f), 0.0}};
    const double top = std::max(double(count), 1.0), band = 0.2 / top;
    for (std::size_t k = 0; k < count; ++k) {
        const phantoms::Shape& shape = phantom.shapes[k];
        const bool fills_box = shape.type == phantoms::ShapeType::layer ||
                               shape.type == phantoms::ShapeType::half_space;
        if (fills_box || texels[k + 1] == 0.0) continue;
        const double diameter = std::cbrt(6.0 / std::numbers::pi * texels[k + 1] * h * h * h);
        const double opacity = 1.0 - std::pow(0.2, 1.0 / std::max(diameter, 1.0));
        const cv::Vec3b bgr = imaging::label_colour(shape.label);
        const glm::vec3 colour =
            shape.label > 0 ? glm::vec3(bgr[2], bgr[1], bgr[0]) / 255.0f : glm::vec3(0.7f);
        const double at = double(k + 1) / top;
        points.push_back({at - 1.5 * band, colour, 0.0});
        points.push_back({at - band, colour, opacity});
        points.push_back({std::min(at + band, 1.0), colour, opacity});
        if (at + 1.5 * band < 1.0) points.push_back({at + 1.5 * band, colour, 0.0});
    }
    if (points.back().value < 1.0) points.push_back({1.0, glm::vec3(0.0f), 0.0});
    scene.context_tf = imaging::pbvr::ColourTransferFunction("shapes", phantom.source,
                                                             std::move(points), 1.0, 0.0, 1.0);
    scene.context_tf.set_window(0.0f, float(top));
    scene.context = std::move(instances);
}

// The scene with its 3D context; `name` is what the catalogue calls it.
std::shared_ptr<const Scene> with_context(const scene::Scene& loaded, const std::string& name) {
    auto scene = std::make_shared<Scene>();
    static_cast<scene::Scene&>(*scene) = loaded;
    scene->name = name;
    const bool head = loaded.volume && loaded.volume->is_default;
    scene->context_zoom = head ? 1.3 : 1.0;
    const bool meshes =
        loaded.phantom &&
        std::any_of(loaded.phantom->shapes.begin(), loaded.phantom->shapes.end(),
                    [](const phantoms::Shape& s) { return s.type == phantoms::ShapeType::mesh; });
    if (meshes) {
        mesh_phantom_context(*loaded.phantom, *scene);
        return scene;
    }
    scene->context_tf = imaging::pbvr::load_colour_tf(head ? "head" : "ramp");
    scene->context = loaded.context_volume();
    scene->context_tf.bind(*scene->context);
    return scene;
}

std::shared_ptr<const Scene> load(scene::SceneOptions options, const std::string& name) {
    return with_context(*scene::load_scene(options), name);
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

std::shared_ptr<const Scene> load_scene(const std::string& spec, const std::string& phantom_dir,
                                        const std::string& tf) {
    scene::SceneOptions options;
    options.tf = tf;
    if (spec == "head-craniotomy" || spec == "head" || spec == "default")
        return load(options, "head-craniotomy");
    if (spec == "head-temporal") {
        options.view = "temporal";
        return load(options, spec);
    }
    if (spec.rfind("phantom:", 0) == 0) {
        const std::string name = spec.substr(8);
        const std::string path = phantom_dir + "/" + name + ".json";
        if (name.empty() || name.find('/') != std::string::npos || !std::filesystem::exists(path))
            throw base::InputError(spec, "", "no phantom of that name in " + phantom_dir);
        options.phantom = path;
        return load(options, spec);
    }
    if (!std::filesystem::exists(spec))
        throw base::InputError(spec, "",
                               "no such file (scenes: head-craniotomy, head-temporal, "
                               "phantom:NAME, or a volume or phantom file)");
    // A phantom, unless it is a raw volume's header (which names its data file).
    if (ends_with(spec, ".json")) {
        const nlohmann::json j = base::jsonio::read_file(spec);
        if (j.is_object() && j.contains("shapes")) {
            options.phantom = spec;
            return load(options, spec);
        }
    }
    options.volume = spec;
    return load(options, spec);
}

}  // namespace sonotrace::gui
