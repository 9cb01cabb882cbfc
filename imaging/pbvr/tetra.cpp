#include "imaging/pbvr/tetra.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <type_traits>

#include "tissue/base/error.h"
#include "tissue/vtk_legacy.h"

namespace sonotrace::imaging::pbvr {

using base::InputError;

namespace {

// VTK hexahedron point order -> corner c = x + 2y + 4z.
constexpr std::array<int, 8> kVtkHexToCorner = {0, 1, 3, 2, 4, 5, 7, 6};

}  // namespace

void TetMesh::validate(const std::string& source) const {
    if (values.size() != points.size())
        throw InputError(source, "POINT_DATA", "needs one scalar per point");
    for (std::size_t p = 0; p < points.size(); ++p) {
        if (!std::isfinite(values[p]) || !std::isfinite(points[p].x) ||
            !std::isfinite(points[p].y) || !std::isfinite(points[p].z))
            throw InputError(source, "POINTS", "point " + std::to_string(p) + " is not finite");
    }
    for (std::size_t t = 0; t < tets.size(); ++t)
        for (uint32_t i : tets[t])
            if (i >= points.size())
                throw InputError(source, "CELLS",
                                 "cell " + std::to_string(t) + " refers to a missing point");
}

tissue::Volume TetMesh::values_as_volume() const {
    tissue::VolumeGeometry g;
    g.dims = {int(std::max<std::size_t>(values.size(), 1)), 1, 1};
    tissue::Volume volume(g);
    std::copy(values.begin(), values.end(), volume.voxels().begin());  // empty: one zero
    return volume;
}

TetMesh read_vtk_unstructured(const std::string& path) {
    tissue::VtkLegacyStream in(path);
    TetMesh mesh;
    std::vector<std::vector<int64_t>> cells;
    std::vector<int> types;
    bool have_scalars = false;
    while (const std::optional<std::string> keyword = in.next_keyword()) {
        const std::string& w = *keyword;
        if (w == "DATASET") {
            if (in.word("DATASET") != "UNSTRUCTURED_GRID")
                throw InputError(path, "DATASET", "only UNSTRUCTURED_GRID is supported");
        } else if (w == "POINTS") {
            mesh.points = in.points();
        } else if (w == "CELLS") {
            const std::size_t n = in.count("CELLS", 4.0, 8.0);  // a count and an index at least
            in.word("CELLS");                                   // total size
            if (mesh.points.empty()) throw InputError(path, "CELLS", "comes before POINTS");
            cells.resize(n);
            for (auto& c : cells) {
                const auto count = in.number<int64_t>("CELLS", "int");
                if (count < 1 || count > 64) throw InputError(path, "CELLS", "bad point count");
                c.resize(std::size_t(count));
                for (auto& i : c) i = in.number<int64_t>("CELLS", "int");
            }
            in.section_done();
        } else if (w == "CELL_TYPES") {
            types.resize(in.count("CELL_TYPES", 2.0, 4.0));
            for (int& t : types) t = in.number<int>("CELL_TYPES", "int");
            in.section_done();
        } else if (w == "SCALARS" && !have_scalars) {
            in.word("SCALARS");  // name
            const std::string type = in.word("SCALARS");
            std::string next = in.word("SCALARS");
            if (next != "LOOKUP_TABLE") next = in.word("SCALARS");  // component count given
            in.word("SCALARS");                                     // table name
            mesh.values.resize(mesh.points.size());
            for (float& v : mesh.values) v = in.number<float>("SCALARS", type);
            in.section_done();
            have_scalars = true;
        }
    }
    if (cells.size() != types.size())
        throw InputError(path, "CELL_TYPES", "needs one type per cell");
    if (!have_scalars) throw InputError(path, "POINT_DATA", "needs a SCALARS array");
    for (std::size_t c = 0; c < cells.size(); ++c) {
        const auto& v = cells[c];
        for (const int64_t i : v)
            if (i < 0 || std::size_t(i) >= mesh.points.size())
                throw InputError(path, "CELLS",
                                 "cell " + std::to_string(c) + " refers to a missing point");
        if (types[c] == 10 && v.size() == 4) {
            mesh.tets.push_back({uint32_t(v[0]), uint32_t(v[1]), uint32_t(v[2]), uint32_t(v[3])});
        } else if (types[c] == 12 && v.size() == 8) {
            std::array<uint32_t, 8> corner{};
            for (int k = 0; k < 8; ++k)
                corner[std::size_t(kVtkHexToCorner[std::size_t(k)])] = uint32_t(v[std::size_t(k)]);
            for (const auto& t : kCellTetrahedra)
                mesh.tets.push_back({corner[std::size_t(t[0])], corner[std::size_t(t[1])],
                                     corner[std::size_t(t[2])], corner[std::size_t(t[3])]});
        } else {
            throw InputError(path, "CELL_TYPES",
                             "cell " + std::to_string(c) + " has type " + std::to_string(types[c]) +
                                 " (only 10 tetrahedron and 12 hexahedron are supported)");
        }
    }
    mesh.validate(path);
    return mesh;
}

TetMesh tetrahedralize(const tissue::Volume& volume, glm::ivec3 low,
                       std::optional<glm::ivec3> high) {
    const glm::ivec3 n = volume.dims();
    const glm::ivec3 hi = glm::clamp(high.value_or(n - 1), glm::ivec3(0), n - 1);
    low = glm::clamp(low, glm::ivec3(0), n - 1);
    if (glm::any(glm::lessThanEqual(hi, low)))
        throw InputError("tetrahedralize", "box", "needs at least one cell per axis");
    const glm::ivec3 size = hi - low + 1;
    // 6 tetrahedra (16 bytes each) and a point (28 bytes) per voxel: 20 M tetrahedra is
    // ~500 MB, more than a rendering context should take.
    const double tetrahedra = 6.0 * double(size.x - 1) * double(size.y - 1) * double(size.z - 1);
    if (tetrahedra > 20e6)
        throw InputError("tetrahedralize", "box",
                         "would make " + std::to_string(std::llround(tetrahedra / 1e6)) +
                             " M tetrahedra (at most 20 M): use a sub-volume");
    TetMesh mesh;
    auto point_index = [&](int i, int j, int k) {
        return uint32_t((std::size_t(k - low.z) * std::size_t(size.y) + std::size_t(j - low.y)) *
                            std::size_t(size.x) +
                        std::size_t(i - low.x));
    };
    for (int k = low.z; k <= hi.z; ++k)
        for (int j = low.y; j <= hi.y; ++j)
            for (int i = low.x; i <= hi.x; ++i) {
                mesh.points.push_back(volume.geometry().index_to_world(glm::dvec3(i, j, k)));
                mesh.values.push_back(volume.at(i, j, k));
            }
    for (int k = low.z; k < hi.z; ++k)
        for (int j = low.y; j < hi.y; ++j)
            for (int i = low.x; i < hi.x; ++i)
                for (const auto& t : kCellTetrahedra) {
                    std::array<uint32_t, 4> tet{};
                    for (int v = 0; v < 4; ++v) {
                        const int c = t[std::size_t(v)];
                        tet[std::size_t(v)] =
                            point_index(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2));
                    }
                    mesh.tets.push_back(tet);
                }
    return mesh;
}

std::optional<TetCrossing> cross_tetrahedron(const std::array<glm::dvec3, 4>& corners,
                                             const glm::dvec3& origin, const glm::dvec3& dir) {
    const glm::dmat3 m(corners[1] - corners[0], corners[2] - corners[0], corners[3] - corners[0]);
    if (std::abs(glm::determinant(m)) < 1e-12) return std::nullopt;
    return cross_tetrahedron(corners[0], glm::inverse(m), origin, dir);
}

std::optional<TetCrossing> cross_tetrahedron(const glm::dvec3& corner0,
                                             const glm::dmat3& inverse_edges,
                                             const glm::dvec3& origin, const glm::dvec3& dir) {
    // barycentric weights along the ray: lambda_i(t) = a_i + b_i t
    const glm::dvec3 a3 = inverse_edges * (origin - corner0), b3 = inverse_edges * dir;
    const glm::dvec4 a(1.0 - a3.x - a3.y - a3.z, a3.x, a3.y, a3.z);
    const glm::dvec4 b(-b3.x - b3.y - b3.z, b3.x, b3.y, b3.z);
    double t0 = 0.0, t1 = std::numeric_limits<double>::max();
    for (int i = 0; i < 4; ++i) {
        if (std::abs(b[i]) < 1e-15) {
            if (a[i] < 0.0) return std::nullopt;
            continue;
        }
        const double t = -a[i] / b[i];
        if (b[i] > 0.0)
            t0 = std::max(t0, t);
        else
            t1 = std::min(t1, t);
    }
    if (!(t1 > t0)) return std::nullopt;
    TetCrossing c;
    c.t_entry = t0, c.t_exit = t1;
    c.entry_weights = glm::max(a + b * t0, glm::dvec4(0.0));
    c.exit_weights = glm::max(a + b * t1, glm::dvec4(0.0));
    return c;
}

}  // namespace sonotrace::imaging::pbvr
