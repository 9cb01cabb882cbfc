#pragma once
// Whether two triangles in space cross, by the separating-axis theorem: two convex sets
// are disjoint exactly when their projections on some axis are. For two triangles with
// normals n1, n2 and edges e1_i, e2_j the candidate axes are n1, n2, the nine e1_i x e2_j,
// and (for coplanar triangles, where the cross products vanish or lie along n) the
// in-plane edge normals n1 x e1_i and n2 x e2_j: 17 in all (Eberly, "Intersection of
// Convex Objects: The Method of Separating Axes", Geometric Tools, 2008). Axes of length
// zero separate nothing and are skipped. Projections that overlap by no more than
// `touch` (mm) count as apart, so triangles that only touch do not cross.
#include <algorithm>
#include <array>

#include <glm/glm.hpp>

namespace sonotrace::phantoms {

using Triangle = std::array<glm::dvec3, 3>;

inline bool triangles_cross(const Triangle& a, const Triangle& b, double touch) {
    const std::array<glm::dvec3, 3> ea = {a[1] - a[0], a[2] - a[1], a[0] - a[2]};
    const std::array<glm::dvec3, 3> eb = {b[1] - b[0], b[2] - b[1], b[0] - b[2]};
    const glm::dvec3 na = glm::cross(ea[0], ea[1]), nb = glm::cross(eb[0], eb[1]);
    auto separates = [&](const glm::dvec3& axis) {
        const double length = glm::length(axis);
        if (!(length > 1e-300)) return false;
        const glm::dvec3 u = axis / length;
        const double a0 = glm::dot(a[0], u), a1 = glm::dot(a[1], u), a2 = glm::dot(a[2], u);
        const double b0 = glm::dot(b[0], u), b1 = glm::dot(b[1], u), b2 = glm::dot(b[2], u);
        const double a_low = std::min({a0, a1, a2}), a_high = std::max({a0, a1, a2});
        const double b_low = std::min({b0, b1, b2}), b_high = std::max({b0, b1, b2});
        return a_high <= b_low + touch || b_high <= a_low + touch;
    };
    if (separates(na) || separates(nb)) return false;
    for (const glm::dvec3& i : ea)
        for (const glm::dvec3& j : eb)
            if (separates(glm::cross(i, j))) return false;
    for (const glm::dvec3& i : ea)
        if (separates(glm::cross(na, i))) return false;
    for (const glm::dvec3& j : eb)
        if (separates(glm::cross(nb, j))) return false;
    return true;
}

}  // namespace sonotrace::phantoms
