// The one scene type (phantoms/scene/scene.h): what it takes from a phantom or a volume,
// what it sets in the simulation settings, and the options it refuses before loading.
#include <gtest/gtest.h>

#include "phantoms/scene/scene.h"
#include "tests/test_util.h"
#include "tissue/base/error.h"
#include "tissue/nifti_io.h"

namespace sonotrace::scene {
using namespace imaging;  // the frames the scenes make
namespace {

const std::string kPhantoms = SONOTRACE_SOURCE_DIR "/phantoms";

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
    const std::string message =
        test::input_error_message([&] { scene->require_inside(pose, "--pose"); });
    EXPECT_NE(message.find("--pose"), std::string::npos) << message;
    EXPECT_NE(message.find("outside the phantom"), std::string::npos) << message;
    // Clamped, the face is back on the box.
    EXPECT_DOUBLE_EQ(scene->clamp(pose).position.y, 0.0);
}

TEST(Scene, OptionsAreCheckedBeforeAnythingLoads) {
    SceneOptions bad_view;
    bad_view.view = "sagittal";
    EXPECT_NE(test::input_error_message([&] { load_scene(bad_view); }).find("--view"),
              std::string::npos);
    SceneOptions both;
    both.phantom = kPhantoms + "/mirror.json";
    both.volume = "/nonexistent.nii";
    EXPECT_NE(test::input_error_message([&] { load_scene(both); }).find("--phantom"),
              std::string::npos);
    SceneOptions missing;
    missing.phantom = kPhantoms + "/no_such_phantom.json";
    EXPECT_NE(test::input_error_message([&] { load_scene(missing); }).find("no_such_phantom"),
              std::string::npos);
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

// A volume whose file names its world axes (NIfTI with an sform) is scanned from the
// subject's top, looking down; the same voxels without anatomical axes from the top face
// of the index box. The "head" is a ball of radius 15 mm in air whose voxel axes are
// permuted against the world's (i -> +y, j -> +z, k -> +x), so index and world directions
// disagree: its top, by construction, is the ball's centre + 15 mm along world z.
TEST(Scene, AnAnatomicalVolumeIsScannedFromTheTopLookingDown) {
    tissue::VolumeGeometry g;
    g.dims = {40, 60, 50};
    g.spacing = glm::dvec3(1.0);
    g.direction = glm::dmat3(glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1), glm::dvec3(1, 0, 0));
    g.origin = {-25.0, -20.0, -30.0};
    tissue::Volume ball(g);
    const glm::dvec3 centre = g.index_to_world(glm::dvec3(g.dims - 1) * 0.5);
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i)
                ball.at(i, j, k) =
                    glm::length(g.index_to_world({i, j, k}) - centre) < 15.0 ? 100.0f : 0.0f;
    const std::string path = ::testing::TempDir() + "/anatomical_ball.nii.gz";
    tissue::write_nifti(ball, path);
    SceneOptions options;
    options.volume = path;
    options.tf = "mri-t1-head";  // 0 is air, the ball is tissue: its surface is the skin
    const auto scene = load_scene(options);
    const probe::Pose pose = scene->start.pose;
    EXPECT_NEAR(glm::dot(pose.axial(), glm::dvec3(0, 0, -1)), 1.0, 1e-9);   // inferior
    EXPECT_NEAR(glm::dot(pose.lateral(), glm::dvec3(1, 0, 0)), 1.0, 1e-9);  // left to right
    const glm::dvec3 top = centre + glm::dvec3(0, 0, 15);
    // The skin search steps 0.5 mm through a voxelised, interpolated surface.
    EXPECT_NEAR(glm::length(pose.position - top), 0.0, 1.0) << pose.to_string();
    // Without anatomical axes the same voxels keep the index box's top face (+j).
    VolumeSource plain = load_volume_source(options);
    plain.loaded.anatomical = false;
    const probe::Pose indexed = default_volume_pose(plain);
    EXPECT_NEAR(glm::dot(indexed.axial(), g.direction[1]), 1.0, 1e-9);
}

}  // namespace
}  // namespace sonotrace::scene
