// Analytic phantoms: signed distances against closed forms, the interface blend, the
// parser's errors, and every phantom of the catalogue parses.
#include <gtest/gtest.h>

#include <filesystem>

#include "phantoms/phantom.h"
#include "phantoms/trace_setup.h"
#include "tests/test_util.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace {
namespace {

using phantoms::Shape;
using phantoms::ShapeType;
using tissue::Property;

Shape shape(ShapeType type, glm::dvec3 a, glm::dvec3 b, double radius) {
    Shape s;
    s.type = type, s.a = a, s.b = b, s.radius = radius;
    return s;
}

TEST(Phantom, SignedDistancesMatchClosedForms) {
    const Shape sphere = shape(ShapeType::sphere, {1, 2, 3}, {}, 2.0);
    EXPECT_NEAR(sphere.signed_distance({1, 2, 3}), -2.0, 1e-12);
    EXPECT_NEAR(sphere.signed_distance({1, 2, 8}), 3.0, 1e-12);
    const Shape box = shape(ShapeType::box, {0, 0, 0}, {4, 2, 2}, 0.0);
    EXPECT_NEAR(box.signed_distance({2, 1, 1}), -1.0, 1e-12);  // centre: nearest face y
    EXPECT_NEAR(box.signed_distance({7, 1, 1}), 3.0, 1e-12);   // beyond a face
    EXPECT_NEAR(box.signed_distance({7, 6, 1}), 5.0, 1e-12);   // beyond an edge: 3-4-5
    const Shape rod = shape(ShapeType::cylinder, {0, 0, 0}, {0, 0, 10}, 1.0);
    EXPECT_NEAR(rod.signed_distance({3, 0, 5}), 2.0, 1e-12);
    EXPECT_NEAR(rod.signed_distance({0, 0, 12}), 2.0, 1e-12);
    EXPECT_NEAR(rod.signed_distance({0, 0.5, 5}), -0.5, 1e-12);
    const Shape wire = shape(ShapeType::wire, {5, 5, 0}, {}, 0.5);
    EXPECT_NEAR(wire.signed_distance({8, 9, 123}), 4.5, 1e-12);  // along z: unbounded
    const glm::dvec3 n = glm::normalize(glm::dvec3(1, 1, 0));
    const Shape half = shape(ShapeType::half_space, {0, 0, 0}, n, 0.0);
    EXPECT_NEAR(half.signed_distance({2, 2, 0}), -std::sqrt(8.0), 1e-12);
    const Shape layer = shape(ShapeType::layer, {0, 10, 0}, {0, 1, 0}, 4.0);
    EXPECT_NEAR(layer.signed_distance({0, 12, 0}), -2.0, 1e-12);
    EXPECT_NEAR(layer.signed_distance({0, 9, 0}), 1.0, 1e-12);
    EXPECT_NEAR(layer.signed_distance({0, 15, 0}), 1.0, 1e-12);
}

TEST(Phantom, InterfacesBlendLinearlyOverTheSmoothingWidth) {
    const nlohmann::json j = nlohmann::json::parse(R"({
        "name": "blend", "size": [20, 20, 20], "smoothing": 1.0,
        "background": {"tissue": "water"},
        "shapes": [{"type": "half_space", "point": [0, 10, 0], "normal": [0, 1, 0],
                    "tissue": "liver"}]})");
    const phantoms::Phantom ph = phantoms::parse_phantom(j, "test");
    const float c_water = tissue::find_tissue("water", "", "").properties[Property::speed_of_sound];
    const float c_liver = tissue::find_tissue("liver", "", "").properties[Property::speed_of_sound];
    int label = -1;
    EXPECT_FLOAT_EQ(ph.at({5, 9.4, 5}, &label)[Property::speed_of_sound], c_water);
    EXPECT_EQ(label, tissue::tissue_label_of("water"));
    EXPECT_FLOAT_EQ(ph.at({5, 10.6, 5}, &label)[Property::speed_of_sound], c_liver);
    EXPECT_EQ(label, tissue::tissue_label_of("liver"));
    // A quarter width inside: three quarters liver.
    EXPECT_NEAR(ph.at({5, 10.25, 5})[Property::speed_of_sound],
                c_water + 0.75 * (c_liver - c_water), 1e-3);
    // Rasterised on a grid: the same function at the texel centres.
    tissue::VolumeGeometry g;
    g.dims = {4, 21, 1};
    g.spacing = {1, 1, 1};
    tissue::Volume labels;
    const tissue::PropertyMaps maps = phantoms::rasterise(ph, g, &labels);
    EXPECT_FLOAT_EQ(maps[Property::speed_of_sound].at(1, 10, 0), 0.5f * (c_water + c_liver));
    EXPECT_EQ(labels.at(1, 5, 0), float(tissue::tissue_label_of("water")));
    EXPECT_EQ(labels.at(1, 15, 0), float(tissue::tissue_label_of("liver")));
}

TEST(Phantom, BadInputNamesTheField) {
    const struct {
        const char* text;
        const char* field;
    } cases[] = {
        {R"({"name": "x", "size": [10, 10, 10]})", "background"},
        {R"({"name": "x", "size": [10, 0, 10], "background": {"tissue": "water"}})", "size"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "bone"}})", "tissue"},
        {R"({"name": "x", "size": [10, 10, 10], "colour": 1, "background": {"tissue": "water"}})",
         "colour"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "cone", "tissue": "fat"}]})",
         "shapes[0].type"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "sphere", "centre": [1, 2, 3], "radius": -1, "tissue": "fat"}]})",
         "shapes[0].radius"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "layer", "point": [0, 1, 0], "normal": [0, 0, 0],
                         "thickness": 1, "tissue": "fat"}]})",
         "shapes[0].normal"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "wire", "at": [1, 2], "radius": 0.1, "speed": 1500}]})",
         "shapes[0].speed"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "probe": {"beam": [0, 1, 0], "lateral": [0, 2, 0]}})",
         "probe.lateral"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "sphere", "centre": [30, 5, 5], "radius": 2, "tissue": "fat"}]})",
         "shapes[0]"},  // entirely outside the phantom
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "half_space", "point": [0, 12, 0], "normal": [0, 1, 0],
                         "tissue": "fat"}]})",
         "shapes[0]"},
        {R"({"name": "x", "size": [1000, 1000, 1000], "resolution": 0.01,
             "background": {"tissue": "water"}})",
         "resolution"},  // 10^15 texels
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "box", "min": [1, 1, 1], "max": [2, 2, 2], "profile": "parabolic",
                         "tissue": "fat"}]})",
         "shapes[0].profile"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "shapes": [{"type": "tube", "path": [[1, 1, 1]], "radius": 1, "tissue": "fat"}]})",
         "shapes[0].path"},
        {R"({"name": "x", "mode": "paper", "size": [10, 10, 10], "background": {"paper_density": 1},
             "shapes": [{"type": "sphere", "centre": [5, 5, 5], "radius": 1}]})",
         "shapes[0].paper_density"},
        {R"({"name": "x", "mode": "paper", "size": [10, 10, 10], "background": {"tissue": "water"}})",
         "background.tissue"},  // paper mode has no acoustic properties
        {R"({"name": "x", "mode": "sound", "size": [10, 10, 10], "background": {"tissue": "water"}})",
         "mode"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "source": {"type": "cone", "at": [1, 1], "direction": [0, 1], "particles": 5}})",
         "source.type"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "source": {"type": "fan", "at": [1, 1], "direction": [0, 0], "half_angle": 5,
                        "particles": 5}})",
         "source.direction"},
        // Point targets: outside the phantom, impossible sizes and strengths, unknown keys.
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 12]}]})",
         "targets[0].at"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "point", "at": [5, 5, -1]}]})",
         "targets[0].at"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "point", "at": [5, 5]}]})",
         "targets[0].at"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "needle", "at": [5, 5]}]})",
         "targets[0].type"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 5], "diameter": 3}]})",
         "targets[0].diameter"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 5], "reflectivity": 0}]})",
         "targets[0].reflectivity"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 5], "reflectivity": "high"}]})",
         "targets[0].reflectivity"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 5], "radius": 0.1}]})",
         "targets[0].radius"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": {"type": "wire", "at": [5, 5]}})",
         "targets"},
        // A tilted wire's axis: a direction, and only for wires.
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 5], "axis": [0, 0, 0]}]})",
         "targets[0].axis"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "wire", "at": [5, 5], "axis": [1, 0]}]})",
         "targets[0].axis"},
        {R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
             "targets": [{"type": "point", "at": [5, 5, 5], "axis": [1, 0, 0]}]})",
         "targets[0].axis"},
    };
    for (const auto& c : cases) {
        try {
            phantoms::parse_phantom(nlohmann::json::parse(c.text), "p.json");
            ADD_FAILURE() << "accepted: " << c.text;
        } catch (const base::InputError& e) {
            EXPECT_NE(std::string(e.what()).find("p.json"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(c.field), std::string::npos) << e.what();
        }
    }
}

TEST(Phantom, TubeDistanceAndParabolicProfile) {
    // An L-shaped centreline, radius 1: distances to the nearest segment minus the radius.
    Shape tube = shape(ShapeType::tube, {}, {}, 1.0);
    tube.path = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}};
    EXPECT_NEAR(tube.signed_distance({5, 3, 0}), 2.0, 1e-12);
    EXPECT_NEAR(tube.signed_distance({12, 5, 0}), 1.0, 1e-12);
    EXPECT_NEAR(tube.signed_distance({10, 0, 0}), -1.0, 1e-12);
    EXPECT_NEAR(tube.signed_distance({10, 13, 0}), 2.0, 1e-12);  // beyond the end
    EXPECT_NEAR(tube.signed_distance({-3, 0, 4}), 4.0, 1e-12);   // 3-4-5 from the start
    // Parabolic profile 1 - (r/R)^2, whatever the smoothing width.
    tube.radius = 2.0, tube.parabolic = true;
    EXPECT_NEAR(tube.weight({5, 0, 0}, 0.5), 1.0, 1e-12);
    EXPECT_NEAR(tube.weight({5, 1, 0}, 0.5), 0.75, 1e-12);
    EXPECT_NEAR(tube.weight({5, 0, std::sqrt(2.0)}, 0.5), 0.5, 1e-12);
    EXPECT_EQ(tube.weight({5, 2.5, 0}, 0.5), 0.0);
}

TEST(Phantom, PaperFiguresReproduceTheirMedia) {
    const std::string dir = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/";
    // Figure 2: d 1.0 left of x = 30, 1.6 between it and the plane tilted 35 degrees
    // through (65, 37.5), 1.0 beyond that plane.
    const phantoms::Phantom fig2 = phantoms::load_phantom(dir + "paper_fig2.json");
    EXPECT_DOUBLE_EQ(fig2.paper_density_at({20, 37.5, 0.5}), 1.0);
    EXPECT_DOUBLE_EQ(fig2.paper_density_at({45, 37.5, 0.5}), 1.6);
    EXPECT_DOUBLE_EQ(fig2.paper_density_at({90, 60, 0.5}), 1.0);
    // Figure 4: d = 1 + 0.5 (1 - (r/5)^2) across the fibre's straight entry (x = 15).
    const phantoms::Phantom fig4 = phantoms::load_phantom(dir + "paper_fig4a.json");
    EXPECT_NEAR(fig4.paper_density_at({15, 110, 0.5}), 1.5, 1e-9);
    EXPECT_NEAR(fig4.paper_density_at({17.5, 110, 0.5}), 1.375, 1e-9);
    EXPECT_NEAR(fig4.paper_density_at({25, 110, 0.5}), 1.0, 1e-9);
    // On the bend (radius 70 about (85, 98)), 2.5 mm outwards: the polyline of 128
    // segments sags by 70 (1 - cos(pi / 256)) = 5e-3 mm at most.
    const double a = 0.6;  // radians along the quarter circle
    const glm::dvec3 axis(85 - 70 * std::cos(a), 98 - 70 * std::sin(a), 0.5);
    const glm::dvec3 out = axis + 2.5 * glm::dvec3(-std::cos(a), -std::sin(a), 0.0);
    EXPECT_NEAR(fig4.paper_density_at(axis), 1.5, 1e-4);
    EXPECT_NEAR(fig4.paper_density_at(out), 1.375, 1e-3);
    // Figure 6: d 1 above y = 30, 3 in the reflector, 2 +- 0.6 in the textured matter.
    const phantoms::Phantom fig6 = phantoms::load_phantom(dir + "paper_fig6.json");
    EXPECT_DOUBLE_EQ(fig6.paper_density_at({50, 20, 0.5}), 1.0);
    EXPECT_DOUBLE_EQ(fig6.paper_density_at({50, 31, 0.5}), 3.0);
    double lo = 10.0, hi = 0.0;
    for (int i = 0; i < 400; ++i) {
        const double d = fig6.paper_density_at({0.25 * i, 50.0 + 0.05 * i, 0.5});
        lo = std::min(lo, d), hi = std::max(hi, d);
    }
    EXPECT_GE(lo, 1.4);
    EXPECT_LE(hi, 2.6);
    EXPECT_GT(hi - lo, 0.5) << "the texture varies";
    // Each traces: particles from its source, the paper's physics.
    const simulator::TraceSetup scene = phantoms::trace_setup(fig6, 10);
    EXPECT_EQ(scene.sources.size(), 10u);
    EXPECT_EQ(scene.settings.mode, simulator::PhysicsMode::paper);
    EXPECT_TRUE(scene.settings.ring.has_value());
    EXPECT_EQ(scene.settings.lobe_weight, simulator::LobeWeight::energy);
}

TEST(Phantom, TraceEntryErrorsNameTheField) {
    auto parse = [](const char* text) {
        return phantoms::parse_phantom(nlohmann::json::parse(text), "t.json");
    };
    const char* base = R"({"name": "x", "mode": "paper", "size": [10, 10, 10],
        "background": {"paper_density": 1}, %s})";
    auto with = [&](const std::string& extra) {
        std::string text = base;
        text.replace(text.find("%s"), 2, extra);
        return text;
    };
    test::expect_input_error(
        [&] { phantoms::trace_setup(parse(with(R"("comment": "no source")").c_str())); }, "t.json",
        "source");
    const std::string src =
        R"("source": {"type": "fan", "at": [1, 1], "direction": [1, 0], "half_angle": 10, "particles": 3})";
    test::expect_input_error(
        [&] { phantoms::trace_setup(parse(with(src + R"(, "trace": {"lobe": 3})").c_str())); },
        "t.json", "trace.lobe");
    test::expect_input_error(
        [&] {
            phantoms::trace_setup(
                parse(with(src + R"(, "trace": {"lobe_weight": "heavy"})").c_str()));
        },
        "t.json", "trace.lobe_weight");
}

TEST(Phantom, RasterisesIn3D) {
    // A sphere of radius 3 mm at the centre of an 11^3 grid of 1 mm: inside along every
    // axis up to 2 mm (beyond the 0.5 mm half-width of the blend), outside from 4 mm.
    const phantoms::Phantom ph = phantoms::parse_phantom(nlohmann::json::parse(R"({
        "name": "ball", "size": [10, 10, 10], "smoothing": 1.0, "background": {"tissue": "water"},
        "shapes": [{"type": "sphere", "centre": [5, 5, 5], "radius": 3, "tissue": "fat"}]})"),
                                                         "ball");
    tissue::VolumeGeometry g;
    g.dims = {11, 11, 11};
    g.spacing = {1, 1, 1};
    tissue::Volume labels;
    const auto maps = phantoms::rasterise(ph, g, &labels);
    const float fat = tissue::find_tissue("fat", "", "").properties[Property::speed_of_sound];
    const float water = tissue::find_tissue("water", "", "").properties[Property::speed_of_sound];
    for (const glm::ivec3 axis : {glm::ivec3(1, 0, 0), glm::ivec3(0, 1, 0), glm::ivec3(0, 0, 1)}) {
        const glm::ivec3 in = glm::ivec3(5) + 2 * axis, out = glm::ivec3(5) + 4 * axis;
        EXPECT_FLOAT_EQ(maps[Property::speed_of_sound].at(in.x, in.y, in.z), fat);
        EXPECT_FLOAT_EQ(maps[Property::speed_of_sound].at(out.x, out.y, out.z), water);
        EXPECT_EQ(labels.at(in.x, in.y, in.z), float(tissue::tissue_label_of("fat")));
    }
}

TEST(Phantom, KeyGivenTwiceIsRefused) {
    // Two definitions of one radius: which one is meant cannot be resolved.
    const std::string text =
        R"({"name": "x", "size": [10, 10, 10], "background": {"tissue": "water"},
        "shapes": [{"type": "sphere", "centre": [5, 5, 5], "radius": 1, "radius": 2,
                    "tissue": "fat"}]})";
    test::expect_input_error([&] { base::jsonio::parse(text, "twice.json"); }, "twice.json",
                             "radius", "twice");
    // The same key in different objects is fine.
    EXPECT_NO_THROW(base::jsonio::parse(R"({"a": {"k": 1}, "b": {"k": 2}})", "ok.json"));
}

TEST(Phantom, CatalogueParses) {
    int count = 0;
    for (const auto& entry :
         std::filesystem::directory_iterator(std::string(SONOTRACE_SOURCE_DIR) + "/phantoms")) {
        if (entry.path().extension() != ".json") continue;
        const phantoms::Phantom ph = phantoms::load_phantom(entry.path().string());
        EXPECT_FALSE(ph.description.empty()) << entry.path();
        EXPECT_FALSE(ph.shapes.empty()) << entry.path();
        ++count;
    }
    EXPECT_GE(count, 5);
}

}  // namespace
}  // namespace sonotrace
