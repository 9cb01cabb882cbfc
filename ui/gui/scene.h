#pragma once
// What the demo GUI scans: the Colin27 head (intraoperative and transtemporal views), a
// phantom of the catalogue, or a volume or phantom file, each an scene::Scene with the
// volume its 3D context view renders. No OpenGL here: the tests use it directly.
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "imaging/pbvr/colour_tf.h"
#include "phantoms/scene/scene.h"
#include "tissue/volume.h"

namespace sonotrace::gui {

struct SceneEntry {
    std::string name;   // what load_scene takes
    std::string title;  // what the scene menu shows
};

// The built-in scenes: the two head views, then every phantom in `phantom_dir`.
std::vector<SceneEntry> scene_catalogue(const std::string& phantom_dir);

// A scene (phantoms/scene/scene.h) as the GUI shows it: with its 3D context.
struct Scene : scene::Scene {
    // The 3D context: a volume and its colour transfer function (bound to it).
    std::shared_ptr<const tissue::Volume> context;
    imaging::pbvr::ColourTransferFunction context_tf;
    double context_zoom = 1.0;  // the 3D view's start zoom (the head is framed closer)
};

// "head-craniotomy", "head-temporal", "phantom:NAME" (NAME.json in phantom_dir), or a
// path: a phantom (.json) or a volume (NIfTI, DICOM, raw with header, image stack; see
// tissue/volume_io.h), placed by scene::default_volume_pose. `tf` is a volume's transfer
// function (a preset name or a JSON file; empty: the volume's default). Throws
// base::InputError naming the file on any failure; nothing is half-loaded.
std::shared_ptr<const Scene> load_scene(const std::string& spec, const std::string& phantom_dir,
                                        const std::string& tf = "");

}  // namespace sonotrace::gui
