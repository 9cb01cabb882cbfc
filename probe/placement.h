#pragma once
// Placing a probe on a volume: walk along a ray through the classified volume to the
// first strong interface (the skin) or to the inner surface of the first bone (the
// cortex under a craniotomy), and open a virtual craniotomy in property maps.
#include <functional>
#include <optional>

#include <glm/glm.hpp>

#include "tissue/property_maps.h"
#include "tissue/transfer_function.h"
#include "tissue/volume.h"

namespace sonotrace::probe {

struct RayHit {
    glm::dvec3 point;    // mm, world
    double distance_mm;  // from the ray's start
};

// The first point along start + t * direction (t in [0, max_mm], steps of step_mm)
// where `accept` holds for the acoustic properties there. `tf` must be bound to `volume`.
// Every function here takes the value assumed outside the volume as `outside`; without
// it, the volume's minimum (a scan of every voxel: pass it when placing often).
std::optional<RayHit> march_until(
    const tissue::Volume& volume, const tissue::TransferFunction& tf, const glm::dvec3& start,
    const glm::dvec3& direction, double max_mm, double step_mm,
    const std::function<bool(const tissue::AcousticProperties&)>& accept,
    std::optional<float> outside = std::nullopt);

// The skin: the first point whose impedance differs from the starting medium's by more
// than `relative_change` (0.5 = 50 %); from air that is the first tissue.
std::optional<RayHit> skin_surface(const tissue::Volume& volume, const tissue::TransferFunction& tf,
                                   const glm::dvec3& start, const glm::dvec3& direction,
                                   double max_mm, double relative_change = 0.5,
                                   std::optional<float> outside = std::nullopt);

// Speed of sound above which a sample counts as bone (m/s).
inline constexpr float kBoneSpeed = 2000.0f;

// The inner surface of the first bone along the ray: the first point after a run of
// bone (speed >= kBoneSpeed) where the speed drops below it again, or, if more bone
// follows within kDiploeReachMm (the inner table beyond the diploe), after that.
inline constexpr double kDiploeReachMm = 6.0;
std::optional<RayHit> beneath_bone(const tissue::Volume& volume, const tissue::TransferFunction& tf,
                                   const glm::dvec3& start, const glm::dvec3& direction,
                                   double max_mm);

// Tissue at a point of a ray: its properties and its label (TransferFunction::tissue_label).
using RayTest = std::function<bool(const tissue::AcousticProperties&, int label)>;

// The first point along the ray that begins a run of at least `run_mm` where `run`
// holds, after a run of at least `gap_mm` where `gap` holds: the cortex beneath the
// skull and CSF of an MRI head (whose T1 skull can look like CSF), for instance.
std::optional<RayHit> after_gap(const tissue::Volume& volume, const tissue::TransferFunction& tf,
                                const glm::dvec3& start, const glm::dvec3& direction, double max_mm,
                                const RayTest& gap, double gap_mm, const RayTest& run,
                                double run_mm, std::optional<float> outside = std::nullopt);

// A virtual craniotomy on a probe-aligned grid (tissue/resample.h axes: i lateral,
// j depth, k elevation): within `radius_mm` of the beam axis and shallower than
// `depth_mm` below the grid's first row, bone, air and fat (anything outside the soft
// tissue range kSoftTissueSpeed or lighter than 900 kg/m^3) become `fill` (saline).
// `axis_lateral_mm` is the lateral coordinate of the beam axis from the grid's first
// column. Returns the number of samples changed.
inline constexpr float kSoftTissueSpeed[2] = {1460.0f, 1700.0f};  // m/s, (low, high]
std::size_t open_craniotomy(tissue::PropertyMaps& maps, double axis_lateral_mm, double radius_mm,
                            double depth_mm, const tissue::AcousticProperties& fill);

}  // namespace sonotrace::probe
