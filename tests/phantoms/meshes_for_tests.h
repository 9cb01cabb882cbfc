#pragma once
// Meshes the tests write: an icosphere (an icosahedron subdivided and pushed out to a
// sphere), its inradius, and writers for binary STL, OBJ, ASCII PLY and VTK polydata.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "phantoms/mesh.h"

namespace sonotrace::test {

using phantoms::TriangleMesh;

// An icosahedron subdivided `levels` times, its vertices pushed out to radius r about c;
// triangles counter-clockwise seen from outside.
inline TriangleMesh icosphere(int levels, double r, glm::dvec3 c = glm::dvec3(0.0)) {
    const double t = (1.0 + std::sqrt(5.0)) / 2.0;
    std::vector<glm::dvec3> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                 {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                 {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    for (auto& p : v) p = glm::normalize(p);
    std::vector<std::array<uint32_t, 3>> f = {
        {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
        {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
        {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
    for (int level = 0; level < levels; ++level) {
        std::map<std::pair<uint32_t, uint32_t>, uint32_t> middle;
        auto mid = [&](uint32_t a, uint32_t b) {
            const auto key = std::minmax(a, b);
            const auto found = middle.find(key);
            if (found != middle.end()) return found->second;
            v.push_back(glm::normalize(v[a] + v[b]));
            return middle[key] = uint32_t(v.size() - 1);
        };
        std::vector<std::array<uint32_t, 3>> finer;
        for (const auto& [a, b, d] : f) {
            const uint32_t ab = mid(a, b), bd = mid(b, d), da = mid(d, a);
            finer.insert(finer.end(), {{a, ab, da}, {b, bd, ab}, {d, da, bd}, {ab, bd, da}});
        }
        f = std::move(finer);
    }
    TriangleMesh mesh;
    for (const auto& p : v) mesh.vertices.push_back(c + r * p);
    mesh.triangles = f;
    return mesh;
}

// The smallest distance from c to a triangle's plane: the inradius about c.
inline double inradius(const TriangleMesh& m, glm::dvec3 c) {
    double r = 1e30;
    for (const auto& t : m.triangles) {
        const glm::dvec3 n = glm::normalize(
            glm::cross(m.vertices[t[1]] - m.vertices[t[0]], m.vertices[t[2]] - m.vertices[t[0]]));
        r = std::min(r, std::abs(glm::dot(m.vertices[t[0]] - c, n)));
    }
    return r;
}

inline void write_stl(const TriangleMesh& m, const std::string& path) {
    std::ofstream out(path, std::ios::binary);
    char header[80] = "binary STL written by test_mesh";
    out.write(header, 80);
    const auto n = uint32_t(m.triangles.size());
    out.write(reinterpret_cast<const char*>(&n), 4);
    for (const auto& t : m.triangles) {
        float values[12] = {};
        for (int k = 0; k < 3; ++k)
            for (int a = 0; a < 3; ++a)
                values[3 + 3 * k + a] = float(m.vertices[t[std::size_t(k)]][a]);
        out.write(reinterpret_cast<const char*>(values), sizeof values);
        const uint16_t attribute = 0;
        out.write(reinterpret_cast<const char*>(&attribute), 2);
    }
}

inline void write_obj(const TriangleMesh& m, const std::string& path) {
    std::ofstream out(path);
    out.precision(17);
    for (const auto& p : m.vertices) out << "v " << p.x << ' ' << p.y << ' ' << p.z << '\n';
    for (const auto& t : m.triangles)
        out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
}

inline void write_ply(const TriangleMesh& m, const std::string& path) {
    std::ofstream out(path);
    out.precision(17);
    out << "ply\nformat ascii 1.0\nelement vertex " << m.vertices.size()
        << "\nproperty double x\nproperty double y\nproperty double z\nelement face "
        << m.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
    for (const auto& p : m.vertices) out << p.x << ' ' << p.y << ' ' << p.z << '\n';
    for (const auto& t : m.triangles) out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
}

inline void write_vtk(const TriangleMesh& m, const std::string& path) {
    std::ofstream out(path);
    out.precision(17);
    out << "# vtk DataFile Version 3.0\nwritten by a test\nASCII\nDATASET POLYDATA\nPOINTS "
        << m.vertices.size() << " double\n";
    for (const auto& p : m.vertices) out << p.x << ' ' << p.y << ' ' << p.z << '\n';
    out << "POLYGONS " << m.triangles.size() << ' ' << 4 * m.triangles.size() << '\n';
    for (const auto& t : m.triangles) out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
}

}  // namespace sonotrace::test
