#pragma once
// The embedded default head (Colin27, MNI coordinates): its two views, and the membranes
// its T1 MRI does not show. Everything here knows this one head's anatomy; the frame
// pipeline (imaging/simulation.h) does not.
#include <cstddef>

#include "imaging/simulation.h"
#include "tissue/property_maps.h"
#include "tissue/transfer_function.h"
#include "tissue/volume.h"

namespace sonotrace::imaging {

// Intraoperative view: the convex probe on the right parietal cortex through a
// craniotomy, coronal plane down through both lateral ventricles. `tf` bound to `head`.
ScenePlacement craniotomy_scene(const tissue::Volume& head, const tissue::TransferFunction& tf);
// The phased probe on the skin of the right temple (transtemporal window), axial plane.
ScenePlacement temporal_scene(const tissue::Volume& head, const tissue::TransferFunction& tf);

// What the Colin27 T1 MRI shows as CSF or brain but is not, placed by anatomy (MNI
// coordinates, mm) on a grid whose properties came from `head` (whose value outside is
// `outside`):
//   scalp (with `scalp`): the skin, galea and temporalis have the intensities of brain
//     and CSF; outside
//     the skull (reachable from the volume's border without crossing bone or coming
//     within 2 mm of the brain mask mricron-data ships with the head, ch2bet) they are
//     muscle. Read as brain, the scalp was a duct that the automatic TGC (brain's
//     attenuation) lit with reverberation across the temporal view;
//   falx cerebri: the sheet of dura in the interhemispheric fissure, |x - 0.5| < 0.75,
//     above the corpus callosum (z > 34), where the grid holds brain or CSF;
//   choroid plexus: the lateral ventricles' CSF within 2.5 mm above their floor (the
//     head 2.5 mm lower is not CSF), 3 < |x| < 22, -45 < y < -5, 8 < z < 26 (body and
//     atrium).
// The membranes are hyperechoic in intraoperative and neonatal cranial ultrasound.
// `labels` (the grid's tissue labels, optional) follow. Returns the number of samples
// changed. Throws base::InputError when the brain mask is missing or not on the head's
// grid.
std::size_t add_colin27_anatomy(const tissue::Volume& head, const tissue::TransferFunction& tf,
                                float outside, const tissue::VolumeGeometry& grid,
                                tissue::PropertyMaps& maps, tissue::Volume* labels = nullptr,
                                bool scalp = true);

}  // namespace sonotrace::imaging
