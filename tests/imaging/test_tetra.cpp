// Tetrahedral meshes and image-space PBVR: ray-tetrahedron clipping, the regular-grid
// split, the VTK reader, convergence to the ray integral for one tetrahedron and one
// hexahedral cell (at 1 / N in squared error, its fragments stratified across
// repetitions, and unbiased), and the paper's figure 3 comparison of the five depth modes.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <random>

#include "imaging/pbvr/pbvr.h"
#include "imaging/pbvr/tetra.h"
#include "tests/imaging/pbvr_test_volumes.h"
#include "tests/test_util.h"

namespace sonotrace::imaging::pbvr {
namespace {

double tet_volume(const TetMesh& m, const std::array<uint32_t, 4>& t) {
    const glm::dvec3 a = m.points[t[0]];
    return std::abs(glm::determinant(
               glm::dmat3(m.points[t[1]] - a, m.points[t[2]] - a, m.points[t[3]] - a))) /
           6.0;
}

TEST(Tetra, RayClippingGivesEntryExitAndWeights) {
    const std::array<glm::dvec3, 4> c = {glm::dvec3(0, 0, 0), glm::dvec3(1, 0, 0),
                                         glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)};
    const auto hit = cross_tetrahedron(c, {0.2, 0.2, -1.0}, {0.0, 0.0, 1.0});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t_entry, 1.0, 1e-12);  // the face z = 0
    EXPECT_NEAR(hit->t_exit, 1.6, 1e-12);   // the face x + y + z = 1
    EXPECT_NEAR(hit->entry_weights[0], 0.6, 1e-12);
    EXPECT_NEAR(hit->entry_weights[1], 0.2, 1e-12);
    EXPECT_NEAR(hit->exit_weights[3], 0.6, 1e-12);
    EXPECT_FALSE(cross_tetrahedron(c, {0.8, 0.8, -1.0}, {0.0, 0.0, 1.0}));  // misses
    EXPECT_FALSE(cross_tetrahedron(c, {0.2, 0.2, 2.0}, {0.0, 0.0, 1.0}));   // behind the origin
}

TEST(Tetra, RegularGridSplitConformsAndInterpolatesLinearFields) {
    tissue::VolumeGeometry g;
    g.dims = {4, 3, 3};
    g.spacing = {0.5, 1.0, 2.0};
    g.origin = {10.0, 0.0, -3.0};
    tissue::Volume v(g);
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 4; ++i) {
                const glm::dvec3 w = g.index_to_world({i, j, k});
                v.at(i, j, k) = float(w.x + 2.0 * w.y + 3.0 * w.z);
            }
    const TetMesh mesh = tetrahedralize(v);
    EXPECT_EQ(mesh.tets.size(), 3u * 2u * 2u * 6u);
    double total = 0.0;
    for (const auto& t : mesh.tets) {
        EXPECT_GT(tet_volume(mesh, t), 1e-9);
        total += tet_volume(mesh, t);
    }
    EXPECT_NEAR(total, 1.5 * 2.0 * 4.0, 1e-9);  // the box, covered once
    // A sub-box, and a refusal for volumes that would not fit in memory.
    EXPECT_EQ(tetrahedralize(v, {1, 0, 0}, glm::ivec3(2, 1, 1)).tets.size(), 6u);
    tissue::VolumeGeometry big;
    big.dims = {200, 200, 200};
    test::expect_input_error([&] { tetrahedralize(tissue::Volume(big)); }, "tetrahedralize", "box",
                             "use a sub-volume");
    // Barycentric interpolation inside a tetrahedron reproduces the linear field.
    std::mt19937 rng(2);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int n = 0; n < 50; ++n) {
        const auto& t = mesh.tets[std::size_t(n) % mesh.tets.size()];
        glm::dvec4 b(u(rng), u(rng), u(rng), u(rng));
        b /= b.x + b.y + b.z + b.w;
        glm::dvec3 p(0.0);
        double value = 0.0;
        for (int k = 0; k < 4; ++k)
            p += b[k] * mesh.points[t[std::size_t(k)]],
                value += b[k] * mesh.values[t[std::size_t(k)]];
        EXPECT_NEAR(value, p.x + 2.0 * p.y + 3.0 * p.z, 1e-5);
    }
}

// One hexahedron (type 12) and one tetrahedron (type 10).
void write_vtk(const std::string& path, bool binary) {
    const double points[9][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1},
                                 {1, 0, 1}, {1, 1, 1}, {0, 1, 1}, {2, 0, 0}};
    const int hex[8] = {0, 1, 2, 3, 4, 5, 6, 7}, tet[4] = {1, 8, 2, 5};
    std::ofstream out(path, std::ios::binary);
    out << "# vtk DataFile Version 3.0\ntest\n"
        << (binary ? "BINARY" : "ASCII") << "\nDATASET UNSTRUCTURED_GRID\nPOINTS 9 float\n";
    auto big_endian = [&](auto value) {
        unsigned char bytes[sizeof value];
        std::memcpy(bytes, &value, sizeof value);
        if constexpr (std::endian::native == std::endian::little)
            std::reverse(bytes, bytes + sizeof value);
        out.write(reinterpret_cast<const char*>(bytes), sizeof value);
    };
    auto number = [&](auto value) {
        if (binary)
            big_endian(value);
        else
            out << value << " ";
    };
    for (const auto& p : points)
        for (double c : p) number(float(c));
    out << "\nCELLS 2 14\n";
    number(int32_t(8));
    for (int i : hex) number(int32_t(i));
    number(int32_t(4));
    for (int i : tet) number(int32_t(i));
    out << "\nCELL_TYPES 2\n";
    number(int32_t(12));
    number(int32_t(10));
    out << "\nPOINT_DATA 9\nSCALARS density float 1\nLOOKUP_TABLE default\n";
    for (int i = 0; i < 9; ++i) number(float(i) * 0.5f);
    out << "\n";
}

TEST(Tetra, VtkLegacyAsciiAndBinaryReadTheSameMesh) {
    test::ScratchDir dir;
    write_vtk(dir / "a.vtk", false);
    write_vtk(dir / "b.vtk", true);
    const TetMesh a = read_vtk_unstructured(dir / "a.vtk"),
                  b = read_vtk_unstructured(dir / "b.vtk");
    ASSERT_EQ(a.tets.size(), 7u);  // the hexahedron as 6 tetrahedra, plus one
    EXPECT_EQ(a.tets, b.tets);
    EXPECT_EQ(a.values, b.values);
    EXPECT_EQ(a.values[8], 4.0f);
    double total = 0.0;
    for (const auto& t : a.tets) total += tet_volume(a, t);
    EXPECT_NEAR(total, 1.0 + 1.0 / 6.0, 1e-9);

    std::ofstream(dir / "triangle.vtk") << "# vtk DataFile Version 3.0\nx\nASCII\nDATASET "
                                           "UNSTRUCTURED_GRID\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\n"
                                           "CELLS 1 4\n3 0 1 2\nCELL_TYPES 1\n5\nPOINT_DATA 3\n"
                                           "SCALARS s float\nLOOKUP_TABLE default\n0 1 2\n";
    test::expect_input_error([&] { read_vtk_unstructured(dir / "triangle.vtk"); }, "triangle.vtk",
                             "CELL_TYPES", "type 5");
    std::ofstream(dir / "noscalars.vtk")
        << "# vtk DataFile Version 3.0\nx\nASCII\nDATASET "
           "UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n"
           "CELLS 1 5\n4 0 1 2 9\nCELL_TYPES 1\n10\n";
    test::expect_input_error([&] { read_vtk_unstructured(dir / "noscalars.vtk"); }, "noscalars.vtk",
                             "");
    test::expect_input_error([&] { read_vtk_unstructured(dir / "missing.vtk"); }, "missing.vtk",
                             "");
    // Counts that are not non-negative integers, or that the file is too short to hold
    // (each point takes at least 6 bytes of ASCII: 50 M points would need 300 MB), are
    // named before anything is allocated.
    const std::string head = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\n";
    const struct {
        std::string body, field, message;
    } bad_counts[] = {
        {"POINTS abc float\n0 0 0\n", "POINTS", "count 'abc'"},
        {"POINTS -5 float\n0 0 0\n", "POINTS", "count '-5'"},
        {"POINTS 3.5 float\n0 0 0\n", "POINTS", "count '3.5'"},
        {"POINTS 50000000 float\n0 0 0 1 0 0\n", "POINTS", "declares 50000000 items"},
        {"POINTS 1 float\n0 0 0\nCELLS 99999999999 5\n4 0 0 0 0\n", "CELLS",
         "declares 99999999999"},
        {"POINTS 1 float\n0 0 0\nCELL_TYPES 1e9\n10\n", "CELL_TYPES", "count '1e9'"},
        // found by fuzz_vtk: an index beyond int64 (its conversion was undefined)
        {"POINTS 1 float\n0 0 0\nCELLS 1 5\n4 1.7e20 0 0 0\n", "CELLS",
         "integer 1.7e+20 is out of range"},
    };
    for (const auto& c : bad_counts) {
        std::ofstream(dir / "counts.vtk") << head << c.body;
        test::expect_input_error([&] { read_vtk_unstructured(dir / "counts.vtk"); }, "counts.vtk",
                                 c.field, c.message);
    }
}

// A camera looking at the box [0, 1]^3 (or wider) from the front-right.
OrbitCamera camera_on(glm::dvec3 target, double distance) {
    OrbitCamera c;
    c.target = target;
    c.distance_mm = distance;
    c.azimuth_deg = 30.0;
    c.elevation_deg = 20.0;
    c.fov_deg = 30.0;
    c.width = c.height = 48;
    return c;
}

ColourTransferFunction colour_map(glm::vec3 low, glm::vec3 high, double opacity) {
    return ColourTransferFunction("map", "test", {{0.0, low, 0.05 * opacity}, {1.0, high, opacity}},
                                  1.0, 0.0, 1.0);
}

double rmse(const RgbImage& a, const RgbImage& b) {
    double sum = 0.0;
    for (std::size_t p = 0; p < a.pixels.size(); ++p) {
        const glm::vec3 d = a.pixels[p] - b.pixels[p];
        sum += glm::dot(d, d);
    }
    return std::sqrt(sum / (3.0 * double(a.pixels.size())));
}

RgbImage render(const std::vector<std::pair<const TetMesh*, const ColourTransferFunction*>>& meshes,
                const OrbitCamera& camera, DepthSampling depth, int repetitions,
                uint64_t seed = 1) {
    RenderSettings settings;
    settings.subpixel_level = 1;
    settings.seed = seed;
    PbvrRenderer renderer(camera, settings);
    for (const auto& [mesh, tf] : meshes) renderer.add_mesh(*mesh, *tf, depth);
    for (int r = 0; r < repetitions; ++r) renderer.add_repetition();
    return renderer.image();
}

// One tetrahedron, a scalar linear across it.
const TetMesh& single_tetrahedron() {
    static const TetMesh mesh = [] {
        TetMesh m;
        m.points = {{0, 0, 0}, {1.5, 0, 0}, {0, 1.5, 0}, {0, 0, 1.5}};
        m.values = {0.0f, 1.0f, 0.3f, 0.7f};
        m.tets = {{0, 1, 2, 3}};
        return m;
    }();
    return mesh;
}

TEST(Tetra, OneTetrahedronAndOneHexahedronConvergeToTheRayIntegral) {
    // With the CDF depth, a fragment's particle colour is distributed as the emission
    // along the segment weighted by the transmittance: the ensemble converges to the
    // emission-absorption integral. 400 repetitions: noise ~ 0.5 / 20 = 2.5e-2 per pixel
    // at worst, the PSNR over the image (most pixels background or opaque-ish) > 38 dB.
    const TetMesh& single = single_tetrahedron();
    tissue::VolumeGeometry g;
    g.dims = {2, 2, 2};
    g.spacing = glm::dvec3(1.5);
    tissue::Volume cell(g, tissue::Voxels{0.0f, 0.9f, 0.2f, 1.0f, 0.4f, 0.6f, 0.1f, 0.8f});
    const TetMesh hexahedron = tetrahedralize(cell);
    ColourTransferFunction tf = colour_map({0.1f, 0.2f, 0.9f}, {1.0f, 0.9f, 0.2f}, 0.9);
    for (const TetMesh* mesh : {static_cast<const TetMesh*>(&single), &hexahedron}) {
        tf.bind(mesh->values_as_volume());
        const OrbitCamera camera = camera_on({0.6, 0.6, 0.6}, 8.0);
        RenderSettings settings;
        settings.subpixel_level = 1;
        const RgbImage reference = raycast_meshes({{mesh, &tf}}, camera, settings, 0.005);
        const RgbImage image = render({{mesh, &tf}}, camera, DepthSampling::cdf, 400);
        EXPECT_GT(psnr(image, reference), 38.0) << mesh->tets.size() << " tetrahedra";
    }
}

// Figure 3 of the paper: two intersecting tetrahedra, a red and a blue colour map;
// RMSE of each depth mode against the fused ray integral.
// The depth matters where a fragment is opaque and its colour varies along it: opacities
// up to 0.9 per mm on cells of ~1 mm. Each mode's squared bias is estimated free of the
// Monte Carlo noise from two independent 1000-repetition images I1, I2:
//     bias^2 = mean((I1 + I2)/2 - reference)^2 - mean(I1 - I2)^2 / 4
// (the second term is the noise variance of the average).
void compare_depth_modes(const TetMesh& red_mesh, const TetMesh& blue_mesh, OrbitCamera camera,
                         const std::string& name) {
    camera.width = camera.height = 32;
    ColourTransferFunction red = colour_map({0.3f, 0.0f, 0.0f}, {1.0f, 0.9f, 0.1f}, 0.9);
    ColourTransferFunction blue = colour_map({0.0f, 0.0f, 0.3f}, {0.1f, 0.9f, 1.0f}, 0.9);
    red.bind(red_mesh.values_as_volume());
    blue.bind(blue_mesh.values_as_volume());
    RenderSettings settings;
    settings.subpixel_level = 1;
    const std::vector<std::pair<const TetMesh*, const ColourTransferFunction*>> meshes = {
        {&red_mesh, &red}, {&blue_mesh, &blue}};
    const RgbImage reference = raycast_meshes(meshes, camera, settings, 0.005);
    std::map<DepthSampling, double> error;
    std::string report;
    for (const DepthSampling d : {DepthSampling::cdf, DepthSampling::entry, DepthSampling::middle,
                                  DepthSampling::exit, DepthSampling::random}) {
        const RgbImage a = render(meshes, camera, d, 1000, 1),
                       b = render(meshes, camera, d, 1000, 2);
        RgbImage mean = a;
        for (std::size_t p = 0; p < mean.pixels.size(); ++p)
            mean.pixels[p] = 0.5f * (a.pixels[p] + b.pixels[p]);
        const double total = rmse(mean, reference), noise = rmse(a, b) / 2.0;
        error[d] = total * total - noise * noise;  // the squared bias
        report += to_string(d) + " rmse " + std::to_string(total) + " bias " +
                  std::to_string(std::sqrt(std::max(error[d], 0.0))) + "; ";
    }
    ::testing::Test::RecordProperty("rmse_" + name, report);
    for (const DepthSampling d :
         {DepthSampling::entry, DepthSampling::middle, DepthSampling::exit, DepthSampling::random})
        EXPECT_LT(error[DepthSampling::cdf], error[d]) << name << ": " << report;
}

TEST(Tetra, CdfDepthHasTheLowestErrorOnIntersectingTetrahedra) {
    TetMesh a, b;
    a.points = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0, 0, 2}};
    a.values = {0.0f, 1.0f, 0.5f, 0.2f};
    a.tets = {{0, 1, 2, 3}};
    b.points = {{1.4, 1.4, 1.4}, {-0.6, 1.4, 1.4}, {1.4, -0.6, 1.4}, {1.4, 1.4, -0.6}};
    b.values = {1.0f, 0.0f, 0.4f, 0.8f};
    b.tets = {{0, 1, 2, 3}};
    compare_depth_modes(a, b, camera_on({0.7, 0.7, 0.7}, 9.0), "two_tetrahedra");
}

TEST(Tetra, CdfDepthHasTheLowestErrorOnOverlappingMeshes) {
    // Two 4^3 grids (27 cells of 1 mm, 162 tetrahedra each) of smooth fields, overlapping.
    auto blob = [](glm::dvec3 origin, double phase) {
        tissue::VolumeGeometry g;
        g.dims = {4, 4, 4};
        g.spacing = glm::dvec3(1.0);
        g.origin = origin;
        tissue::Volume v(g);
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i)
                    v.at(i, j, k) =
                        float(0.5 + 0.5 * std::sin(phase + 0.9 * i) * std::cos(0.7 * j + 0.5 * k));
        return tetrahedralize(v);
    };
    const TetMesh a = blob({0.0, 0.0, 0.0}, 0.0), b = blob({1.5, 0.9, 0.6}, 1.3);
    compare_depth_modes(a, b, camera_on({2.2, 1.9, 1.8}, 16.0), "overlapping_meshes");
}

TEST(Tetra, FusedImagesAreByteIdenticalOnOneAndTwoThreads) {
    tissue::VolumeGeometry g;
    g.dims = {5, 5, 5};
    g.spacing = glm::dvec3(0.6);
    tissue::Volume v(g);
    for (std::size_t i = 0; i < v.size(); ++i) v.voxels()[i] = float((i * 37) % 11) / 10.0f;
    const TetMesh mesh = tetrahedralize(v);
    ColourTransferFunction tf = colour_map({0.2f, 0.2f, 0.8f}, {1.0f, 0.8f, 0.2f}, 0.8);
    tf.bind(mesh.values_as_volume());
    for (const DepthSampling d : {DepthSampling::cdf, DepthSampling::random}) {
        auto run = [&](int threads) {
            tbb::global_control c(tbb::global_control::max_allowed_parallelism,
                                  std::size_t(threads));
            return render({{&mesh, &tf}}, camera_on({1.2, 1.2, 1.2}, 8.0), d, 5);
        };
        const RgbImage a = run(1), b = run(2);
        EXPECT_EQ(
            std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(glm::vec3)), 0)
            << to_string(d);
    }
}

TEST(Tetra, ARegularVolumeAndAMeshFuseAsTheReferenceDoes) {
    // A shaded blob (particles) with a tetrahedralized slab crossing it (fragments), one
    // Z-buffer; against raycast_fused, which adds the extinctions along each ray.
    tissue::VolumeGeometry g;
    g.dims = {24, 24, 24};
    tissue::Volume blob(g);
    for (int k = 0; k < 24; ++k)
        for (int j = 0; j < 24; ++j)
            for (int i = 0; i < 24; ++i)
                blob.at(i, j, k) =
                    float(std::max(0.0, 1.0 - glm::length(glm::dvec3(i, j, k) - 11.5) / 10.0));
    ColourTransferFunction blob_tf = colour_map({0.6f, 0.3f, 0.3f}, {1.0f, 0.9f, 0.8f}, 0.3);
    blob_tf.bind(blob);
    const RenderVolume volume(blob, blob_tf);
    tissue::VolumeGeometry sg;
    sg.dims = {7, 7, 2};
    sg.spacing = {4.0, 4.0, 2.0};
    sg.origin = {0.0, 0.0, 10.5};
    tissue::Volume slab(sg);
    for (std::size_t v = 0; v < slab.size(); ++v) slab.voxels()[v] = float(v % 7) / 6.0f;
    const TetMesh mesh = tetrahedralize(slab);
    ColourTransferFunction slab_tf = colour_map({0.0f, 0.2f, 0.5f}, {0.2f, 0.8f, 1.0f}, 0.6);
    slab_tf.bind(mesh.values_as_volume());
    OrbitCamera camera = camera_on({11.5, 11.5, 11.5}, 90.0);
    RenderSettings settings;
    settings.subpixel_level = 1;
    settings.radius_scale = 1.0;
    const RgbImage reference =
        raycast_fused(&volume, &blob_tf, {{&mesh, &slab_tf}}, camera, settings, 0.02);
    PbvrRenderer renderer(volume, blob_tf, camera, settings);
    renderer.add_mesh(mesh, slab_tf, DepthSampling::cdf);
    for (int r = 0; r < 300; ++r) renderer.add_repetition();
    // 300 repetitions of 48 x 48 pixels: noise ~0.3 / sqrt(300) = 0.017 per pixel where
    // the slab and the blob compete, far less elsewhere; measured 42.9 dB. 39 dB (RMSE
    // 0.011) fails if either volume is missing from the Z-buffer or their order is wrong.
    const double db = psnr(renderer.image(), reference);
    ::testing::Test::RecordProperty("psnr_fused", std::to_string(db));
    EXPECT_GT(db, 39.0);
}

// One tetrahedron seen whole: each sub-pixel's one fragment decides it alone. Its number
// is stratified across repetitions (CellSequence), so N repetitions cover [0, 1) evenly:
// the fraction of them in which the fragment becomes a particle is within about 1 / N of
// its opacity (and its depth's colour likewise), and the squared error falls as 1 / N^2,
// +6 dB per doubling, where independent numbers give 1 / N, +3 dB (measured with them:
// 29.5, 35.7 and 41.7 dB at 4, 16 and 64 repetitions; stratified: 35.3, 47.4, 59.4).
// Against the ray integral of the same mesh at 2 um steps (raycast_meshes: a quadrature of
// the emission-absorption integral, independent of the particles), the mean squared error
// over 16 seeds must fall by at least 10 dB per 4x repetitions, from 4 to 16 and from 16 to
// 64 (independent numbers: 6.2 and 6.0), and reach 55 dB at 64.
// One tetrahedron at one sub-pixel a pixel, and its ray integral at 2 um steps
// (raycast_meshes: a quadrature of the emission-absorption integral, independent of the
// particles).
struct OneTetrahedronScene {
    ColourTransferFunction tf = colour_map({0.1f, 0.2f, 0.9f}, {1.0f, 0.9f, 0.2f}, 0.9);
    OrbitCamera camera = camera_on({0.6, 0.6, 0.6}, 8.0);
    RgbImage reference;
    OneTetrahedronScene() {
        tf.bind(single_tetrahedron().values_as_volume());
        RenderSettings settings;
        settings.subpixel_level = 1;
        reference = raycast_meshes({{&single_tetrahedron(), &tf}}, camera, settings, 0.002);
    }
    RgbImage render(int repetitions, uint64_t seed) const {
        return pbvr::render({{&single_tetrahedron(), &tf}}, camera, DepthSampling::cdf, repetitions,
                            seed);
    }
};

TEST(Tetra, StratifiedFragmentsConvergeAsOneOverTheRepetitions) {
    const OneTetrahedronScene scene;
    std::vector<double> db;
    for (const int repetitions : {4, 16, 64}) {
        double mse = 0.0;
        for (uint64_t seed = 1; seed <= 16; ++seed) {
            const double e = rmse(scene.render(repetitions, seed), scene.reference);
            mse += e * e / 16.0;
        }
        db.push_back(-10.0 * std::log10(mse));
    }
    EXPECT_GT(db[1] - db[0], 10.0) << db[0] << " " << db[1];
    EXPECT_GT(db[2] - db[1], 10.0) << db[1] << " " << db[2];
    EXPECT_GT(db[2], 55.0);
    ::testing::Test::RecordProperty(
        "psnr_4_16_64",
        std::to_string(db[0]) + " " + std::to_string(db[1]) + " " + std::to_string(db[2]));
}

// Stratified across repetitions, one seed's repetitions depend on each other; each must
// still be an unbiased draw. 64 seeds of 2 repetitions each (independent of each other)
// averaged, pixel by pixel and channel by channel, against the ray integral: sum of
// (mean - reference)^2 / (sample variance / 64) per sample must be chi-square with one
// degree of freedom per sample, so its mean within 25 % of 1 (0.90-1.14 over five sets of
// seeds; the reference's own error, about 65 dB, is 2 % of the mean's variance here). The
// same against the reference lifted by 0.02 must exceed 2 (5.7-6.4): the test can fail.
TEST(Tetra, ShortStratifiedRunsAverageToTheRayIntegral) {
    const OneTetrahedronScene scene;
    ImageEnsemble short_runs;
    for (int run = 0; run < 64; ++run) short_runs.add(scene.render(2, uint64_t(100 + run)));
    // Samples that never vary: background, or opaque in every run.
    const auto statistic = short_runs.against(scene.reference, 0.0, 0.0, 1e-9);
    const double lifted = short_runs.against(scene.reference, 0.02, 0.0, 1e-9).per_sample;
    EXPECT_GT(statistic.degrees, 300) << "too few samples vary";
    std::printf("chi-square per sample: %.3f (lifted by 0.02: %.2f)\n", statistic.per_sample,
                lifted);
    EXPECT_NEAR(statistic.per_sample, 1.0, 0.25);
    EXPECT_GT(lifted, 2.0);
}

}  // namespace
}  // namespace sonotrace::imaging::pbvr
