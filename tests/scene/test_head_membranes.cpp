// The membranes the Colin27 T1 cannot show (falx cerebri, choroid plexus), placed by
// anatomy: where they go on a coronal plane through the lateral ventricles, and that the
// default intraoperative frame shows the falx brighter than the brain beside it.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

#include "imaging/colin27.h"
#include "imaging/simulation.h"
#include "imaging/sulcal_membranes.h"
#include "phantoms/scene/scene.h"
#include "probe/transducer.h"
#include "tissue/nifti_io.h"
#include "tissue/property_maps.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace {
namespace {

const scene::VolumeSource& head() {
    static const scene::VolumeSource source = scene::load_volume_source({});
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

// The scalp (skin, the temporalis, the galea) has the T1 intensities of brain and CSF,
// and read as such it was a duct of brain-like tissue outside the skull that the
// automatic TGC (brain's attenuation) lit with reverberation. On the temporal view's
// axial plane (MNI z = 2), independently of the rule that relabels it: walking in from
// outside along six rays through the centre (the temples, 30 degrees either side), between the skin
// (the first voxel the transfer function does not read as air) and the skull (the first run of 1 mm
// of bone at least 3 mm deeper), the plane holds muscle or fat; and no sample inside the brain mask
// mricron-data ships with the head (ch2bet) is muscle.
TEST(HeadMembranes, TheScalpIsMuscleAndTheBrainIsNot) {
    const tissue::Volume& head_volume = head().loaded.volume;
    const tissue::TransferFunction& tf = *head().tf;
    tissue::VolumeGeometry grid;  // MNI z = 2, x and y over the head, 0.5 mm
    grid.dims = {381, 441, 1};
    grid.spacing = {0.5, 0.5, 1.0};
    grid.origin = {-95.0, -125.0, 2.0};
    tissue::Volume labels;
    head_mapper()(grid, &labels);
    const int muscle = tissue::tissue_label_of("muscle"), fat = tissue::tissue_label_of("fat"),
              bone = tissue::tissue_label_of("cortical_bone"), air = tissue::tissue_label_of("air");
    auto label_at = [&](const glm::dvec3& p) {
        const glm::dvec3 ijk = grid.world_to_index(p);
        return int(labels.at(int(std::lround(ijk.x)), int(std::lround(ijk.y)), 0));
    };
    auto raw_label = [&](const glm::dvec3& p) {
        return tf.tissue_label(
            head_volume.sample_trilinear(head_volume.geometry().world_to_index(p), head().outside));
    };
    const glm::dvec3 centre(0.0, -18.0, 2.0);
    for (const double degrees : {-30.0, 0.0, 30.0, 150.0, 180.0, 210.0}) {
        const double a = degrees * std::numbers::pi / 180.0;
        const glm::dvec3 out(std::cos(a), std::sin(a), 0.0);
        const double start = 110.0;
        double skin = -1.0, skull = -1.0, bone_run = 0.0;
        for (double r = start; r > 30.0 && skull < 0.0; r -= 0.5) {
            const int l = raw_label(centre + r * out);
            if (skin < 0.0 && l != air) skin = r;
            if (skin < 0.0 || r > skin - 3.0) continue;
            bone_run = l == bone ? bone_run + 0.5 : 0.0;
            if (bone_run >= 1.0) skull = r + bone_run;
        }
        ASSERT_GT(skin, 0.0) << "no skin along " << out.x << " " << out.y;
        ASSERT_GT(skull, 0.0) << "no skull along " << out.x << " " << out.y;
        int scalp = 0, muscle_or_fat = 0;
        for (double r = skin - 1.0; r > skull + 1.0; r -= 0.5) {
            const int l = label_at(centre + r * out);
            ++scalp;
            muscle_or_fat += l == muscle || l == fat;
        }
        ASSERT_GE(scalp, 4) << "a scalp of 3 mm at least along " << out.x << " " << out.y;
        EXPECT_GE(muscle_or_fat, scalp * 9 / 10)
            << "along " << out.x << " " << out.y << ": skin at " << skin << " mm, skull at "
            << skull << " mm";
    }
    const tissue::Volume mask =
        tissue::read_nifti("/usr/share/mricron/templates/ch2bet.nii.gz").volume;
    int inside = 0, muscle_inside = 0;
    for (int j = 0; j < grid.dims.y; ++j)
        for (int i = 0; i < grid.dims.x; ++i) {
            const glm::dvec3 p = grid.index_to_world(glm::dvec3(i, j, 0));
            if (mask.sample_nearest(mask.geometry().world_to_index(p), 0.0f) <= 0.0f) continue;
            ++inside;
            muscle_inside += int(labels.at(i, j, 0)) == muscle;
        }
    EXPECT_GT(inside, 50000);
    EXPECT_EQ(muscle_inside, 0);
}

// Over a craniotomy the scalp is turned back: the craniotomy view keeps the MRI's
// values there (near the saline a surgeon fills the window with); the temporal view, and
// a probe placed anywhere else on the head, meet the scalp as muscle.
TEST(HeadMembranes, OnlyTheCraniotomyTurnsTheScalpBack) {
    for (const char* view : {"craniotomy", "temporal"}) {
        scene::SceneOptions options;
        options.view = view;
        const auto scene = scene::load_scene(options);
        const probe::Transducer t = probe::find_transducer(scene->probe_preset, "test");
        const imaging::PlaneGrid grid = imaging::plane_grid(t, scene->start.pose, 0.5);
        tissue::Volume labels;
        scene->mapper(grid.geometry, &labels);
        const int muscle = tissue::tissue_label_of("muscle");
        int count = 0;
        for (const float l : labels.voxels()) count += int(l) == muscle;
        if (std::string(view) == "craniotomy") {
            EXPECT_EQ(count, 0) << view;
        } else {
            EXPECT_GT(count, 1000) << view;
        }
    }
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

// The sulci's pia-arachnoid (imaging/sulcal_membranes.h) on a synthetic brain map at
// 0.25 mm, whose answers follow from the rule's geometry: a 1 mm line of CSF between
// brain (a sulcus) and a 1 mm line of half-volume CSF (fraction 0.6, as a T1 shows a
// thinner sulcus: brain-like, 0.4 below its banks) become pia throughout, being thinner
// than the 3 mm opening and within 0.5 mm of brain; a 16 mm disc of CSF (a ventricle)
// keeps its CSF, walls included; CSF beside another tissue (fat) stays CSF; a map
// without brain changes nowhere. The membranes take the pia's backscatter (1.0, which no
// other sample has here) and keep their speed.
TEST(SulcalMembranes, ThinCsfBetweenBrainBecomesPiaAndWideCsfStaysCsf) {
    tissue::VolumeGeometry grid;
    grid.dims = {200, 200, 1};
    grid.spacing = {0.25, 0.25, 1.0};
    const auto& brain = tissue::find_tissue("brain", "", "");
    const auto& csf = tissue::find_tissue("csf", "", "");
    const auto& fat = tissue::find_tissue("fat", "", "");
    auto make = [&](bool with_brain) {
        tissue::PropertyMaps maps;
        for (auto& f : maps.fields) f = tissue::Volume(grid);
        for (int j = 0; j < 200; ++j)
            for (int i = 0; i < 200; ++i) {
                const double x = i * 0.25, y = j * 0.25;
                tissue::AcousticProperties p = with_brain ? brain.properties : fat.properties;
                if (x >= 10.0 && x < 11.0) p = csf.properties;  // sulcus
                if (x >= 20.0 && x < 21.0) p = tissue::lerp(csf.properties, brain.properties, 0.6f);
                if (std::hypot(x - 36.0, y - 25.0) < 8.0) p = csf.properties;  // ventricle
                if (x >= 5.0 && x < 6.0 && y < 10.0) p = csf.properties;       // by fat:
                if (x >= 3.0 && x < 5.0 && y < 10.0) p = fat.properties;       // not a sulcus
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                    maps.fields[f].at(i, j) = p.values[f];
            }
        return maps;
    };
    tissue::PropertyMaps maps = make(true);
    tissue::Volume labels(grid);
    const std::size_t changed = imaging::add_sulcal_membranes(maps, &labels);
    const float pia = float(tissue::tissue_label_of("pia_arachnoid"));
    int sulcus = 0, partial = 0, ventricle = 0, by_fat = 0, elsewhere = 0;
    for (int j = 0; j < 200; ++j)
        for (int i = 0; i < 200; ++i) {
            const double x = i * 0.25, y = j * 0.25;
            const bool is_pia = labels.at(i, j) == pia;
            EXPECT_EQ(is_pia, maps[tissue::Property::backscatter].at(i, j) == 1.0f);
            const bool inner = y > 2.0 && y < 48.0;  // clear of the map's edges
            // The membrane scatters; its samples keep their speed (no new interface).
            if (x >= 10.0 && x < 11.0) {
                EXPECT_EQ(maps[tissue::Property::speed_of_sound].at(i, j),
                          csf.properties[tissue::Property::speed_of_sound]);
            }
            if (x >= 10.0 && x < 11.0)
                sulcus += inner && !is_pia;
            else if (x >= 20.0 && x < 21.0)
                partial += inner && !is_pia;
            else if (std::hypot(x - 36.0, y - 25.0) < 8.5)
                ventricle += is_pia;
            else if (x >= 5.0 && x < 6.0 && y < 10.0)
                by_fat += is_pia;
            else
                elsewhere += is_pia;
        }
    EXPECT_EQ(sulcus, 0) << "sulcus samples left as CSF";
    EXPECT_EQ(partial, 0) << "half-volume sulcus samples left as they were";
    EXPECT_EQ(ventricle, 0) << "ventricle samples made pia";
    EXPECT_EQ(by_fat, 0) << "CSF beside fat made pia";
    EXPECT_EQ(elsewhere, 0) << "pia beyond the sulci";
    EXPECT_GT(changed, std::size_t(2 * 4 * 184));
    tissue::PropertyMaps no_brain = make(false);
    EXPECT_EQ(imaging::add_sulcal_membranes(no_brain), std::size_t(0));
}

}  // namespace
}  // namespace sonotrace
