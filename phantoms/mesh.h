#pragma once
// Closed triangle meshes as phantom shapes (phantom.h's "mesh" type): read from STL, OBJ
// or PLY (Assimp) or VTK legacy polydata (tissue/vtk_legacy.h), checked, placed by a
// transform, and evaluated as a signed distance.
//
// Checks (each failure names the file): the file exists and is at most kMaxMeshFileBytes;
// the counts a file declares fit its size (STL, PLY, VTK); at most kMaxMeshTriangles triangles;
// every coordinate finite; no triangle of zero area; closed and consistently oriented (every edge
// shared by exactly two triangles that run it in opposite directions, after coincident vertices are
// merged); a positive enclosed volume; no two triangles that share no vertex cross
// (triangle_overlap.h), which would leave points inside twice or inside out, where the
// inside test below has no answer. A mesh wound inwards is turned outwards.
//
// Inside test: the sign of (p - q) . N, where q is the point of the mesh nearest to p and
// N the angle-weighted pseudo-normal of the feature q lies on (the triangle, an edge: the
// sum of its two triangles' normals, or a vertex: its triangles' normals weighted by their
// angles there). For a closed, consistently oriented mesh this sign is exact wherever q is
// (Baerentzen & Aanaes, IEEE TVCG 11(3), 2005), without the ray-parity test's trouble at
// edges and vertices. The nearest point comes from a bounding-volume hierarchy.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace sonotrace::phantoms {

inline constexpr std::uintmax_t kMaxMeshFileBytes = std::uintmax_t(2) << 30;  // 2 GiB
inline constexpr std::size_t kMaxMeshTriangles = 20'000'000;

struct TriangleMesh {
    std::vector<glm::dvec3> vertices;                // mm
    std::vector<std::array<uint32_t, 3>> triangles;  // counter-clockwise seen from outside
};

// The triangles of every mesh in the file, coincident vertices merged. Throws
// base::InputError(path, ...) when it cannot be read or holds no triangle.
TriangleMesh read_mesh_file(const std::string& path);

// Scale, then rotate (degrees about x, then y, then z), then translate: the file's units
// and frame to the phantom's millimetres.
struct MeshTransform {
    glm::dvec3 scale{1.0}, rotate_deg{0.0}, translate_mm{0.0};
    glm::dvec3 apply(const glm::dvec3& p) const;
};

// A closed mesh ready for distance queries (see the top of this file).
class MeshShape {
  public:
    // Checks `mesh` (errors name `source`) and builds the hierarchy.
    MeshShape(TriangleMesh mesh, const std::string& source);

    // Distance (mm) to the surface, negative inside.
    double signed_distance(const glm::dvec3& p) const;
    // The distance from p to the bounding box (0 inside it): a lower bound of |distance|
    // that costs nothing, for callers that need only nearby points.
    double distance_to_bounds(const glm::dvec3& p) const;
    const glm::dvec3& lower() const { return lower_; }
    const glm::dvec3& upper() const { return upper_; }
    double volume_mm3() const { return volume_; }
    std::size_t triangle_count() const { return mesh_.triangles.size(); }

  private:
    struct Node {
        glm::dvec3 lower, upper;
        uint32_t first = 0, count = 0;  // leaf: triangles [first, first + count) of order_
        uint32_t left = 0, right = 0;   // inner: child nodes
    };
    uint32_t build(uint32_t first, uint32_t count, const std::vector<glm::dvec3>& centres);
    // Throws base::InputError(source, "triangle N") for the first pair that crosses.
    void require_no_crossing(const std::string& source) const;

    TriangleMesh mesh_;
    std::vector<glm::dvec3> face_normal_;                 // unit, per triangle
    std::vector<std::array<glm::dvec3, 3>> edge_normal_;  // per triangle, edge k: v[k] -> v[k+1]
    std::vector<glm::dvec3> vertex_normal_;               // angle-weighted
    std::vector<uint32_t> order_;                         // triangle indices, by leaf
    std::vector<Node> nodes_;
    glm::dvec3 lower_{0.0}, upper_{0.0};
    double volume_ = 0.0;
};

}  // namespace sonotrace::phantoms
