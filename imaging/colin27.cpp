#include "imaging/colin27.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <numeric>
#include <string>
#include <vector>

#include "probe/placement.h"
#include "probe/pose.h"
#include "tissue/base/error.h"
#include "tissue/nifti_io.h"
#include "tissue/tissue_table.h"

namespace sonotrace::imaging {

namespace {

// The brain mask mricron-data ships with the Colin27 head (skull-stripped, same grid).
constexpr const char* kColin27BrainMaskPath = "/usr/share/mricron/templates/ch2bet.nii.gz";

// On the grid of `head`, 1 where a voxel lies outside the skull: reachable from the volume's
// border without crossing cortical bone (the transfer function's label) or coming within
// 2 mm of the brain mask. The margin closes the gaps a 1 mm T1 skull has; the cranium's
// CSF lies inside it or behind bone.
tissue::Volume outside_the_skull(const tissue::Volume& head, const tissue::TransferFunction& tf) {
    const tissue::Volume mask = tissue::read_nifti(kColin27BrainMaskPath).volume;
    const glm::ivec3 n = head.dims();
    if (mask.dims() != n)
        throw base::InputError(kColin27BrainMaskPath, "dim",
                               "the brain mask's grid differs from the head's: is the volume "
                               "the Colin27 head?");
    const std::size_t count = head.size();
    // Within 2 mm of the brain (two dilations: faces, then faces, edges and corners).
    std::vector<uint8_t> near(count, 0);
    for (std::size_t v = 0; v < count; ++v) near[v] = mask.voxels()[v] > 0.0f;
    for (const bool diagonal : {false, true}) {
        std::vector<uint8_t> grown = near;
        for (int k = 1; k < n.z - 1; ++k)
            for (int j = 1; j < n.y - 1; ++j)
                for (int i = 1; i < n.x - 1; ++i) {
                    const std::size_t v = head.linear_index(i, j, k);
                    if (near[v]) continue;
                    for (int dk = -1; dk <= 1 && !grown[v]; ++dk)
                        for (int dj = -1; dj <= 1 && !grown[v]; ++dj)
                            for (int di = -1; di <= 1; ++di) {
                                if (!diagonal && std::abs(di) + std::abs(dj) + std::abs(dk) != 1)
                                    continue;
                                if (near[head.linear_index(i + di, j + dj, k + dk)]) {
                                    grown[v] = 1;
                                    break;
                                }
                            }
                }
        near = std::move(grown);
    }
    const int bone = tissue::tissue_label_of("cortical_bone");
    tissue::Volume outside(head.geometry());
    std::vector<std::size_t> front;
    auto enter = [&](int i, int j, int k) {
        const std::size_t v = head.linear_index(i, j, k);
        if (outside.voxels()[v] > 0.0f || near[v] || tf.tissue_label(head.voxels()[v]) == bone)
            return;
        outside.voxels()[v] = 1.0f;
        front.push_back(v);
    };
    for (int k = 0; k < n.z; ++k)
        for (int j = 0; j < n.y; ++j)
            for (int i = 0; i < n.x; ++i)
                if (i == 0 || j == 0 || k == 0 || i == n.x - 1 || j == n.y - 1 || k == n.z - 1)
                    enter(i, j, k);
    while (!front.empty()) {
        const std::size_t v = front.back();
        front.pop_back();
        const int i = int(v % std::size_t(n.x)), j = int(v / std::size_t(n.x) % std::size_t(n.y)),
                  k = int(v / (std::size_t(n.x) * std::size_t(n.y)));
        if (i > 0) enter(i - 1, j, k);
        if (i < n.x - 1) enter(i + 1, j, k);
        if (j > 0) enter(i, j - 1, k);
        if (j < n.y - 1) enter(i, j + 1, k);
        if (k > 0) enter(i, j, k - 1);
        if (k < n.z - 1) enter(i, j, k + 1);
    }
    return outside;
}

// outside_the_skull() of the process's head and transfer function, computed once (every
// frame plane asks; the GUI can change the transfer function, which moves the bone).
const tissue::Volume& outside_the_skull_once(const tissue::Volume& head,
                                             const tissue::TransferFunction& tf) {
    static std::mutex mutex;
    static tissue::Volume outside;
    static std::string key;
    const glm::ivec3 n = head.dims();
    std::string now = std::to_string(n.x) + "x" + std::to_string(n.y) + "x" + std::to_string(n.z) +
                      " " + tf.describe().dump();
    const std::lock_guard lock(mutex);
    if (now != key) {
        outside = outside_the_skull(head, tf);
        key = std::move(now);
    }
    return outside;
}

}  // namespace

std::size_t add_colin27_anatomy(const tissue::Volume& head, const tissue::TransferFunction& tf,
                                float outside, const tissue::VolumeGeometry& grid,
                                tissue::PropertyMaps& maps, tissue::Volume* labels, bool scalp) {
    using tissue::Property;
    const tissue::TissueEntry& dura = tissue::find_tissue("dura", "", "");
    const tissue::TissueEntry& plexus = tissue::find_tissue("choroid_plexus", "", "");
    const int brain = tissue::tissue_label_of("brain");
    auto is_csf = [&](const tissue::PropertyMaps& m, int i, int j, int k) {
        return m[Property::backscatter].at(i, j, k) < 0.05f &&
               std::abs(m[Property::speed_of_sound].at(i, j, k) - 1515.0f) < 10.0f;
    };
    auto is_brain_or_csf = [&](int i, int j, int k) {
        const float c = maps[Property::speed_of_sound].at(i, j, k);
        return c > 1500.0f && c < 1580.0f && maps[Property::density].at(i, j, k) > 990.0f;
    };
    const tissue::TissueEntry& muscle = tissue::find_tissue("muscle", "", "");
    static const tissue::Volume none;
    const tissue::Volume& outside_skull = scalp ? outside_the_skull_once(head, tf) : none;
    // Outside the skull where the mask, interpolated between voxel centres, passes 1/2: a
    // nearest-voxel test cut the scalp in millimetre steps, whose corners the tracer met
    // as faces (the step test on the default frame saw them).
    auto in_the_scalp = [&](const glm::dvec3& p) {
        return outside_skull.sample_trilinear(outside_skull.geometry().world_to_index(p), 0.0f) >
               0.5f;
    };
    auto set = [&](int i, int j, int k, const tissue::TissueEntry& t) {
        for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
            maps.fields[f].at(i, j, k) = t.properties.values[f];
        if (labels) labels->at(i, j, k) = float(tissue::tissue_label_of(std::string(t.key)));
    };
    // Rows in parallel (each sample reads and writes only itself); counts summed after.
    const glm::ivec3 n = grid.dims;
    std::vector<std::size_t> changed_in_row(std::size_t(n.y) * std::size_t(n.z), 0);
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        std::size_t& changed = changed_in_row[std::size_t(row)];
        for (int i = 0; i < n.x; ++i) {
            const glm::dvec3 p = grid.index_to_world(glm::dvec3(i, j, k));
            if (scalp && is_brain_or_csf(i, j, k) && in_the_scalp(p)) {
                set(i, j, k, muscle);
                ++changed;
                continue;
            }
            if (std::abs(p.x - 0.5) < 0.75 && p.z > 34.0 && is_brain_or_csf(i, j, k)) {
                set(i, j, k, dura);
                ++changed;
                continue;
            }
            const double ax = std::abs(p.x);
            if (ax > 3.0 && ax < 22.0 && p.y > -45.0 && p.y < -5.0 && p.z > 8.0 && p.z < 26.0 &&
                is_csf(maps, i, j, k)) {
                // The floor: the head 2.5 mm lower is tissue, not CSF.
                const glm::dvec3 below = p - glm::dvec3(0.0, 0.0, 2.5);
                const float v =
                    head.sample_trilinear(head.geometry().world_to_index(below), outside);
                if (tf.tissue_label(v) == brain) {
                    set(i, j, k, plexus);
                    ++changed;
                }
            }
        }
    });
    return std::accumulate(changed_in_row.begin(), changed_in_row.end(), std::size_t(0));
}

ScenePlacement craniotomy_scene(const tissue::Volume& head, const tissue::TransferFunction& tf) {
    // MNI coordinates (mm): aim between the bodies of the lateral ventricles, slightly to
    // the right, from above and to the right; coronal plane (lateral axis left-right).
    const glm::dvec3 target(8.0, -14.0, 18.0);
    const glm::dvec3 approach = glm::normalize(glm::dvec3(0.42, 0.0, 1.0));  // target -> entry
    const glm::dvec3 outside = target + 130.0 * approach;
    // Skin, then the cortex: the first 3 mm of brain after at least 2 mm of skull and
    // CSF (the T1 skull is dark like CSF; the scalp can look like brain).
    const auto skin = probe::skin_surface(head, tf, outside, -approach, 120.0);
    const int brain = tissue::tissue_label_of("brain"), csf = tissue::tissue_label_of("csf"),
              bone = tissue::tissue_label_of("cortical_bone");
    const auto cortex =
        skin ? probe::after_gap(
                   head, tf, skin->point + 1.0 * (-approach), -approach, 60.0,
                   [&](const tissue::AcousticProperties&, int l) { return l == csf || l == bone; },
                   2.0, [&](const tissue::AcousticProperties&, int l) { return l == brain; }, 3.0)
             : std::nullopt;
    if (!cortex)
        throw base::InputError("scene craniotomy", "pose",
                               "no skull and cortex found along the approach to the ventricles: "
                               "is the volume the Colin27 head?");
    ScenePlacement scene;
    scene.pose = probe::Pose::looking(cortex->point - 0.5 * approach, -approach, {1.0, 0.0, 0.0});
    scene.craniotomy_radius_mm = 32.0;
    scene.craniotomy_depth_mm = 12.0;
    scene.description =
        "intraoperative: convex probe on the right parietal cortex through a 64 mm "
        "craniotomy, coronal plane through the lateral ventricles";
    return scene;
}

ScenePlacement temporal_scene(const tissue::Volume& head, const tissue::TransferFunction& tf) {
    const probe::Pose temple = probe::colin27_temporal_pose();
    const glm::dvec3 outside = temple.position - 30.0 * temple.axial();
    const auto skin = probe::skin_surface(head, tf, outside, temple.axial(), 80.0);
    if (!skin)
        throw base::InputError("scene temporal", "pose",
                               "no skin found on the right temple: is the volume the "
                               "Colin27 head?");
    ScenePlacement scene;
    scene.pose = temple;
    scene.pose.position = skin->point;
    scene.description =
        "transtemporal: phased probe on the skin of the right temple, axial plane through "
        "the midbrain, imaging across the skull";
    return scene;
}

}  // namespace sonotrace::imaging
