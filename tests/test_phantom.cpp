// Analytic phantoms: signed distances against closed forms, the interface blend, the
// parser's errors, and every phantom of the catalogue parses.
#include <gtest/gtest.h>

#include <filesystem>

#include "phantoms/phantom.h"
#include "tissue/error.h"
#include "tissue/json_util.h"
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
    };
    for (const auto& c : cases) {
        try {
            phantoms::parse_phantom(nlohmann::json::parse(c.text), "p.json");
            ADD_FAILURE() << "accepted: " << c.text;
        } catch (const tissue::InputError& e) {
            EXPECT_NE(std::string(e.what()).find("p.json"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(c.field), std::string::npos) << e.what();
        }
    }
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
