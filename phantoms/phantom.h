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
// Later shapes paint over earlier ones. Each shape also takes the property keys of a
// transfer-function point ("tissue", "speed_of_sound", ...).
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "probe/pose.h"
#include "tissue/acoustic_properties.h"
#include "tissue/property_maps.h"
#include "tissue/volume.h"

namespace sonotrace::phantoms {

enum class ShapeType { sphere, ellipsoid, box, cylinder, wire, half_space, layer };

struct Shape {
    ShapeType type = ShapeType::sphere;
    glm::dvec3 a{0.0}, b{0.0};  // centre / min / from / point; radii / max / to / normal
    double radius = 0.0;        // sphere, cylinder, wire; layer: thickness
    tissue::AcousticProperties properties;
    int label = 0;  // tissue label (tissue_label_of), 0 for explicit properties

    // Signed distance (mm): negative inside. Exact for sphere, box, cylinder, wire,
    // half-space and layer; for an ellipsoid the distance scaled by its smallest radius.
    double signed_distance(const glm::dvec3& p) const;
};

struct Phantom {
    std::string name, description, source;
    glm::dvec3 size{40.0, 40.0, 10.0};  // extent from the origin
    double resolution_mm = 0.25;        // of rasterised volumes
    double smoothing_mm = 0.5;          // width over which each interface blends
    tissue::AcousticProperties background;
    int background_label = 0;
    std::vector<Shape> shapes;
    std::string probe_preset;  // "" = the command's default
    probe::Pose pose;          // default: top centre, beam +y, lateral +x

    // Properties (blended linearly across each shape's boundary over smoothing_mm) and
    // the label (the shape covering the point by half or more) at a point.
    tissue::AcousticProperties at(const glm::dvec3& p, int* label = nullptr) const;
};

// Parses a phantom; errors name `source` and the JSON path of the field.
Phantom parse_phantom(const nlohmann::json& j, const std::string& source);
Phantom load_phantom(const std::string& path);

// The phantom on a grid: property maps and, on request, tissue labels (nearest).
tissue::PropertyMaps rasterise(const Phantom& phantom, const tissue::VolumeGeometry& grid,
                               tissue::Volume* labels = nullptr);

}  // namespace sonotrace::phantoms
