// The membranes the Colin27 T1 cannot show (falx cerebri, choroid plexus), placed by
// anatomy: where they go on a coronal plane through the lateral ventricles, and that the
// default intraoperative frame shows the falx brighter than the brain beside it.
#include <gtest/gtest.h>

#include "imaging/colin27.h"
#include "imaging/scene/scene.h"
#include "imaging/simulation.h"
#include "probe/transducer.h"
#include "tissue/property_maps.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace {
namespace {

const imaging::VolumeSource& head() {
    static const imaging::VolumeSource source = imaging::load_volume_source({});
    return source;
}

imaging::PlaneMapper head_mapper() {
    // The embedded head: VolumeSource adds the membranes (is_default).
    return [](const tissue::VolumeGeometry& grid, tissue::Volume* labels) {
        return head().plane_properties(grid, labels);
    };
}

TEST(HeadMembranes, FalxInTheFissureAndPlexusOnTheVentricleFloors) {
    // The MNI coronal plane y = -14 (through the bodies of the lateral ventricles),
    // x in [-30, 30], z in [0, 80], 0.5 mm.
    tissue::VolumeGeometry grid;
    grid.dims = {121, 161, 1};
    grid.spacing = {0.5, 0.5, 1.0};
    grid.origin = {-30.0, -14.0, 80.0};
    grid.direction = glm::dmat3(glm::dvec3(1, 0, 0), glm::dvec3(0, 0, -1), glm::dvec3(0, 1, 0));
    tissue::Volume labels;
    head_mapper()(grid, &labels);
    const int dura = tissue::tissue_label_of("dura"),
              plexus = tissue::tissue_label_of("choroid_plexus"),
              csf = tissue::tissue_label_of("csf");
    int falx_column = 0, fissure_column = 0, plexus_left = 0, plexus_right = 0;
    for (int j = 0; j < grid.dims.y; ++j) {
        for (int i = 0; i < grid.dims.x; ++i) {
            const glm::dvec3 p = grid.index_to_world(glm::dvec3(i, j, 0));
            const int l = int(labels.at(i, j, 0));
            if (l == dura) {
                EXPECT_LT(std::abs(p.x - 0.5), 0.75) << p.x << " " << p.z;
                EXPECT_GT(p.z, 34.0);
            }
            // The midline column from the callosum to the vertex: the falx throughout.
            if (std::abs(p.x - 0.5) < 0.25 && p.z > 36.0 && p.z < 70.0) {
                ++fissure_column;
                falx_column += l == dura;
            }
            if (l == plexus) {
                (p.x < 0 ? plexus_left : plexus_right)++;
                // On a floor: CSF (or more plexus) above it within 3 mm.
                bool fluid_above = false;
                for (int up = 1; up <= 6 && j - up >= 0; ++up) {
                    const int a = int(labels.at(i, j - up, 0));
                    fluid_above |= a == csf;
                }
                EXPECT_TRUE(fluid_above) << p.x << " " << p.z;
            }
        }
    }
    EXPECT_GT(fissure_column, 50);
    EXPECT_EQ(falx_column, fissure_column);
    EXPECT_GT(plexus_left, 20);  // both lateral ventricles
    EXPECT_GT(plexus_right, 20);
}

// On the temple the scalp (skin, fat, the temporalis) covers the squama by several
// millimetres; the T1 air/skin edge passes through the skull's dark intensities, and
// read as bone it put a film of bone under the probe (R^2 = 0.37 against tissue: a
// reverberating cavity above the skull). Along the temporal view's central line, after
// the plane is readied for the probe, the first bone-fast sample (c > 1800 m/s) lies
// deeper than 3 mm, and the skull is still there within 25 mm.
TEST(HeadMembranes, UnderTheTemporalProbeTheSkinIsNotBone) {
    const imaging::ScenePlacement scene = imaging::temporal_scene(head().loaded.volume, *head().tf);
    const probe::Transducer t = probe::find_transducer("phased", "test");
    const imaging::PlaneGrid grid = imaging::plane_grid(t, scene.pose, 0.25);
    tissue::Volume labels;
    tissue::PropertyMaps maps = head_mapper()(grid.geometry, &labels);
    imaging::prepare_plane(maps, grid, scene, 5.0, &labels);
    const probe::ScanGeometry g(t);
    double first_bone = -1.0;
    for (double d = 0.0; d <= 25.0 && first_bone < 0.0; d += 0.05) {
        const glm::dvec2 m = g.point(t.lines / 2, d) + grid.to_map;
        const int i = int(std::lround(m.x / grid.geometry.spacing.x)),
                  j = int(std::lround(m.y / grid.geometry.spacing.y));
        if (maps[tissue::Property::speed_of_sound].at(i, j, 0) > 1800.0f) first_bone = d;
    }
    EXPECT_GT(first_bone, 3.0);
    EXPECT_LT(first_bone, 25.0);
}

TEST(HeadMembranes, TheDefaultFrameShowsTheFalxBrighterThanTheBrainBesideIt) {
    const imaging::ScenePlacement scene =
        imaging::craniotomy_scene(head().loaded.volume, *head().tf);
    imaging::SimulationSettings settings;
    settings.transducer = probe::find_transducer("convex", "test");
    settings.imaging.gain_db = 36.0;
    settings.trace.interface_reach_mm = 3.0;
    const imaging::SimulatedFrame out =
        imaging::simulate_plane(head_mapper(), scene, settings, true);
    const cv::Mat& labels = *out.labels;
    const cv::Mat& image = out.frame.image.image;
    const int dura = tissue::tissue_label_of("dura"), brain = tissue::tissue_label_of("brain");
    // Per row: the falx pixels against brain pixels 3-6 mm to either side.
    const int near = int(3.0 / out.frame.image.pixel_mm), far = int(6.0 / out.frame.image.pixel_mm);
    double falx = 0.0, beside = 0.0;
    int n_falx = 0, n_beside = 0;
    for (int r = 0; r < labels.rows; ++r) {
        for (int c = 0; c < labels.cols; ++c) {
            if (labels.at<uint8_t>(r, c) != dura) continue;
            falx += image.at<float>(r, c), ++n_falx;
            for (int d = near; d <= far; ++d) {
                for (int side : {-1, 1}) {
                    const int cc = c + side * d;
                    if (cc < 0 || cc >= labels.cols || labels.at<uint8_t>(r, cc) != brain) continue;
                    beside += image.at<float>(r, cc), ++n_beside;
                }
            }
        }
    }
    ASSERT_GT(n_falx, 200);  // the falx crosses the frame
    ASSERT_GT(n_beside, 1000);
    EXPECT_GT(falx / n_falx, beside / n_beside + 0.05)
        << "falx " << falx / n_falx << ", brain beside it " << beside / n_beside;
}

}  // namespace
}  // namespace sonotrace
