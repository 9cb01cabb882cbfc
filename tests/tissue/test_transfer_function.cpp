// Transfer functions: interpolation, clamping, normalisation, labels, presets on the
// Colin27 anatomy, the tissue table against literature, and every error case.
#include <gtest/gtest.h>

#include <fstream>

#include "tests/test_util.h"
#include "tissue/property_maps.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"

namespace sonotrace::tissue {
namespace {

using test::expect_input_error;

float speed(const AcousticProperties& p) {
    return p[Property::speed_of_sound];
}

const char* kTwoPoints = R"({
  "kind": "piecewise-linear", "intensity": "raw",
  "points": [
    {"intensity": 0, "tissue": "water"},
    {"intensity": 100, "speed_of_sound": 1600, "density": 1100, "attenuation": 1.0,
     "backscatter": 0.8, "scatterer_density": 40, "roughness": 1.0}
  ]})";

TEST(TransferFunction, LinearBetweenPointsAndClampedOutside) {
    auto tf = parse_transfer_function(kTwoPoints, "two.json");
    VolumeGeometry g;
    tf->bind(Volume(g));
    const AcousticProperties water = find_tissue("water", "", "").properties;
    const AcousticProperties quarter = tf->evaluate(25.0f);
    const float b[] = {1600, 1100, 1.0f, 0.8f, 40, 1.0f};
    for (std::size_t n = 0; n < kPropertyCount; ++n) {
        EXPECT_NEAR(quarter.values[n], 0.75 * water.values[n] + 0.25 * b[n],
                    1e-3 * std::abs(b[n]) + 1e-6)
            << kPropertyInfo[n].key;
    }
    EXPECT_EQ(speed(tf->evaluate(-50.0f)), water[Property::speed_of_sound]);
    EXPECT_EQ(speed(tf->evaluate(1e6f)), 1600.0f);
    EXPECT_EQ(speed(tf->evaluate(100.0f)), 1600.0f);
    EXPECT_FALSE(tf->uses_nearest_sampling());
}

TEST(TransferFunction, TissueOverridesAndNormalisedWindow) {
    auto tf = parse_transfer_function(R"({"intensity": "normalized",
        "normalization": {"low_quantile": 0.0, "high_quantile": 0.5},
        "points": [{"intensity": 0, "tissue": "fat"},
                   {"intensity": 1, "tissue": "liver", "speed_of_sound": 1600}]})",
                                      "n.json");
    VolumeGeometry g;
    g.dims = {1000, 1, 1};
    Volume v(g);
    for (int i = 0; i < 1000; ++i) v.at(i, 0) = float(i);
    tf->bind(v);  // window: 0 .. median (~500)
    const auto* pl = dynamic_cast<const PiecewiseLinearTransferFunction*>(tf.get());
    ASSERT_NE(pl, nullptr);
    EXPECT_NEAR(pl->window_high(), 500.0, 1.0);
    // Raw 250 = normalised 0.5: halfway between fat (1450) and the overridden liver (1600).
    EXPECT_NEAR(speed(tf->evaluate(250.0f)), 1525.0, 0.5);
    // The override changes only the named property.
    EXPECT_EQ(tf->evaluate(900.0f)[Property::density],
              find_tissue("liver", "", "").properties[Property::density]);
}

TEST(TransferFunction, LabelTable) {
    auto tf = parse_transfer_function(R"({"kind": "labels", "labels": [
        {"label": 0, "tissue": "air"}, {"label": 3, "tissue": "liver"},
        {"label": 7, "speed_of_sound": 1700, "density": 1200, "attenuation": 2, "backscatter": 0.1,
         "scatterer_density": 1, "roughness": 0}]})",
                                      "labels.json");
    EXPECT_TRUE(tf->uses_nearest_sampling());
    VolumeGeometry g;
    g.dims = {3, 1, 1};
    Volume v(g);
    v.at(0, 0) = 0, v.at(1, 0) = 3, v.at(2, 0) = 7;
    tf->bind(v);
    EXPECT_EQ(speed(tf->evaluate(3.0f)),
              find_tissue("liver", "", "").properties[Property::speed_of_sound]);
    EXPECT_EQ(speed(tf->evaluate(7.0f)), 1700.0f);
    v.at(1, 0) = 5;
    expect_input_error([&] { tf->bind(v); }, "labels.json", "labels", "label 5");
    v.at(1, 0) = 3.5f;
    expect_input_error([&] { tf->bind(v); }, "labels.json", "labels", "not an integer");
}

// A dataset's drawn tissue properties: each labelled texel's property times its factor,
// held to the property's range; other labels and other properties untouched.
TEST(PropertyMaps, ScaleByLabelScalesOnlyThatTissuesPropertyWithinItsRange) {
    VolumeGeometry g;
    g.dims = {4, 1, 1};
    PropertyMaps maps;
    for (Volume& f : maps.fields) f = Volume(g, 0.5f);
    maps[Property::speed_of_sound] = Volume(g, 1500.0f);
    const Volume labels(g, Voxels{0.0f, 1.0f, 2.0f, 2.0f});
    const LabelScale scales[] = {{2, Property::speed_of_sound, 1.02},
                                 {2, Property::backscatter, 3.0},
                                 {1, Property::attenuation, 0.5}};
    scale_by_label(maps, labels, scales);
    const auto& c = maps[Property::speed_of_sound].voxels();
    EXPECT_EQ(c[0], 1500.0f);
    EXPECT_EQ(c[1], 1500.0f);
    EXPECT_FLOAT_EQ(c[2], 1530.0f);
    EXPECT_FLOAT_EQ(c[3], 1530.0f);
    // 0.5 x 3 = 1.5, held to backscatter's 1.
    EXPECT_EQ(maps[Property::backscatter].voxels()[2], 1.0f);
    EXPECT_EQ(maps[Property::backscatter].voxels()[1], 0.5f);
    EXPECT_FLOAT_EQ(maps[Property::attenuation].voxels()[1], 0.25f);
    EXPECT_EQ(maps[Property::attenuation].voxels()[2], 0.5f);
    EXPECT_EQ(maps[Property::density].voxels()[2], 0.5f);
}

TEST(TissueTable, ValuesAreInRangeAndMatchLiterature) {
    for (const TissueEntry& t : tissue_table()) {
        for (std::size_t n = 0; n < kPropertyCount; ++n) {
            EXPECT_GE(t.properties.values[n], kPropertyInfo[n].min) << t.key;
            EXPECT_LE(t.properties.values[n], kPropertyInfo[n].max) << t.key;
        }
    }
    // Characteristic impedances (MRayl) from textbooks (Szabo 2014, table B.1 ranges).
    EXPECT_NEAR(find_tissue("water", "", "").properties.impedance_mrayl(), 1.51, 0.03);
    EXPECT_NEAR(find_tissue("soft_tissue", "", "").properties.impedance_mrayl(), 1.63, 0.05);
    EXPECT_NEAR(find_tissue("fat", "", "").properties.impedance_mrayl(), 1.38, 0.05);
    EXPECT_GT(find_tissue("cortical_bone", "", "").properties.impedance_mrayl(), 5.0);
    EXPECT_LT(find_tissue("air", "", "").properties.impedance_mrayl(), 0.001);
    // Soft-tissue-to-air interfaces reflect ~99.9 % of the intensity: R = (Z2-Z1)/(Z2+Z1),
    // Z_air = 4.1e-4 MRayl, Z_tissue = 1.63 MRayl -> R^2 = 0.99899.
    const double z1 = find_tissue("soft_tissue", "", "").properties.impedance_mrayl();
    const double z2 = find_tissue("air", "", "").properties.impedance_mrayl();
    EXPECT_NEAR(std::pow((z2 - z1) / (z2 + z1), 2), 0.99899, 2e-5);
    expect_input_error([] { find_tissue("unobtainium", "f.json", "points[0].tissue"); }, "f.json",
                       "points[0].tissue", "known: water");
}

TEST(TransferFunctionPresets, AllPresetsParse) {
    const auto names = transfer_function_presets();
    ASSERT_GE(names.size(), 2u);
    for (const auto& name : names) EXPECT_NO_THROW(load_transfer_function(name)) << name;
}

TEST(TransferFunctionPresets, MriT1HeadGivesColin27PlausibleAcoustics) {
    // Points in MNI space whose tissue is known from anatomy; the preset must give each
    // the acoustics of that tissue.
    const Volume head = load_volume({kDefaultVolumeName, std::nullopt}).volume;
    auto tf = load_transfer_function("mri-t1-head");
    tf->bind(head);
    auto at = [&](double x, double y, double z) {
        return tf->evaluate(head.sample_trilinear(head.geometry().world_to_index({x, y, z}), 0.0f));
    };
    EXPECT_LT(speed(at(89, -18, 2)), 400.0) << "air outside the right temple";
    EXPECT_GT(speed(at(-72, -18, 2)), 3000.0) << "left temporal squama";
    EXPECT_GT(speed(at(-68, 0, 18)), 3000.0) << "left parietal skull";
    EXPECT_GT(speed(at(71, 0, 18)), 3000.0) << "right parietal skull";
    EXPECT_NEAR(speed(at(5, 0, 18)), 1515.0, 15.0) << "lateral ventricle CSF";
    EXPECT_NEAR(speed(at(-30, 0, 18)), 1560.0, 10.0) << "white matter (corona radiata)";
    EXPECT_LT(at(5, 0, 18)[Property::backscatter], 0.1) << "ventricles are anechoic";
    EXPECT_GT(at(-30, 0, 18)[Property::backscatter], 0.2) << "parenchyma scatters";
}

// Hounsfield units are defined by two points, air -1000 and water 0; the other tissues'
// ranges are the clinical ones (fat about -100, soft tissue 20-80, cortical bone 700 and
// more). The preset must give each the tissue table's acoustics, on raw values.
TEST(TransferFunctionPresets, CtHounsfieldGivesEachTissueOfItsRange) {
    auto tf = load_transfer_function("ct-hounsfield");
    tissue::VolumeGeometry g;
    g.dims = {2, 1, 1};
    Volume any(g);  // raw values: binding looks at nothing
    tf->bind(any);
    auto label_at = [&](float hu) { return tissue_label_name(tf->tissue_label(hu)); };
    EXPECT_EQ(label_at(-1000.0f), "air");
    EXPECT_EQ(label_at(-700.0f), "air") << "lung reflects totally";
    EXPECT_EQ(label_at(-100.0f), "fat");
    EXPECT_EQ(label_at(5.0f), "water");
    EXPECT_EQ(label_at(55.0f), "soft_tissue");
    EXPECT_EQ(label_at(1200.0f), "cortical_bone");
    const auto& bone = find_tissue("cortical_bone", "", "").properties;
    EXPECT_FLOAT_EQ(speed(tf->evaluate(1200.0f)), bone[Property::speed_of_sound]);
    EXPECT_LT(speed(tf->evaluate(-1000.0f)), 400.0);
    // Partial volume between soft tissue and bone: in between.
    const double trabecular = speed(tf->evaluate(400.0f));
    EXPECT_GT(trabecular, 1700.0);
    EXPECT_LT(trabecular, bone[Property::speed_of_sound]);
}

TEST(TransferFunctionErrors, EachProblemNamesFileAndField) {
    auto check = [](const std::string& text, const std::string& field, const std::string& what) {
        expect_input_error([&] { parse_transfer_function(text, "tf.json"); }, "tf.json", field,
                           what);
    };
    check(R"({"points": [{"intensity": 0, "tissue": "fat"}], "colour": "red"})", "colour",
          "unknown key");
    check(R"({"points": [{"intensity": 0, "tissue": "fat", "speed": 1500}]})", "points[0].speed",
          "unknown key");
    check(R"({"points": [{"intensity": 0, "tissue": "fat"}, {"intensity": 0, "tissue": "liver"}]})",
          "points[1].intensity", "strictly increasing");
    check(R"({"points": [{"intensity": 5, "tissue": "fat"}, {"intensity": 2, "tissue": "liver"}]})",
          "points[1].intensity", "strictly increasing");
    check(R"({"points": [{"intensity": 0, "tissue": "bone"}]})", "points[0].tissue",
          "unknown tissue");
    check(R"({"points": [{"intensity": 0, "speed_of_sound": 1500}]})", "points[0].density",
          "required");
    check(R"({"points": [{"intensity": 0, "tissue": "fat", "speed_of_sound": -3}]})",
          "points[0].speed_of_sound", "outside");
    check(R"({"points": [{"intensity": 0, "tissue": "fat", "backscatter": "high"}]})",
          "points[0].backscatter", "number");
    check(R"({"points": []})", "points", "non-empty");
    check(R"({"kind": "spline", "points": []})", "kind", "piecewise-linear");
    check(R"({"intensity": "log", "points": [{"intensity": 0, "tissue": "fat"}]})", "intensity",
          "raw");
    check(R"({"kind": "labels", "labels": [{"label": 1.5, "tissue": "fat"}]})", "labels[0].label",
          "integer");
    check(
        R"({"kind": "labels", "labels": [{"label": 1, "tissue": "fat"}, {"label": 1, "tissue": "air"}]})",
        "labels[1].label", "twice");
    check(R"({"points": [{"intensity": 0, "tissue": "fat"})", "", "invalid JSON at line 1");
    expect_input_error([] { load_transfer_function("/no/such/tf.json"); }, "/no/such/tf.json", "",
                       "presets");
}

}  // namespace
}  // namespace sonotrace::tissue
