#pragma once
// The pia-arachnoid of the sulci and fissures: in intraoperative and transcranial
// ultrasound the sulci are bright, heterogeneous lines (the pia, the arachnoid and their
// vessels, folded into the sulcus), which a T1 MRI reads as CSF between two banks of
// cortex. On a property map whose transfer function holds brain and CSF (the table's
// entries: the embedded head's, or any brain MRI's), CSF that is
//   thin:       not within an opening of the CSF by a disc of radius kThickCsfMm (1.5 mm):
//               sulci and fissures, not the ventricles or the wide cisterns, whose walls
//               stay as they are (the ventricles are hypoechoic), and
//   by brain:   within kMembraneMm (0.5 mm) of a brain sample,
// becomes the table's "pia_arachnoid" (backscatter 1.0 against brain's 0.35: 9 dB
// brighter). In the plane of each slice of the map (a 2D frame's plane; each elevation
// slice of a 3D one): the opening is taken where the map is sampled, at its own spacing.
#include <cstddef>

#include "tissue/property_maps.h"
#include "tissue/volume.h"

namespace sonotrace::imaging {

constexpr double kThickCsfMm = 1.5;
constexpr double kMembraneMm = 0.5;
constexpr float kValleyDepth = 0.25f;

// Adds the membranes to `maps` (and `labels`, when given). Returns the number of samples
// changed; 0 when the map holds no brain or no CSF.
std::size_t add_sulcal_membranes(tissue::PropertyMaps& maps, tissue::Volume* labels = nullptr);

}  // namespace sonotrace::imaging
