#pragma once
// What the demo GUI scans: the Colin27 head (intraoperative and transtemporal views), a
// phantom of the catalogue, or a volume or phantom file. A scene knows where the probe
// starts, how to lay it back on the surface after a move, what lies on any plane, and
// the volume the 3D context view renders. No OpenGL here: the tests use it directly.
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "imaging/pbvr/colour_tf.h"
#include "imaging/simulation.h"
#include "tissue/volume.h"

namespace sonotrace::gui {

struct SceneEntry {
    std::string name;   // what load_scene takes
    std::string title;  // what the scene menu shows
};

// The built-in scenes: the two head views, then every phantom in `phantom_dir`.
std::vector<SceneEntry> scene_catalogue(const std::string& phantom_dir);

struct Scene {
    std::string name, title, description;
    imaging::ScenePlacement start;  // where the probe starts (and the craniotomy)
    std::string probe_preset;       // the probe it is meant for
    imaging::PlaneMapper mapper;    // properties and labels on a plane grid
    double interface_reach_mm = 1.0;
    // Lays a moved probe back on the surface (skin, or cortex under the craniotomy);
    // returns the pose unchanged where no surface is found.
    std::function<probe::Pose(const probe::Pose&)> settle;
    // The box (world mm) the probe face must stay in.
    glm::dvec3 box_low{0.0}, box_high{0.0};
    // The 3D context: a volume and its colour transfer function (bound to it).
    std::shared_ptr<const tissue::Volume> context;
    imaging::pbvr::ColourTransferFunction context_tf;
    double context_zoom = 1.0;  // the 3D view's start zoom (the head is framed closer)
    // The distinct materials present (tissues of the table or a phantom's explicit
    // properties), for the explain panel.
    std::vector<tissue::AcousticProperties> materials;
};

// "head-craniotomy", "head-temporal", "phantom:NAME" (NAME.json in phantom_dir), or a
// path: a phantom (.json) or a volume (NIfTI, raw with header, image stack; see
// tissue/volume_io.h), scanned from the top face. Throws base::InputError naming the
// file on any failure; nothing is half-loaded.
std::shared_ptr<const Scene> load_scene(const std::string& spec, const std::string& phantom_dir);

// The probe kept inside the scene's box (face position clamped).
probe::Pose clamp_to_scene(const Scene& scene, const probe::Pose& pose);

}  // namespace sonotrace::gui
