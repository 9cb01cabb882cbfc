#pragma once
// Irregular volumes for image-space PBVR (Sakamoto & Koyamada, sec. 3.4 and 4):
// tetrahedral meshes, their VTK legacy input, the tetrahedralisation of regular grids,
// and the fragments a camera ray cuts out of a tetrahedron.
//
// A fragment is what the projected-tetrahedra split hands to stochastic rasterization:
// for one sub-pixel, the ray's entry and exit through the tetrahedron, with the scalar
// (linear inside a tetrahedron) and the camera depth at both (PbvrRenderer rasterizes
// the projected faces; cross_tetrahedron clips one ray, for the reference).
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "tissue/volume.h"

namespace sonotrace::imaging::pbvr {

// The 6 tetrahedra of a hexahedral cell around its diagonal 0-7 (corner c = x + 2y + 4z):
// every face is split along the diagonal through its lowest and highest corners, the
// same on both sides of a face, so the split conforms across cells.
inline constexpr std::array<std::array<int, 4>, 6> kCellTetrahedra = {
    {{0, 1, 3, 7}, {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}, {0, 4, 5, 7}, {0, 5, 1, 7}}};

struct TetMesh {
    std::vector<glm::dvec3> points;             // world mm
    std::vector<float> values;                  // per point, raw (the TF normalizes)
    std::vector<std::array<uint32_t, 4>> tets;  // point indices

    // Throws base::InputError(source, ...) on indices out of range or non-finite data.
    void validate(const std::string& source) const;
    // The values as a volume-like sample set for ColourTransferFunction::bind.
    tissue::Volume values_as_volume() const;
};

// VTK legacy unstructured grid (ASCII or binary): POINTS, CELLS and CELL_TYPES (10
// tetrahedron, 12 hexahedron: split into 6 tetrahedra; other types are an error), and
// the first POINT_DATA SCALARS array. Throws InputError naming the file and section.
TetMesh read_vtk_unstructured(const std::string& path);

// Every cell of a regular volume (or of the index box [low, high]) as 6 tetrahedra
// around the cell's main diagonal (conforming across cells), in world coordinates.
TetMesh tetrahedralize(const tissue::Volume& volume, glm::ivec3 low = glm::ivec3(0),
                       std::optional<glm::ivec3> high = std::nullopt);

// A ray's passage through a tetrahedron: parameters along the ray (entry < exit) and
// the barycentric weights of the entry and exit points.
struct TetCrossing {
    double t_entry = 0.0, t_exit = 0.0;
    glm::dvec4 entry_weights{0.0}, exit_weights{0.0};
};
// Clips the ray origin + t dir (t >= 0) against the tetrahedron's four faces.
std::optional<TetCrossing> cross_tetrahedron(const std::array<glm::dvec3, 4>& corners,
                                             const glm::dvec3& origin, const glm::dvec3& dir);
// The same with the tetrahedron given by its first corner and the inverse of its edge
// matrix (v1 - v0, v2 - v0, v3 - v0), for many rays through one tetrahedron.
std::optional<TetCrossing> cross_tetrahedron(const glm::dvec3& corner0,
                                             const glm::dmat3& inverse_edges,
                                             const glm::dvec3& origin, const glm::dvec3& dir);

}  // namespace sonotrace::imaging::pbvr
