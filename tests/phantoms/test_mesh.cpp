// Closed triangle meshes as phantom shapes (phantoms/mesh.h): an icosphere the test writes
// as STL, OBJ and PLY against the sphere it approximates, nested meshes, the transform,
// and the refusals of bad meshes, each naming the file.
//
// The reference: an icosphere's vertices lie on the sphere of radius R, so the polyhedron
// P holds the ball of its inradius r (the smallest distance from the centre to a face
// plane, computed here from the written triangles) and lies in the ball of radius R.
// Signed distance grows as the set shrinks, so for every point p:
//   |p - c| - R  <=  d_P(p)  <=  |p - c| - r.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "phantoms/mesh.h"
#include "phantoms/phantom.h"
#include "phantoms/triangle_overlap.h"
#include "tests/phantoms/meshes_for_tests.h"
#include "tests/test_util.h"
#include "tissue/base/error.h"
#include "tissue/tissue_table.h"

namespace sonotrace {
namespace {

using phantoms::TriangleMesh;
using test::icosphere;
using test::inradius;
using test::write_obj;
using test::write_ply;
using test::write_stl;
using test::write_vtk;

// The distance from p to the nearest triangle, by brute force over all of them and a
// different construction from the shape's: the foot of the perpendicular on the plane if
// it falls inside the triangle (barycentric signs), else the nearest of the three edges.
double brute_distance(const TriangleMesh& m, const glm::dvec3& p) {
    auto to_segment = [&](const glm::dvec3& a, const glm::dvec3& b) {
        const double t = std::clamp(glm::dot(p - a, b - a) / glm::dot(b - a, b - a), 0.0, 1.0);
        return glm::length(p - (a + t * (b - a)));
    };
    double best = 1e30;
    for (const auto& t : m.triangles) {
        const glm::dvec3 &a = m.vertices[t[0]], &b = m.vertices[t[1]], &c = m.vertices[t[2]];
        const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
        const glm::dvec3 foot = p - glm::dot(p - a, n) * n;
        const bool inside = glm::dot(glm::cross(b - a, foot - a), n) >= 0.0 &&
                            glm::dot(glm::cross(c - b, foot - b), n) >= 0.0 &&
                            glm::dot(glm::cross(a - c, foot - c), n) >= 0.0;
        const double d = inside ? std::abs(glm::dot(p - a, n))
                                : std::min({to_segment(a, b), to_segment(b, c), to_segment(c, a)});
        best = std::min(best, d);
    }
    return best;
}

// A prism of length 10 mm along z over the triangle (0,0), (10,0), (0,3): an edge of 16.7
// degrees, where the sign taken from either face alone goes wrong beside it.
TriangleMesh thin_prism() {
    TriangleMesh m;
    const glm::dvec2 corner[3] = {{0, 0}, {10, 0}, {0, 3}};  // counter-clockwise
    for (double z : {0.0, 10.0})
        for (const auto& q : corner) m.vertices.push_back({q.x, q.y, z});
    m.triangles = {{0, 2, 1}, {3, 4, 5}};  // the ends, facing -z and +z
    for (uint32_t k = 0; k < 3; ++k) {     // the sides, outwards
        const uint32_t next = (k + 1) % 3;
        m.triangles.push_back({k, next, next + 3});
        m.triangles.push_back({k, next + 3, k + 3});
    }
    return m;
}

TEST(Mesh, SignAndDistanceAgreeWithBruteForceBesideASharpEdge) {
    const TriangleMesh prism = thin_prism();
    const phantoms::MeshShape shape(prism, "prism");
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> x(-2.0, 14.0), y(-2.0, 5.0), z(-2.0, 12.0);
    int outside = 0, inside = 0;
    for (int n = 0; n < 20000; ++n) {
        // Half the points within 0.5 mm of the sharp edge along z at (10, 0).
        glm::dvec3 p(x(rng), y(rng), z(rng));
        if (n % 2 == 0)
            p = glm::dvec3(10.0 + 0.25 * (x(rng) - 6.0) / 8.0, 0.25 * (y(rng) - 1.5) / 3.5, p.z);
        const bool in = p.z > 0.0 && p.z < 10.0 && p.x > 0.0 && p.y > 0.0 && 0.3 * p.x + p.y < 3.0;
        const double d = shape.signed_distance(p), expected = brute_distance(prism, p);
        if (expected < 1e-9) continue;
        ASSERT_NEAR(std::abs(d), expected, 1e-9) << n;
        ASSERT_EQ(d < 0.0, in) << n << ": " << p.x << ", " << p.y << ", " << p.z;
        (in ? inside : outside)++;
    }
    EXPECT_GT(inside, 500);
    EXPECT_GT(outside, 5000);
}

// d_P between the two balls' distances at 20,000 points (fixed seed) around c, within
// `slack` (the file's rounding of the coordinates).
void expect_between_the_balls(const phantoms::MeshShape& shape, const TriangleMesh& m, glm::dvec3 c,
                              double R, double slack) {
    const double r = inradius(m, c);
    ASSERT_LT(R - r, 0.01 * R);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-2.0 * R, 2.0 * R);
    int inside = 0;
    for (int n = 0; n < 20000; ++n) {
        const glm::dvec3 p = c + glm::dvec3(u(rng), u(rng), u(rng));
        const double d = shape.signed_distance(p), radial = glm::length(p - c);
        ASSERT_GE(d, radial - R - slack) << n;
        ASSERT_LE(d, radial - r + slack) << n;
        inside += d < 0.0;
    }
    // About the ball's share of the cube, 4/3 pi / 64 = 6.5 %.
    EXPECT_NEAR(inside / 20000.0, 4.0 / 3.0 * std::numbers::pi / 64.0, 0.01);
}

TEST(Mesh, AnIcosphereLiesBetweenItsInnerAndOuterBallsInEveryFormat) {
    test::ScratchDir dir;
    const glm::dvec3 c(20.0, 15.0, 5.0);
    const double R = 6.0;
    const TriangleMesh sphere = icosphere(4, R, c);  // 5,120 triangles
    struct Format {
        const char* file;
        void (*write)(const TriangleMesh&, const std::string&);
        double slack;  // Assimp reads coordinates in single precision, VTK in double
    };
    for (const Format& f :
         {Format{"ico.stl", write_stl, 1e-5}, Format{"ico.obj", write_obj, 1e-5},
          Format{"ico.ply", write_ply, 1e-5}, Format{"ico.vtk", write_vtk, 1e-9}}) {
        SCOPED_TRACE(f.file);
        f.write(sphere, dir / f.file);
        TriangleMesh read = phantoms::read_mesh_file(dir / f.file);
        EXPECT_EQ(read.vertices.size(), sphere.vertices.size());  // shared corners merged
        EXPECT_EQ(read.triangles.size(), sphere.triangles.size());
        const phantoms::MeshShape shape(std::move(read), dir / f.file);
        expect_between_the_balls(shape, sphere, c, R, f.slack);
        std::mt19937 rng(3);
        std::uniform_real_distribution<double> u(-1.5 * R, 1.5 * R);
        for (int n = 0; n < 300; ++n) {
            const glm::dvec3 p = c + glm::dvec3(u(rng), u(rng), u(rng));
            ASSERT_NEAR(std::abs(shape.signed_distance(p)), brute_distance(sphere, p), f.slack)
                << n;
        }
        const double r = inradius(sphere, c);
        EXPECT_GT(shape.volume_mm3(), 4.0 / 3.0 * std::numbers::pi * r * r * r);
        EXPECT_LT(shape.volume_mm3(), 4.0 / 3.0 * std::numbers::pi * R * R * R);
    }
}

TEST(Mesh, AMeshWoundInwardsIsTurnedOutwards) {
    TriangleMesh inward = icosphere(2, 3.0);
    for (auto& t : inward.triangles) std::swap(t[1], t[2]);
    const phantoms::MeshShape shape(inward, "inward");
    EXPECT_LT(shape.signed_distance({0, 0, 0}), -2.9);
    EXPECT_NEAR(shape.signed_distance({5, 0, 0}), 2.0, 0.1);
    EXPECT_GT(shape.volume_mm3(), 0.0);
}

// A phantom with the icosphere, a nested one of another tissue inside it, against the
// same phantom of analytic spheres: the labels agree except within the faceting (R - r)
// plus one texel of a boundary.
TEST(Mesh, NestedMeshesRasteriseAsTheirSpheresExceptAtBoundaries) {
    test::ScratchDir dir;
    const glm::dvec3 c(20.0, 20.0, 5.0);
    write_obj(icosphere(4, 8.0, c), dir / "outer.obj");
    // The inner one in other units and frame: metres about the origin, placed by the
    // transform.
    write_stl(icosphere(4, 0.004), dir / "inner.stl");
    auto phantom_json = [&](bool meshes) {
        nlohmann::json outer = {{"tissue", "liver"}}, inner = {{"tissue", "blood"}};
        if (meshes) {
            outer.update({{"type", "mesh"}, {"file", "outer.obj"}});
            inner.update({{"type", "mesh"},
                          {"file", "inner.stl"},
                          {"scale", 1000},
                          {"rotate", {30, 10, 0}},
                          {"translate", {c.x, c.y, c.z}}});
        } else {
            outer.update({{"type", "sphere"}, {"centre", {c.x, c.y, c.z}}, {"radius", 8.0}});
            inner.update({{"type", "sphere"}, {"centre", {c.x, c.y, c.z}}, {"radius", 4.0}});
        }
        return nlohmann::json{{"name", "nested"},
                              {"size", {40, 40, 10}},
                              {"resolution", 0.25},
                              {"smoothing", 0.0},
                              {"background", {{"tissue", "fat"}}},
                              {"shapes", {outer, inner}}};
    };
    auto labels_of = [&](bool meshes) {
        const std::string path = dir / (meshes ? "meshes.json" : "spheres.json");
        std::ofstream(path) << phantom_json(meshes).dump();
        const phantoms::Phantom ph = phantoms::load_phantom(path);
        tissue::Volume labels;
        phantoms::rasterise(ph, phantoms::plane_grid_2d(ph), &labels);
        return labels;
    };
    const tissue::Volume meshes = labels_of(true), spheres = labels_of(false);
    const int fat = tissue::tissue_label_of("fat"), liver = tissue::tissue_label_of("liver"),
              blood = tissue::tissue_label_of("blood");
    ASSERT_EQ(meshes.dims(), spheres.dims());
    int differ = 0, counted[3] = {0, 0, 0};
    const double h = 0.25, faceting = 8.0 - inradius(icosphere(4, 8.0), glm::dvec3(0.0));
    for (int j = 0; j < meshes.dims().y; ++j)
        for (int i = 0; i < meshes.dims().x; ++i) {
            const double radial = glm::length(glm::dvec2(i * h, j * h) - glm::dvec2(c.x, c.y));
            const int label = int(meshes.at(i, j, 0));
            counted[label == fat ? 0 : label == liver ? 1 : label == blood ? 2 : 0]++;
            if (label == int(spheres.at(i, j, 0))) continue;
            ++differ;
            const double from_boundary = std::min(std::abs(radial - 8.0), std::abs(radial - 4.0));
            EXPECT_LE(from_boundary, faceting + h) << i << ", " << j;
        }
    EXPECT_LT(differ, 40);
    EXPECT_GT(counted[1], 1000);                  // liver between the surfaces
    EXPECT_GT(counted[2], 500);                   // blood inside the inner one
    EXPECT_EQ(int(meshes.at(80, 80, 0)), blood);  // the centre
    EXPECT_EQ(int(meshes.at(80, 56, 0)), liver);  // 6 mm off it
    EXPECT_EQ(int(meshes.at(2, 2, 0)), fat);
}

// Each refusal names the mesh file and says what is wrong.
// The separating-axis test against the definition for triangles in general position: two
// triangles meet exactly when an edge of one passes through the other (segment against
// triangle by solving a + u (b - a) + v (c - a) = p + t (q - p), Cramer's rule). 4,000
// random pairs in a 2 mm cube (fixed seed), about half of them crossing.
TEST(Mesh, TrianglesCrossExactlyWhenAnEdgePiercesTheOther) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> coordinate(-1.0, 1.0);
    auto random_triangle = [&] {
        phantoms::Triangle t;
        for (auto& p : t) p = {coordinate(rng), coordinate(rng), coordinate(rng)};
        return t;
    };
    auto pierces = [](const glm::dvec3& p, const glm::dvec3& q, const phantoms::Triangle& t) {
        const glm::dmat3 m(t[1] - t[0], t[2] - t[0], p - q);
        const double det = glm::determinant(m);
        if (std::abs(det) < 1e-14) return false;
        const glm::dvec3 x = glm::inverse(m) * (p - t[0]);  // (u, v, s)
        return x.x >= 0 && x.y >= 0 && x.x + x.y <= 1 && x.z >= 0 && x.z <= 1;
    };
    int crossing = 0;
    for (int n = 0; n < 4000; ++n) {
        const phantoms::Triangle a = random_triangle(), b = random_triangle();
        bool expected = false;
        for (int k = 0; k < 3; ++k)
            expected = expected || pierces(a[std::size_t(k)], a[std::size_t((k + 1) % 3)], b) ||
                       pierces(b[std::size_t(k)], b[std::size_t((k + 1) % 3)], a);
        ASSERT_EQ(phantoms::triangles_cross(a, b, 0.0), expected) << n;
        crossing += expected;
    }
    EXPECT_GT(crossing, 400);
    EXPECT_LT(crossing, 3600);
}

// rasterise keeps a mesh's weight along a row while the row stays within the distance it
// is steady over; that must change nothing: every texel equals Phantom::at at its centre,
// bit for bit (the mesh abdomen of the gallery, on a tilted grid so that rows run
// obliquely through the organs, and with no smoothing).
TEST(Mesh, RasterisedRowsEqualThePhantomAtEveryTexel) {
    for (const double smoothing : {-1.0, 0.0}) {
        phantoms::Phantom phantom =
            phantoms::load_phantom(SONOTRACE_SOURCE_DIR "/phantoms/abdomen_meshes.json");
        if (smoothing >= 0.0) phantom.smoothing_mm = smoothing;
        tissue::VolumeGeometry grid;
        grid.dims = {170, 60, 3};
        grid.spacing = {0.9, 1.3, 7.0};
        grid.origin = {-2.0, 20.0, 22.0};
        const double a = 0.3;  // rows turned in the x-y plane
        grid.direction =
            glm::dmat3(glm::dvec3(std::cos(a), std::sin(a), 0.0),
                       glm::dvec3(-std::sin(a), std::cos(a), 0.0), glm::dvec3(0.0, 0.0, 1.0));
        tissue::Volume labels, instances;
        const tissue::PropertyMaps maps = phantoms::rasterise(phantom, grid, &labels, &instances);
        int inside = 0;
        for (int k = 0; k < grid.dims.z; ++k)
            for (int j = 0; j < grid.dims.y; ++j)
                for (int i = 0; i < grid.dims.x; ++i) {
                    int label = 0, instance = 0;
                    const tissue::AcousticProperties p = phantom.at(
                        grid.index_to_world({double(i), double(j), double(k)}), &label, &instance);
                    for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                        ASSERT_EQ(maps.fields[f].at(i, j, k), p.values[f]) << i << " " << j;
                    ASSERT_EQ(labels.at(i, j, k), float(label));
                    ASSERT_EQ(instances.at(i, j, k), float(instance));
                    inside += instance >= 3;  // the mesh organs
                }
        EXPECT_GT(inside, 1000);
    }
}

TEST(Mesh, BadMeshesAreRefusedNamingTheFile) {
    test::ScratchDir dir;
    const TriangleMesh good = icosphere(1, 5.0);
    auto refused = [&](const std::string& name, const std::string& text) {
        const std::string message = test::input_error_message(
            [&] { phantoms::MeshShape(phantoms::read_mesh_file(dir / name), dir / name); });
        EXPECT_NE(message.find(dir / name), std::string::npos) << message;
        EXPECT_NE(message.find(text), std::string::npos) << message;
    };
    TriangleMesh open = good;
    open.triangles.pop_back();
    write_obj(open, dir / "open.obj");
    refused("open.obj", "the surface is not closed");
    TriangleMesh flipped = good;
    std::swap(flipped.triangles[3][1], flipped.triangles[3][2]);
    write_obj(flipped, dir / "flipped.obj");
    refused("flipped.obj", "not consistently oriented");
    TriangleMesh flat = good;
    flat.vertices.push_back(flat.vertices[flat.triangles[0][0]]);  // a repeated corner
    flat.triangles.push_back(
        {flat.triangles[0][0], flat.triangles[0][1], uint32_t(flat.vertices.size() - 1)});
    write_obj(flat, dir / "flat.obj");
    refused("flat.obj", "zero area");
    // Two spheres in one file: apart (one inside the other, as a vessel in an organ) they
    // are a sound surface; overlapping, the surface crosses itself.
    auto two_spheres = [&](const glm::dvec3& offset, const std::string& name) {
        TriangleMesh both = good;
        const TriangleMesh other = icosphere(1, 3.0, offset);
        const auto base = uint32_t(both.vertices.size());
        both.vertices.insert(both.vertices.end(), other.vertices.begin(), other.vertices.end());
        for (auto t : other.triangles)
            both.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
        write_obj(both, dir / name);
    };
    two_spheres(glm::dvec3(6.0, 0.0, 0.0), "crossing.obj");
    refused("crossing.obj", "the surface intersects itself");
    two_spheres(glm::dvec3(9.0, 0.0, 0.0), "apart.obj");
    EXPECT_NO_THROW(phantoms::MeshShape(phantoms::read_mesh_file(dir / "apart.obj"), "apart.obj"));
    refused("missing.stl", "does not exist");
    std::ofstream(dir / "mesh.off") << "OFF\n";
    refused("mesh.off", "STL, OBJ, PLY or VTK polydata");
    std::ofstream(dir / "huge.vtk") << "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\n"
                                       "POINTS 1000000000 float\n0 0 0\n";
    refused("huge.vtk", "declares 1000000000 items");
    std::ofstream(dir / "grid.vtk") << "# vtk DataFile Version 3.0\nx\nASCII\n"
                                       "DATASET UNSTRUCTURED_GRID\n";
    refused("grid.vtk", "a mesh must be POLYDATA");
    {  // a binary STL declaring four billion triangles in 134 bytes
        std::ofstream out(dir / "huge.stl", std::ios::binary);
        const std::string header(80, 'x');
        out.write(header.data(), 80);
        const uint32_t n = 4000000000u;
        out.write(reinterpret_cast<const char*>(&n), 4);
        out << std::string(50, '\0');
    }
    refused("huge.stl", "declares 4000000000 triangles");
    std::ofstream(dir / "huge.ply") << "ply\nformat ascii 1.0\nelement vertex 999999999999\n"
                                       "property float x\nend_header\n0\n";
    refused("huge.ply", "declares 999999999999 elements");
    std::ofstream(dir / "garbage.obj") << "this is not a mesh\n\x01\x02\n";
    refused("garbage.obj", "garbage.obj");
    // Assimp's PLY reader loops for ever on this file (found by fuzz_mesh): its CPU limit
    // ends it.
    std::filesystem::copy_file(SONOTRACE_SOURCE_DIR "/tests/fuzz/seeds/mesh/ply_reader_loops.ply",
                               dir / "loops.ply");
    refused("loops.ply", "s of CPU time on it: the file is malformed");
    TriangleMesh nan_vertex = good;
    nan_vertex.vertices[2].y = std::nan("");
    const std::string message =
        test::input_error_message([&] { phantoms::MeshShape(nan_vertex, "nan.obj"); });
    EXPECT_NE(message.find("nan.obj"), std::string::npos) << message;
    EXPECT_NE(message.find("vertex 2"), std::string::npos) << message;
    EXPECT_NE(message.find("not finite"), std::string::npos) << message;
}

// The transform's order: scale, rotate about x, y, z in turn, then translate. A box
// 4 x 2 x 1 turned 90 degrees about z spans 2 x 4 x 1.
TEST(Mesh, TheTransformScalesRotatesThenTranslates) {
    phantoms::MeshTransform place;
    place.scale = {2.0, 2.0, 2.0};
    place.rotate_deg = {0.0, 0.0, 90.0};
    place.translate_mm = {10.0, 0.0, 0.0};
    const glm::dvec3 p = place.apply({1.0, 0.0, 0.0});  // -> (2,0,0) -> (0,2,0) -> (10,2,0)
    EXPECT_NEAR(p.x, 10.0, 1e-12);
    EXPECT_NEAR(p.y, 2.0, 1e-12);
    EXPECT_NEAR(p.z, 0.0, 1e-12);
    place = {};
    place.rotate_deg = {90.0, 0.0, 0.0};  // y -> z
    const glm::dvec3 q = place.apply({0.0, 1.0, 0.0});
    EXPECT_NEAR(q.z, 1.0, 1e-12);
    place.rotate_deg = {0.0, 90.0, 0.0};  // z -> x
    const glm::dvec3 s = place.apply({0.0, 0.0, 1.0});
    EXPECT_NEAR(s.x, 1.0, 1e-12);
}

}  // namespace
}  // namespace sonotrace
