#include "ui/gui/scene.h"

#include <algorithm>
#include <filesystem>

#include "tissue/base/error.h"
#include "tissue/base/json_util.h"

namespace sonotrace::gui {

namespace {

bool ends_with(const std::string& s, const std::string& tail) {
    return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// The scene with its 3D context; `name` is what the catalogue calls it.
std::shared_ptr<const Scene> with_context(const scene::Scene& loaded, const std::string& name) {
    auto scene = std::make_shared<Scene>();
    static_cast<scene::Scene&>(*scene) = loaded;
    scene->name = name;
    const bool head = loaded.volume && loaded.volume->is_default;
    scene->context_tf = imaging::pbvr::load_colour_tf(head ? "head" : "ramp");
    scene->context_zoom = head ? 1.3 : 1.0;
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
