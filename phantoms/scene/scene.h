#pragma once
// The one scene type: what is scanned (an MRI or other volume through its transfer
// function, or an analytic phantom), where the probe starts, which probe it is meant for,
// how a plane grid under the probe is filled, and the tracer and imaging settings that
// follow from the medium (interface reach, point targets). `sonotrace simulate`, the GUI,
// the validation cases and the benchmarks all build theirs here, so a scene means the
// same thing everywhere.
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "probe/pose.h"
#include "tissue/base/stages.h"
#include "tissue/transfer_function.h"
#include "tissue/volume.h"
#include "tissue/volume_io.h"

namespace sonotrace::scene {

using base::StageObserver;
using imaging::PlaneMapper;
using imaging::ScenePlacement;
using imaging::SimulationSettings;

// The volume options (--volume, --spacing, --tf, --outside): documented once in
// ui/cli/volume_slice.cpp, named by these flags in error messages.
struct VolumeOptions {
    std::string volume = "default";  // tissue::kDefaultVolumeName, a file or a pattern
    std::string spacing;             // "SX,SY[,SZ]" mm, for images
    std::string tf;                  // preset or file; empty = the volume's default
    double outside = std::numeric_limits<double>::quiet_NaN();  // NaN = the volume's minimum
};

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
    // scalp and membranes the embedded head's MRI cannot tell (imaging::add_colin27_anatomy;
    // `scalp_turned_back`: the scalp as the MRI reads it, for the craniotomy view).
    tissue::PropertyMaps plane_properties(const tissue::VolumeGeometry& grid,
                                          tissue::Volume* labels,
                                          bool scalp_turned_back = false) const;
};

// Default pose for a volume other than the embedded head. With anatomical axes (NIfTI
// with a qform or sform, DICOM): on the skin at the top of the volume, above the centre
// of its box, the beam pointing inferior and the array from the subject's left to right (a
// coronal image, as a probe laid on the vertex of a head). Otherwise top_centre_pose.
probe::Pose default_volume_pose(const VolumeSource& source);

// Validates the volume options, loads the volume and binds the transfer function.
VolumeSource load_volume_source(const VolumeOptions& options, StageObserver* stages = nullptr);

// Default pose for a volume without anatomical axes: on the top face of its bounding
// box, centred, beam along +j, lateral along +i.
probe::Pose top_centre_pose(const tissue::VolumeGeometry& g);

// The overall gain (dB) of a frame whose scene does not say otherwise (Scene::gain_db).
inline constexpr double kDefaultGainDb = 36.0;
// The default head's transtemporal view: the skull costs about 27 dB two-way, and the
// phased probe's frame reaches deeper; this gain puts the parenchyma's median grey level
// where the craniotomy view has it, off the black floor (docs/guide/simulate.md).
inline constexpr double kTemporalGainDb = 74.0;

struct Scene {
    std::string name;          // what identifies it ("head-craniotomy", a file's path)
    std::string title;         // one line, for menus
    std::string description;   // a sentence: what it is, or where the probe sits
    ScenePlacement start;      // where the probe starts (and the craniotomy)
    std::string probe_preset;  // the probe it is meant for
    // The overall gain (dB) a sonographer would start at: 36, and 60 through the skull
    // (the transtemporal view: the bone costs about 27 dB two-way, and at 36 dB the brain
    // is near black). `simulate --gain` and the GUI's slider start here.
    double gain_db = kDefaultGainDb;
    PlaneMapper mapper;  // properties and labels on a plane grid
    // A phantom's shape instances on a grid (Phantom::at: its place in the phantom's
    // shapes from 1, the targets' painted cores after the JSON's shapes; 0 background);
    // empty for a volume, which has none.
    std::function<tissue::Volume(const tissue::VolumeGeometry&)> instances;
    // Reach of the tracer's interface search: beyond it the medium is a plateau.
    double interface_reach_mm = 1.0;
    // Sub-resolution targets (a phantom's points and wires) and the blur of their painted
    // cores (the phantom's smoothing); see SimulationSettings::targets.
    std::vector<tissue::PointTarget> targets;
    double target_smoothing_mm = 0.0;
    // Exactly one of these is set.
    std::shared_ptr<const VolumeSource> volume;
    std::shared_ptr<const phantoms::Phantom> phantom;

    // Sets what follows from the medium: interface reach, targets and their margin (which
    // depends on the quality's map pixel: set the quality first).
    void apply_to(SimulationSettings& settings) const;
    // Refuses a pose whose face lies more than 10 mm outside the volume or phantom: it
    // would image nothing. `source` names where the pose came from.
    void require_inside(const probe::Pose& pose, const std::string& source) const;
    // The probe kept inside the scanned box (face position clamped, world axes).
    probe::Pose clamp(const probe::Pose& pose) const;
    // Lays a moved probe back on the surface along its beam (the cortex under a
    // craniotomy, else the skin); a phantom's flat top keeps the pose as it is.
    probe::Pose settle(const probe::Pose& pose) const;
    // The distinct materials present (tissues of the table or a phantom's explicit
    // properties), named: what the scene can do to a beam, and what the GUI quotes.
    struct Material {
        std::string name;  // the tissue's human name, or "shape N" for explicit properties
        tissue::AcousticProperties properties;
    };
    std::vector<Material> materials() const;
    // A volume for a 3D view: the loaded volume, or a phantom's acoustic impedance
    // (MRayl) on a grid of at most 160 samples a side.
    std::shared_ptr<const tissue::Volume> context_volume() const;
    // The box (world mm) the scanned object spans.
    glm::dvec3 box_low() const;
    glm::dvec3 box_high() const;
};

// The grid a phantom's 3D context is drawn on (Scene::context_volume, the GUI's shapes):
// its box at 1 mm, or coarser so that no side has more than 160 samples.
tissue::VolumeGeometry phantom_context_grid(const phantoms::Phantom& phantom);

// The instance map of a simulated frame (scan_convert_instances on its plane grid): CV_16U,
// all 0 for a scene without instances.
cv::Mat instance_map(const Scene& scene, const imaging::SimulatedFrame& frame);

// What to scan: the volume options, or a phantom file instead; the view of the embedded
// head; a pose instead of the scene's own.
struct SceneOptions : VolumeOptions {
    std::string phantom;              // a phantom file (phantoms/*.json); excludes `volume`
    std::string view = "craniotomy";  // of the default head: craniotomy or temporal
    std::optional<probe::Pose> pose;  // from --pose

    // The checks that need no file: view name, phantom and volume not both.
    void validate() const;
    // The probe a volume's scene is meant for (the view's on the default head, else the
    // linear), known before the volume is loaded; a phantom names its own.
    std::string volume_probe_preset() const;
};

// Validates the options, loads the volume or phantom and places the probe. Throws
// base::InputError naming the option or file; nothing is half-loaded.
std::shared_ptr<const Scene> load_scene(const SceneOptions& options,
                                        StageObserver* stages = nullptr);

// A phantom already in memory (the validation cases edit theirs).
std::shared_ptr<const Scene> phantom_scene(phantoms::Phantom phantom,
                                           std::optional<probe::Pose> pose = std::nullopt);

}  // namespace sonotrace::scene
