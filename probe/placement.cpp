#include "probe/placement.h"

#include <cmath>

namespace sonotrace::probe {

namespace {
using tissue::Property;
}

std::optional<RayHit> march_until(
    const tissue::Volume& volume, const tissue::TransferFunction& tf, const glm::dvec3& start,
    const glm::dvec3& direction, double max_mm, double step_mm,
    const std::function<bool(const tissue::AcousticProperties&)>& accept,
    std::optional<float> outside) {
    const glm::dvec3 dir = glm::normalize(direction);
    const float background = outside ? *outside : volume.value_range().first;
    for (double t = 0.0; t <= max_mm; t += step_mm) {
        const glm::dvec3 p = start + t * dir;
        const float value =
            volume.sample_trilinear(volume.geometry().world_to_index(p), background);
        if (accept(tf.evaluate(value))) return RayHit{p, t};
    }
    return std::nullopt;
}

std::optional<RayHit> skin_surface(const tissue::Volume& volume, const tissue::TransferFunction& tf,
                                   const glm::dvec3& start, const glm::dvec3& direction,
                                   double max_mm, double relative_change,
                                   std::optional<float> outside) {
    if (!outside) outside = volume.value_range().first;
    const double z0 =
        tf.evaluate(volume.sample_trilinear(volume.geometry().world_to_index(start), *outside))
            .impedance_mrayl();
    return march_until(
        volume, tf, start, direction, max_mm, 0.1,
        [&](const tissue::AcousticProperties& p) {
            const double z = p.impedance_mrayl();
            return std::abs(z - z0) > relative_change * std::max(z, z0);
        },
        outside);
}

std::optional<RayHit> beneath_bone(const tissue::Volume& volume, const tissue::TransferFunction& tf,
                                   const glm::dvec3& start, const glm::dvec3& direction,
                                   double max_mm) {
    auto bone = march_until(volume, tf, start, direction, max_mm, 0.1,
                            [](const tissue::AcousticProperties& p) {
                                return p[Property::speed_of_sound] >= kBoneSpeed;
                            });
    if (!bone) return std::nullopt;
    const glm::dvec3 dir = glm::normalize(direction);
    auto below = march_until(volume, tf, bone->point, dir, max_mm - bone->distance_mm, 0.1,
                             [](const tissue::AcousticProperties& p) {
                                 return p[Property::speed_of_sound] < kBoneSpeed;
                             });
    if (!below) return std::nullopt;
    RayHit inner{below->point, bone->distance_mm + below->distance_mm};
    // A skull has two tables around the diploe (marrow: fat on T1): a second run of bone
    // soon after the first is the inner table, and the cortex lies beneath it.
    for (int table = 0; table < 4; ++table) {
        const double reach = std::min(kDiploeReachMm, max_mm - inner.distance_mm);
        auto next = march_until(volume, tf, inner.point, dir, reach, 0.1,
                                [](const tissue::AcousticProperties& p) {
                                    return p[Property::speed_of_sound] >= kBoneSpeed;
                                });
        if (!next) break;
        auto exit = march_until(volume, tf, next->point, dir,
                                max_mm - inner.distance_mm - next->distance_mm, 0.1,
                                [](const tissue::AcousticProperties& p) {
                                    return p[Property::speed_of_sound] < kBoneSpeed;
                                });
        if (!exit) break;
        inner = {exit->point, inner.distance_mm + next->distance_mm + exit->distance_mm};
    }
    return inner;
}

std::optional<RayHit> after_gap(const tissue::Volume& volume, const tissue::TransferFunction& tf,
                                const glm::dvec3& start, const glm::dvec3& direction, double max_mm,
                                const RayTest& gap, double gap_mm, const RayTest& run,
                                double run_mm, std::optional<float> outside) {
    const glm::dvec3 dir = glm::normalize(direction);
    if (!outside) outside = volume.value_range().first;
    constexpr double kStep = 0.1;
    double gap_start = -1.0, run_start = -1.0;
    bool gap_done = false;
    for (double t = 0.0; t <= max_mm; t += kStep) {
        const glm::dvec3 p = start + t * dir;
        const float value = volume.sample_trilinear(volume.geometry().world_to_index(p), *outside);
        const tissue::AcousticProperties props = tf.evaluate(value);
        const int label = tf.tissue_label(value);
        if (gap_done && run(props, label)) {
            if (run_start < 0.0) run_start = t;
            if (t - run_start >= run_mm) return RayHit{start + run_start * dir, run_start};
            continue;
        }
        run_start = -1.0;
        if (gap(props, label)) {
            if (gap_start < 0.0) gap_start = t;
            if (t - gap_start >= gap_mm) gap_done = true;
        } else {
            gap_start = -1.0;
        }
    }
    return std::nullopt;
}

std::size_t open_craniotomy(tissue::PropertyMaps& maps, double axis_lateral_mm, double radius_mm,
                            double depth_mm, const tissue::AcousticProperties& fill) {
    const tissue::VolumeGeometry& g = maps.geometry();
    const double zc = 0.5 * (g.dims.z - 1);
    std::size_t changed = 0;
    for (int k = 0; k < g.dims.z; ++k) {
        for (int j = 0; j < g.dims.y; ++j) {
            if (j * g.spacing.y > depth_mm) break;
            for (int i = 0; i < g.dims.x; ++i) {
                const double dx = i * g.spacing.x - axis_lateral_mm, dz = (k - zc) * g.spacing.z;
                if (dx * dx + dz * dz > radius_mm * radius_mm) continue;
                const float c = maps[Property::speed_of_sound].at(i, j, k);
                const float rho = maps[Property::density].at(i, j, k);
                if (c > kSoftTissueSpeed[0] && c <= kSoftTissueSpeed[1] && rho >= 900.0f) continue;
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                    maps.fields[f].at(i, j, k) = fill.values[f];
                ++changed;
            }
        }
    }
    return changed;
}

}  // namespace sonotrace::probe
