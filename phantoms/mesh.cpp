#include "phantoms/mesh.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <numbers>
#include <optional>
#include <unordered_map>

#include "phantoms/triangle_overlap.h"
#include "tissue/base/error.h"
#include "tissue/base/isolated.h"
#include "tissue/vtk_legacy.h"

namespace sonotrace::phantoms {

namespace {

using base::InputError;

// The reading child's address space: a file of kMaxMeshFileBytes and the reader's working
// copies fit; a file declaring far more fails its allocation there.
constexpr std::size_t kReaderMemoryBytes = std::size_t(16) << 30;

std::string lower_case(std::string s) {
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// The counts a file declares must fit its size before a reader is trusted with them: a
// binary STL's facet count (84 + 50 n bytes exactly), a PLY header's element counts (each
// element takes at least one byte).
void check_declared_counts(const std::string& path, const std::string& extension,
                           std::uintmax_t bytes) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path, "", "cannot be opened");
    if (extension == ".stl") {
        char head[84] = {};
        in.read(head, sizeof head);
        const bool ascii = in.gcount() >= 5 && std::strncmp(head, "solid", 5) == 0;
        if (in.gcount() < 84) {
            if (!ascii) throw InputError(path, "", "is too short for an STL file");
            return;
        }
        uint32_t facets = 0;
        std::memcpy(&facets, head + 80, 4);
        const std::uintmax_t needed = 84 + 50 * std::uintmax_t(facets);
        // An ASCII file may begin like a binary one's header; only a binary one's size is
        // fixed by its count.
        if (needed != bytes && !ascii)
            throw InputError(path, "facet count",
                             "declares " + std::to_string(facets) + " triangles, which take " +
                                 std::to_string(needed) + " bytes; the file has " +
                                 std::to_string(bytes));
        return;
    }
    if (extension == ".ply") {
        std::string line;
        std::uintmax_t elements = 0;
        for (int n = 0; n < 10000 && std::getline(in, line); ++n) {
            if (line.rfind("end_header", 0) == 0) break;
            if (line.rfind("element ", 0) != 0) continue;
            const auto space = line.rfind(' ');
            const std::string count = line.substr(space + 1);
            char* end = nullptr;
            const unsigned long long value = std::strtoull(count.c_str(), &end, 10);
            if (count.empty() || (*end != '\0' && *end != '\r'))
                throw InputError(path, "element", "count '" + count + "' is not a whole number");
            elements += value;
            if (elements > bytes)
                throw InputError(path, "element",
                                 "the header declares " + std::to_string(elements) +
                                     " elements or more; the file has " + std::to_string(bytes) +
                                     " bytes");
        }
    }
}

// Coincident vertices (equal coordinates, as files repeat them per triangle or per part)
// become one, so that the triangles around an edge share it.
struct VertexKey {
    double x, y, z;
    bool operator==(const VertexKey&) const = default;
};
struct VertexHash {
    std::size_t operator()(const VertexKey& k) const {
        std::size_t h = 0;
        for (double v : {k.x, k.y, k.z}) {
            uint64_t bits = 0;
            v = v == 0.0 ? 0.0 : v;  // -0 and +0 alike
            std::memcpy(&bits, &v, 8);
            h = (h ^ std::hash<uint64_t>()(bits)) * 0x9e3779b97f4a7c15ull;
        }
        return h;
    }
};

// The triangles of every mesh Assimp finds in the file, as written (not merged).
TriangleMesh read_with_assimp(const std::string& path) {
    Assimp::Importer importer;
    // Points and lines are dropped; node transforms are applied to the vertices.
    importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                                aiPrimitiveType_POINT | aiPrimitiveType_LINE);
    const aiScene* scene = importer.ReadFile(
        path, aiProcess_Triangulate | aiProcess_SortByPType | aiProcess_PreTransformVertices);
    if (scene == nullptr)
        throw InputError(path, "",
                         std::string("cannot be read as a mesh: ") + importer.GetErrorString());
    TriangleMesh raw;
    for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
        const aiMesh& part = *scene->mMeshes[m];
        const auto first = uint32_t(raw.vertices.size());
        for (unsigned v = 0; v < part.mNumVertices; ++v)
            raw.vertices.push_back({double(part.mVertices[v].x), double(part.mVertices[v].y),
                                    double(part.mVertices[v].z)});
        for (unsigned f = 0; f < part.mNumFaces; ++f) {
            const aiFace& face = part.mFaces[f];
            if (face.mNumIndices != 3) continue;
            raw.triangles.push_back(
                {first + face.mIndices[0], first + face.mIndices[1], first + face.mIndices[2]});
            if (raw.triangles.size() > kMaxMeshTriangles)
                throw InputError(
                    path, "",
                    "holds more than " + std::to_string(kMaxMeshTriangles) + " triangles");
        }
    }
    if (raw.vertices.size() > 3 * kMaxMeshTriangles)
        throw InputError(path, "",
                         "holds more than " + std::to_string(3 * kMaxMeshTriangles) + " vertices");
    return raw;
}

// read_with_assimp in a child process (base::run_forked): a reader that crashes or runs
// away on a malformed file ends the child, and the caller gets a refusal naming the file.
TriangleMesh read_isolated(const std::string& path) {
    // CPU time for the reader: 2 s, and 1 s a megabyte (Assimp reads ASCII meshes at tens of
    // MB/s); its PLY reader looped for ever on a 342-byte file the fuzzer made.
    std::error_code ignored;
    const auto megabytes = unsigned(std::filesystem::file_size(path, ignored) >> 20);
    const unsigned cpu_seconds = 2 + megabytes;
    TriangleMesh raw;
    uint8_t status = 255;
    std::string source, field, detail;
    bool complete = false;
    const std::optional<std::string> ended = base::run_forked(
        [&](int fd) {
            base::PipeWriter out(fd);
            auto refuse = [&](const std::string& s, const std::string& f, const std::string& d) {
                out.value(uint8_t(1));
                out.text(s), out.text(f), out.text(d);
            };
            try {
                const TriangleMesh m = read_with_assimp(path);
                out.value(uint8_t(0));
                out.value(uint64_t(m.vertices.size()));
                out.bytes(m.vertices.data(), m.vertices.size() * sizeof(glm::dvec3));
                out.value(uint64_t(m.triangles.size()));
                out.bytes(m.triangles.data(), m.triangles.size() * sizeof(m.triangles[0]));
            } catch (const InputError& e) {
                refuse(e.source(), e.field(), e.detail());
            } catch (const std::bad_alloc&) {
                refuse(path, "", "declares more data than memory holds: the file is malformed");
            } catch (const std::exception& e) {
                refuse(path, "", std::string("cannot be read as a mesh: ") + e.what());
            }
        },
        [&](int fd) {
            base::PipeReader in(fd);
            complete = in.value(status);
            if (complete && status == 0) {
                uint64_t vertices = 0, triangles = 0;
                complete = in.value(vertices) && vertices <= 3 * kMaxMeshTriangles;
                if (complete) {
                    raw.vertices.resize(vertices);
                    complete = in.bytes(raw.vertices.data(), vertices * sizeof(glm::dvec3)) &&
                               in.value(triangles) && triangles <= kMaxMeshTriangles;
                }
                if (complete) {
                    raw.triangles.resize(triangles);
                    complete = in.bytes(raw.triangles.data(), triangles * sizeof(raw.triangles[0]));
                }
            } else if (complete && status == 1) {
                complete = in.text(source) && in.text(field) && in.text(detail);
            }
        },
        kReaderMemoryBytes, /*quiet: the reader's own messages are not ours to print*/ true,
        cpu_seconds);
    if (ended && ended->find("CPU time") != std::string::npos)
        throw InputError(path, "",
                         "the mesh reader ran for more than " + std::to_string(cpu_seconds) +
                             " s of CPU time on it: the file is malformed");
    if (!complete || ended || status > 1)
        throw InputError(path, "",
                         "the mesh reader failed on it (" + ended.value_or("exit status 0") +
                             "): the file is malformed");
    if (status == 1) throw InputError(source, field, detail);
    return raw;
}

// The mesh with coincident vertices made one (unused ones dropped).
TriangleMesh merge_coincident(TriangleMesh raw, const std::string& path) {
    if (raw.triangles.empty()) throw InputError(path, "", "holds no triangle");
    TriangleMesh mesh;
    std::unordered_map<VertexKey, uint32_t, VertexHash> index;
    std::vector<uint32_t> merged(raw.vertices.size(), UINT32_MAX);
    for (auto& triangle : raw.triangles) {
        for (uint32_t& k : triangle) {
            if (k >= raw.vertices.size())
                throw InputError(
                    path, "",
                    "a triangle names vertex " + std::to_string(k) + ", which is not there");
            if (merged[k] == UINT32_MAX) {
                const glm::dvec3& p = raw.vertices[k];
                const auto [at, added] =
                    index.emplace(VertexKey{p.x, p.y, p.z}, uint32_t(mesh.vertices.size()));
                if (added) mesh.vertices.push_back(p);
                merged[k] = at->second;
            }
            k = merged[k];
        }
        mesh.triangles.push_back(triangle);
    }
    return mesh;
}

// VTK legacy POLYDATA (tissue/vtk_legacy.h): POINTS, and POLYGONS (fans from each
// polygon's first point) or TRIANGLE_STRIPS; VERTICES and LINES are skipped.
TriangleMesh read_vtk_polydata(const std::string& path) {
    tissue::VtkLegacyStream in(path);
    TriangleMesh mesh;
    auto add = [&](uint32_t a, uint32_t b, uint32_t c, const char* section) {
        mesh.triangles.push_back({a, b, c});
        if (mesh.triangles.size() > kMaxMeshTriangles)
            throw InputError(path, section,
                             "holds more than " + std::to_string(kMaxMeshTriangles) + " triangles");
    };
    // A section of cells: n, the total size, then per cell its point count and indices.
    auto cells = [&](const char* section, auto&& take) {
        const std::size_t n = in.count(section, 4.0, 8.0);
        in.word(section);  // total size
        std::vector<uint32_t> cell;
        for (std::size_t c = 0; c < n; ++c) {
            const auto k = in.number<int64_t>(section, "int");
            if (k < 1 || k > 1000000)
                throw InputError(
                    path, section,
                    "cell " + std::to_string(c) + " has " + std::to_string(k) + " points");
            cell.resize(std::size_t(k));
            for (uint32_t& i : cell) i = in.number<uint32_t>(section, "int");
            take(cell);
        }
        in.section_done();
    };
    bool polydata = false;
    while (const std::optional<std::string> keyword = in.next_keyword()) {
        const std::string& w = *keyword;
        if (w == "DATASET") {
            if (in.word("DATASET") != "POLYDATA")
                throw InputError(path, "DATASET", "a mesh must be POLYDATA");
            polydata = true;
        } else if (w == "POINTS") {
            mesh.vertices = in.points();
        } else if (w == "POLYGONS") {
            cells("POLYGONS", [&](const std::vector<uint32_t>& c) {
                for (std::size_t i = 2; i < c.size(); ++i) add(c[0], c[i - 1], c[i], "POLYGONS");
            });
        } else if (w == "TRIANGLE_STRIPS") {
            cells("TRIANGLE_STRIPS", [&](const std::vector<uint32_t>& c) {
                for (std::size_t i = 2; i < c.size(); ++i)  // every other one turned back
                    if (i % 2 == 0)
                        add(c[i - 2], c[i - 1], c[i], "TRIANGLE_STRIPS");
                    else
                        add(c[i - 1], c[i - 2], c[i], "TRIANGLE_STRIPS");
            });
        } else if (w == "VERTICES" || w == "LINES") {
            cells(w.c_str(), [](const std::vector<uint32_t>&) {});
        } else if (w == "POINT_DATA" || w == "CELL_DATA") {
            break;  // attributes: nothing a shape needs
        }
    }
    if (!polydata) throw InputError(path, "DATASET", "is missing (a mesh must be POLYDATA)");
    return mesh;
}

}  // namespace

TriangleMesh read_mesh_file(const std::string& path) {
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error))
        throw InputError(path, "", "does not exist or is not a file");
    const std::uintmax_t bytes = std::filesystem::file_size(path, error);
    if (error) throw InputError(path, "", "cannot be read: " + error.message());
    if (bytes > kMaxMeshFileBytes)
        throw InputError(path, "",
                         "is " + std::to_string(bytes) + " bytes; at most " +
                             std::to_string(kMaxMeshFileBytes) + " are read");
    const std::string extension = lower_case(std::filesystem::path(path).extension().string());
    if (extension == ".vtk") return merge_coincident(read_vtk_polydata(path), path);
    if (extension != ".stl" && extension != ".obj" && extension != ".ply")
        throw InputError(path, "",
                         "is not a mesh this reads (STL, OBJ, PLY or VTK polydata: .stl, .obj, "
                         ".ply, .vtk)");
    check_declared_counts(path, extension, bytes);
    return merge_coincident(read_isolated(path), path);
}

glm::dvec3 MeshTransform::apply(const glm::dvec3& p) const {
    glm::dvec3 q = p * scale;
    const glm::dvec3 r = glm::radians(rotate_deg);
    auto turn = [](double& a, double& b, double angle) {
        const double c = std::cos(angle), s = std::sin(angle);
        const double u = c * a - s * b, v = s * a + c * b;
        a = u, b = v;
    };
    turn(q.y, q.z, r.x);  // about x
    turn(q.z, q.x, r.y);  // about y
    turn(q.x, q.y, r.z);  // about z
    return q + translate_mm;
}

namespace {

// The point of triangle abc nearest to p (Ericson, Real-Time Collision Detection, 5.1.5)
// and the feature it lies on: 0-2 vertex a, b, c; 3-5 edge ab, bc, ca; 6 the face.
struct Nearest {
    glm::dvec3 point;
    int feature;
};
Nearest nearest_on_triangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b,
                            const glm::dvec3& c) {
    const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return {a, 0};
    const glm::dvec3 bp = p - b;
    const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) return {b, 1};
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return {a + ab * (d1 / (d1 - d3)), 3};
    const glm::dvec3 cp = p - c;
    const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) return {c, 2};
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return {a + ac * (d2 / (d2 - d6)), 5};
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0)
        return {b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), 4};
    const double denominator = 1.0 / (va + vb + vc);
    return {a + ab * (vb * denominator) + ac * (vc * denominator), 6};
}

double box_distance2(const glm::dvec3& p, const glm::dvec3& lower, const glm::dvec3& upper) {
    const glm::dvec3 d = glm::max(glm::max(lower - p, p - upper), glm::dvec3(0.0));
    return glm::dot(d, d);
}

uint64_t edge_key(uint32_t from, uint32_t to) {
    return uint64_t(from) << 32 | to;
}

constexpr uint32_t kLeafTriangles = 4;

}  // namespace

MeshShape::MeshShape(TriangleMesh mesh, const std::string& source) : mesh_(std::move(mesh)) {
    const auto& v = mesh_.vertices;
    auto& triangles = mesh_.triangles;
    if (triangles.empty()) throw InputError(source, "", "holds no triangle");
    if (triangles.size() > kMaxMeshTriangles)
        throw InputError(source, "",
                         "holds more than " + std::to_string(kMaxMeshTriangles) + " triangles");
    lower_ = glm::dvec3(std::numeric_limits<double>::infinity());
    upper_ = -lower_;
    for (std::size_t i = 0; i < v.size(); ++i) {
        if (!(std::isfinite(v[i].x) && std::isfinite(v[i].y) && std::isfinite(v[i].z)))
            throw InputError(source, "vertex " + std::to_string(i), "is not finite");
        lower_ = glm::min(lower_, v[i]), upper_ = glm::max(upper_, v[i]);
    }
    const double size = glm::length(upper_ - lower_);
    // Which triangle runs each directed edge: a closed, consistently oriented surface runs
    // every edge once each way.
    std::unordered_map<uint64_t, uint32_t> runs;
    runs.reserve(triangles.size() * 3);
    for (std::size_t t = 0; t < triangles.size(); ++t) {
        const auto& tri = triangles[t];
        const std::string name = "triangle " + std::to_string(t);
        for (uint32_t k : tri)
            if (k >= v.size()) throw InputError(source, name, "names a vertex that is not there");
        const double area2 = glm::length(glm::cross(v[tri[1]] - v[tri[0]], v[tri[2]] - v[tri[0]]));
        if (!(area2 > 1e-12 * size * size))
            throw InputError(source, name, "has zero area (degenerate)");
        for (int e = 0; e < 3; ++e) {
            const uint32_t a = tri[std::size_t(e)], b = tri[std::size_t((e + 1) % 3)];
            if (!runs.emplace(edge_key(a, b), uint32_t(t)).second)
                throw InputError(source, name,
                                 "runs the edge from vertex " + std::to_string(a) + " to " +
                                     std::to_string(b) +
                                     " the same way as another triangle: the surface is not "
                                     "consistently oriented, or more than two triangles meet "
                                     "at that edge");
        }
    }
    for (const auto& [key, t] : runs)
        if (!runs.contains(edge_key(uint32_t(key & 0xffffffffu), uint32_t(key >> 32))))
            throw InputError(source, "triangle " + std::to_string(t),
                             "has an edge (vertices " + std::to_string(key >> 32) + " and " +
                                 std::to_string(key & 0xffffffffu) +
                                 ") no other triangle shares: the surface is not closed");
    // The enclosed volume (divergence theorem); wound inwards, it comes out negative.
    double volume = 0.0;
    for (const auto& tri : triangles)
        volume += glm::dot(v[tri[0]], glm::cross(v[tri[1]], v[tri[2]])) / 6.0;
    if (!(std::abs(volume) > 1e-9 * size * size * size))
        throw InputError(source, "", "encloses no volume");
    if (volume < 0.0) {
        for (auto& tri : triangles) std::swap(tri[1], tri[2]);
        volume = -volume;
    }
    volume_ = volume;

    // Pseudo-normals: faces, vertices by angle, edges as the sum of their two faces.
    face_normal_.resize(triangles.size());
    vertex_normal_.assign(v.size(), glm::dvec3(0.0));
    for (std::size_t t = 0; t < triangles.size(); ++t) {
        const auto& tri = triangles[t];
        const glm::dvec3 n =
            glm::normalize(glm::cross(v[tri[1]] - v[tri[0]], v[tri[2]] - v[tri[0]]));
        face_normal_[t] = n;
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3& at = v[tri[std::size_t(k)]];
            const glm::dvec3 u = glm::normalize(v[tri[std::size_t((k + 1) % 3)]] - at);
            const glm::dvec3 w = glm::normalize(v[tri[std::size_t((k + 2) % 3)]] - at);
            vertex_normal_[tri[std::size_t(k)]] +=
                std::acos(std::clamp(glm::dot(u, w), -1.0, 1.0)) * n;
        }
    }
    runs.clear();
    for (std::size_t t = 0; t < triangles.size(); ++t)
        for (int e = 0; e < 3; ++e)
            runs.emplace(
                edge_key(triangles[t][std::size_t(e)], triangles[t][std::size_t((e + 1) % 3)]),
                uint32_t(t));
    edge_normal_.resize(triangles.size());
    for (std::size_t t = 0; t < triangles.size(); ++t)
        for (int e = 0; e < 3; ++e) {
            const uint32_t a = triangles[t][std::size_t(e)],
                           b = triangles[t][std::size_t((e + 1) % 3)];
            edge_normal_[t][std::size_t(e)] =
                face_normal_[t] + face_normal_[runs.at(edge_key(b, a))];
        }

    // The hierarchy: median splits along the longest axis of the triangles' centres.
    std::vector<glm::dvec3> centres(triangles.size());
    for (std::size_t t = 0; t < triangles.size(); ++t)
        centres[t] = (v[triangles[t][0]] + v[triangles[t][1]] + v[triangles[t][2]]) / 3.0;
    order_.resize(triangles.size());
    for (std::size_t t = 0; t < order_.size(); ++t) order_[t] = uint32_t(t);
    nodes_.reserve(2 * triangles.size() / kLeafTriangles + 1);
    build(0, uint32_t(triangles.size()), centres);
    require_no_crossing(source);
}

void MeshShape::require_no_crossing(const std::string& source) const {
    const auto& v = mesh_.vertices;
    const auto& triangles = mesh_.triangles;
    const double touch = 1e-9 * glm::length(upper_ - lower_);
    auto boxes_meet = [](const Node& a, const Node& b) {
        return glm::all(glm::lessThanEqual(a.lower, b.upper)) &&
               glm::all(glm::lessThanEqual(b.lower, a.upper));
    };
    auto corners = [&](uint32_t t) {
        return Triangle{v[triangles[t][0]], v[triangles[t][1]], v[triangles[t][2]]};
    };
    // The hierarchy against itself: pairs of nodes whose boxes meet, the larger split
    // first, down to pairs of leaves.
    auto volume = [](const Node& n) {
        const glm::dvec3 e = n.upper - n.lower;
        return e.x * e.y * e.z;
    };
    std::vector<std::pair<uint32_t, uint32_t>> pairs = {{0, 0}};
    while (!pairs.empty()) {
        const auto [i, j] = pairs.back();
        pairs.pop_back();
        const Node& a = nodes_[i];
        const Node& b = nodes_[j];
        if (i == j && a.count == 0) {
            pairs.insert(pairs.end(), {{a.left, a.left}, {a.right, a.right}, {a.left, a.right}});
            continue;
        }
        if (i != j && !boxes_meet(a, b)) continue;
        if (i != j && a.count == 0 && (b.count > 0 || volume(a) >= volume(b))) {
            pairs.insert(pairs.end(), {{a.left, j}, {a.right, j}});
            continue;
        }
        if (i != j && b.count == 0) {
            pairs.insert(pairs.end(), {{i, b.left}, {i, b.right}});
            continue;
        }
        for (uint32_t p = a.first; p < a.first + a.count; ++p)
            for (uint32_t q = i == j ? p + 1 : b.first; q < b.first + b.count; ++q) {
                const uint32_t s = order_[p], t = order_[q];
                const auto& x = triangles[s];
                const auto& y = triangles[t];
                bool shared = false;
                for (uint32_t m : x) shared = shared || m == y[0] || m == y[1] || m == y[2];
                if (shared || !triangles_cross(corners(s), corners(t), touch)) continue;
                throw InputError(source, "triangle " + std::to_string(std::min(s, t)),
                                 "crosses triangle " + std::to_string(std::max(s, t)) +
                                     ": the surface intersects itself, so some points are "
                                     "inside it twice or inside out");
            }
    }
}

uint32_t MeshShape::build(uint32_t first, uint32_t count, const std::vector<glm::dvec3>& centres) {
    const uint32_t at = uint32_t(nodes_.size());
    nodes_.emplace_back();
    glm::dvec3 lower(std::numeric_limits<double>::infinity()), upper = -lower;
    glm::dvec3 centre_lower = lower, centre_upper = upper;
    for (uint32_t i = first; i < first + count; ++i) {
        const auto& tri = mesh_.triangles[order_[i]];
        for (uint32_t k : tri)
            lower = glm::min(lower, mesh_.vertices[k]), upper = glm::max(upper, mesh_.vertices[k]);
        centre_lower = glm::min(centre_lower, centres[order_[i]]);
        centre_upper = glm::max(centre_upper, centres[order_[i]]);
    }
    nodes_[at].lower = lower, nodes_[at].upper = upper;
    if (count <= kLeafTriangles) {
        nodes_[at].first = first, nodes_[at].count = count;
        return at;
    }
    const glm::dvec3 extent = centre_upper - centre_lower;
    const int axis =
        extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
    const uint32_t half = count / 2;
    std::nth_element(order_.begin() + first, order_.begin() + first + half,
                     order_.begin() + first + count, [&](uint32_t a, uint32_t b) {
                         return centres[a][axis] < centres[b][axis] ||
                                (centres[a][axis] == centres[b][axis] && a < b);
                     });
    const uint32_t left = build(first, half, centres);
    const uint32_t right = build(first + half, count - half, centres);
    nodes_[at].left = left, nodes_[at].right = right;
    return at;
}

double MeshShape::distance_to_bounds(const glm::dvec3& p) const {
    return std::sqrt(box_distance2(p, lower_, upper_));
}

double MeshShape::signed_distance(const glm::dvec3& p) const {
    double best = std::numeric_limits<double>::infinity();
    glm::dvec3 best_point(0.0), best_normal(0.0);
    uint32_t stack[64];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const Node& node = nodes_[stack[--top]];
        if (box_distance2(p, node.lower, node.upper) >= best) continue;
        if (node.count > 0) {
            for (uint32_t i = node.first; i < node.first + node.count; ++i) {
                const uint32_t t = order_[i];
                const auto& tri = mesh_.triangles[t];
                const Nearest q = nearest_on_triangle(
                    p, mesh_.vertices[tri[0]], mesh_.vertices[tri[1]], mesh_.vertices[tri[2]]);
                const glm::dvec3 d = p - q.point;
                const double d2 = glm::dot(d, d);
                if (d2 >= best) continue;
                best = d2, best_point = q.point;
                best_normal = q.feature < 3   ? vertex_normal_[tri[std::size_t(q.feature)]]
                              : q.feature < 6 ? edge_normal_[t][std::size_t(q.feature - 3)]
                                              : face_normal_[t];
            }
            continue;
        }
        // The nearer child last, so that it is searched first.
        const Node& l = nodes_[node.left];
        const Node& r = nodes_[node.right];
        const bool left_nearer =
            box_distance2(p, l.lower, l.upper) <= box_distance2(p, r.lower, r.upper);
        stack[top++] = left_nearer ? node.right : node.left;
        stack[top++] = left_nearer ? node.left : node.right;
    }
    const double distance = std::sqrt(best);
    return glm::dot(p - best_point, best_normal) >= 0.0 ? distance : -distance;
}

}  // namespace sonotrace::phantoms
