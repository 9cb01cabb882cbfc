#pragma once
// The pia-arachnoid of the sulci and fissures: in intraoperative and transcranial
// ultrasound the sulci are bright, heterogeneous lines (the pia, the arachnoid and their
// vessels, folded into the sulcus), which a T1 MRI reads as CSF, or as a darker seam of
// partial volume, between two banks of cortex. On a property map whose transfer function
// holds brain and CSF (the table's entries: the embedded head's, or any brain MRI's),
// each sample's fraction f of the way from CSF (0) to brain (1) in speed, density and
// backscatter (other tissues: 1). A sample takes the backscatter and scatterer density
// of the table's "pia_arachnoid" (1.0 against brain's 0.35: 9 dB brighter; its label in
// `labels`), keeping its speed, density, attenuation and roughness (thinner than the beam,
// the membrane scatters but does not reflect or refract), where
//   a valley:   f lies kValleyDepth (0.25) or more below its closing by a square of half
//               side kThickCsfMm (1.5 mm): a seam of CSF narrower than 3 mm (a black
//               top-hat), partial-volume seams included;
//   by brain:   within kMembraneMm (0.5 mm) of a sample with f >= 1/2;
//   not wide:   not within 1.5 mm of CSF (f < 1/2) that survives an opening by the same
//               square (the ventricles and wide cisterns, whose walls stay as they are:
//               the ventricles are hypoechoic), nor of another tissue (the plexus on a
//               ventricle's floor, bone, dura).
// In the plane of each slice of the map (a 2D frame's plane; each elevation slice of a
// 3D one), at the map's own spacing. Squares, not discs: OpenCV's morphology by a
// rectangle is separable (about 1.5 ms a frame; by an ellipse 3.5).
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
