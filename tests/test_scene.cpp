// The one scene type (imaging/scene/scene.h): what it takes from a phantom or a volume,
// what it sets in the simulation settings, and the options it refuses before loading.
#include <gtest/gtest.h>

#include "imaging/scene/scene.h"
#include "tissue/base/error.h"

namespace sonotrace::imaging {
namespace {

const std::string kPhantoms = SONOTRACE_SOURCE_DIR "/phantoms";

// The message of the InputError `load` throws ("" if it throws none).
template <typename F>
std::string input_error(F load) {
    try {
        load();
    } catch (const base::InputError& e) {
        return e.what();
    }
    return "";
}

TEST(Scene, APhantomsTargetsReachTheSettingsWithItsMargin) {
    SceneOptions options;
    options.phantom = kPhantoms + "/point_grid.json";
    const auto scene = load_scene(options);
    ASSERT_TRUE(scene->phantom);
    EXPECT_FALSE(scene->volume);
    EXPECT_EQ(scene->probe_preset, "linear");  // the file's "probe" entry
    SimulationSettings s;
    s.quality = Quality::standard;
    scene->apply_to(s);
    // point_grid.json: 14 wires, smoothing 0.2 mm, so interfaces reach max(2 x 0.2, 1) mm
    // and a painted core's margin is its smoothing plus a texel of the quality's map.
    EXPECT_EQ(s.targets.size(), 14u);
    EXPECT_DOUBLE_EQ(s.trace.interface_reach_mm, 1.0);
    EXPECT_DOUBLE_EQ(s.target_margin_mm, 0.2 + quality_level(Quality::standard).map_pixel_mm);
}

TEST(Scene, APoseMoreThan10mmOutsideIsRefusedNamingItsSource) {
    SceneOptions options;
    options.phantom = kPhantoms + "/cyst_and_stone.json";
    const auto scene = load_scene(options);
    probe::Pose pose = scene->start.pose;
    pose.position.y = -9.0;  // 9 mm of coupling above the top face: allowed
    EXPECT_NO_THROW(scene->require_inside(pose, "--pose"));
    pose.position.y = -11.0;
    const std::string message = input_error([&] { scene->require_inside(pose, "--pose"); });
    EXPECT_NE(message.find("--pose"), std::string::npos) << message;
    EXPECT_NE(message.find("outside the phantom"), std::string::npos) << message;
    // Clamped, the face is back on the box.
    EXPECT_DOUBLE_EQ(scene->clamp(pose).position.y, 0.0);
}

TEST(Scene, OptionsAreCheckedBeforeAnythingLoads) {
    SceneOptions bad_view;
    bad_view.view = "sagittal";
    EXPECT_NE(input_error([&] { load_scene(bad_view); }).find("--view"), std::string::npos);
    SceneOptions both;
    both.phantom = kPhantoms + "/mirror.json";
    both.volume = "/nonexistent.nii";
    EXPECT_NE(input_error([&] { load_scene(both); }).find("--phantom"), std::string::npos);
    SceneOptions missing;
    missing.phantom = kPhantoms + "/no_such_phantom.json";
    EXPECT_NE(input_error([&] { load_scene(missing); }).find("no_such_phantom"), std::string::npos);
    // The probe a volume's scene is meant for is known before the volume loads.
    SceneOptions head;
    EXPECT_EQ(head.volume_probe_preset(), "convex");
    head.view = "temporal";
    EXPECT_EQ(head.volume_probe_preset(), "phased");
    head.volume = "scan.nii";
    EXPECT_EQ(head.volume_probe_preset(), "linear");
}

TEST(Scene, APhantomsContextIsItsImpedance) {
    SceneOptions options;
    options.phantom = kPhantoms + "/parallel_plates.json";
    const auto scene = load_scene(options);
    const auto context = scene->context_volume();
    // Water at 37 C, rho c = 993 kg/m^3 x 1524 m/s = 1.513 MRayl (Duck 1990, the tissue
    // table's values): the median sample of a phantom that is mostly water.
    std::vector<float> values(context->voxels().begin(), context->voxels().end());
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    EXPECT_NEAR(values[values.size() / 2], 993.0 * 1524.0 * 1e-6, 1e-3);
}

}  // namespace
}  // namespace sonotrace::imaging
