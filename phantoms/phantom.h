#pragma once
// Analytic phantoms: a background tissue and shapes, each a tissue from the tissue table
// or explicit acoustic properties, evaluated at any point (mm) and rasterised on any grid
// with interfaces smoothed over a stated width, so that gradients are well defined.
//
// JSON format (all lengths mm; x lateral, y depth, z elevation; the probe looks along +y):
//   {"name": "...", "description": "...",
//    "size": [x, y, z], "resolution": 0.25, "smoothing": 0.5,
//    "background": {"tissue": "liver"},                 (or every property, see tissue/)
//    "shapes": [ {"type": "sphere", "centre": [x,y,z], "radius": r, "tissue": ...}, ... ],
//    "probe": {"preset": "linear", "at": [x,y,z], "beam": [0,1,0], "lateral": [1,0,0]}}
// Shape types and their keys:
//   sphere      centre, radius
//   ellipsoid   centre, radii [rx, ry, rz]
//   box         min, max                          (axis-aligned)
//   cylinder    from, to, radius                  (a rod with flat ends)
//   wire        at [x, y], radius                 (along z through the whole phantom)
//   half_space  point, normal                     (everything beyond the plane along normal)
//   layer       point, normal, thickness          (a slab from the plane along normal)
//   tube        path [[x,y,z], ...], radius       (a bent tube along a polyline)
//   mesh        file, and optionally scale, rotate, translate: a closed triangle mesh
//               (STL, OBJ, PLY or VTK polydata; phantoms/mesh.h: its checks and inside
//               test), its path
//               relative to the phantom's file; scale (a number or [sx, sy, sz]: the
//               file's units to mm, default 1), then rotate ([rx, ry, rz] degrees about
//               x, y, z in turn), then translate ([x, y, z] mm)
//   "targets": [ {"type": "wire", "at": [x, y], "diameter": 0.1, "reflectivity": 0.3},
//                {"type": "point", "at": [x, y, z], "diameter": 0.1, "reflectivity": 0.3} ]
// A wire runs along z through [x, y, size_z / 2] unless "axis": [x, y, z] tilts it (a
// needle crossing the scan plane obliquely).
// Targets (tissue/point_target.h) are sub-resolution reflectors imaged through the
// beam's field at their exact position; diameter in (0, 2] mm (default 0.1), reflectivity
// the amplitude reflection coefficient of their surface in (0, 1] (default 0.3, nylon).
// Each is also painted into the maps (speed-matched, the impedance that reflects r, no
// scatterers), so where it is large it shadows and reflects particles like any shape.
// Later shapes paint over earlier ones. Each shape also takes the property keys of a
// transfer-function point ("tissue", "speed_of_sound", ...), and optionally
//   "profile": "parabolic"   weight 1 - (r/R)^2 from the axis (sphere, cylinder, wire,
//                            tube: a graded-index fibre) instead of the smoothed step
// Paper-mode phantoms (the particle paper's figures: one density d acting as the
// refractive index) set "mode": "paper" and give "paper_density" (d, relative) instead of
// acoustic properties, a shape optionally with "texture": {"amplitude": a, "cell": mm}
// (smooth value noise of +-a on d); "source" injects particles for `sonotrace trace`
// (2D, in the z = size/2 plane): {"type": "fan" | "parallel", "at": [x, y], "direction":
// [dx, dy], "half_angle": deg (fan) | "width": mm (parallel), "particles": n}; "trace"
// sets the tracer's physics (switches by the record keys of simulator/physics_switches.h,
// trace settings by simulator/trace_settings.h's names): {"specular_reflection":
// false, "diffuse_reflection": true, "lobe_exponent": "reflecting_density", "lobe_scale":
// 5, "lobe_weight": "energy", "roulette_energy": 1e-3, "ring": {"centre": [x, y],
// "radius": mm, "bins": n}}.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "phantoms/mesh.h"
#include "probe/pose.h"
#include "tissue/acoustic_properties.h"
#include "tissue/point_target.h"
#include "tissue/property_maps.h"
#include "tissue/volume.h"

namespace sonotrace::phantoms {

enum class ShapeType { sphere, ellipsoid, box, cylinder, wire, half_space, layer, tube, mesh };

struct Shape {
    ShapeType type = ShapeType::sphere;
    glm::dvec3 a{0.0}, b{0.0};     // centre / min / from / point; radii / max / to / normal
    double radius = 0.0;           // sphere, cylinder, wire; layer: thickness
    std::vector<glm::dvec3> path;  // tube: the centreline
    std::shared_ptr<const MeshShape> mesh;  // mesh: the placed surface
    tissue::AcousticProperties properties;
    int label = 0;               // tissue label (tissue_label_of), 0 for explicit properties
    bool parabolic = false;      // "profile": "parabolic"
    double paper_density = 1.0;  // paper mode
    double texture_amplitude = 0.0, texture_cell_mm = 1.0;  // paper mode

    // Signed distance (mm): negative inside. Exact for sphere, box, cylinder, wire,
    // half-space, layer, tube and mesh; for an ellipsoid the distance scaled by its
    // smallest radius.
    double signed_distance(const glm::dvec3& p) const;
    // How much of the shape is at p (0..1): the linear ramp over `smoothing` across the
    // boundary, or the parabolic profile. `steady_mm` (optional) receives a distance from
    // p within which the weight is the same (0 when none is known): a mesh's distance is
    // exact, so beyond the ramp it cannot change sooner than the distance left to it.
    double weight(const glm::dvec3& p, double smoothing_mm, double* steady_mm = nullptr) const;
};

// 2D particle injection of a paper-mode (or any) phantom for `sonotrace trace`.
struct ParticleSource {
    enum class Type { fan, parallel } type = Type::fan;
    glm::dvec2 at{0.0}, direction{0.0, 1.0};
    double half_angle_deg = 30.0, width_mm = 10.0;
    int particles = 100;
};

struct Phantom {
    std::string name, description, source;
    glm::dvec3 size{40.0, 40.0, 10.0};  // extent from the origin
    double resolution_mm = 0.25;        // of rasterised volumes
    double smoothing_mm = 0.5;          // width over which each interface blends
    tissue::AcousticProperties background;
    int background_label = 0;
    std::vector<Shape> shapes;  // including the targets' painted cores
    std::vector<tissue::PointTarget> targets;
    std::string probe_preset;  // "" = the command's default
    probe::Pose pose;          // default: top centre, beam +y, lateral +x
    bool paper_mode = false;
    double background_paper_density = 1.0;
    std::optional<ParticleSource> injection;          // "source" entry
    nlohmann::json trace = nlohmann::json::object();  // tracer settings ("trace" entry)

    // Properties (blended linearly across each shape's boundary over smoothing_mm), the
    // label and the instance (the last shape covering the point by half or more: its
    // tissue label, and its place in `shapes` from 1; 0 for the background) at a point.
    tissue::AcousticProperties at(const glm::dvec3& p, int* label = nullptr,
                                  int* instance = nullptr) const;
    // The same from each shape's weight at the point (weights[k] of shapes[k]).
    tissue::AcousticProperties blend(const double* weights, int* label = nullptr,
                                     int* instance = nullptr) const;
    // Paper mode: the density d at a point (blended like the properties, plus textures).
    double paper_density_at(const glm::dvec3& p) const;
};

// Parses a phantom; errors name `source` and the JSON path of the field.
Phantom parse_phantom(const nlohmann::json& j, const std::string& source);
Phantom load_phantom(const std::string& path);

// The phantom on a grid: property maps and, on request, tissue labels and shape
// instances (nearest).
tissue::PropertyMaps rasterise(const Phantom& phantom, const tissue::VolumeGeometry& grid,
                               tissue::Volume* labels = nullptr,
                               tissue::Volume* instances = nullptr);
// Paper mode: the density d on a grid.
tissue::Volume rasterise_paper_density(const Phantom& phantom, const tissue::VolumeGeometry& grid);
// The phantom's 2D grid for tracing: the z = size/2 plane at its resolution.
tissue::VolumeGeometry plane_grid_2d(const Phantom& phantom);

// Smooth value noise in [-1, 1] with cells of `cell` mm (deterministic hash).
double value_noise(double x, double y, double cell);

}  // namespace sonotrace::phantoms
