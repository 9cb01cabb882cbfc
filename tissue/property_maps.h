#pragma once
// Acoustic property fields on a grid: what a transfer function makes of a (resampled)
// volume. Planar (one Volume per property) because they are written out as pictures
// and packed into an AcousticMap for tracing.
#include <array>
#include <span>

#include "tissue/acoustic_properties.h"
#include "tissue/transfer_function.h"
#include "tissue/volume.h"

namespace sonotrace::tissue {

struct PropertyMaps {
    std::array<Volume, kPropertyCount> fields;

    const Volume& operator[](Property p) const { return fields[std::size_t(p)]; }
    Volume& operator[](Property p) { return fields[std::size_t(p)]; }
    const VolumeGeometry& geometry() const { return fields[0].geometry(); }
    // Z = rho * c in MRayl.
    Volume impedance() const;
};

// Applies a bound transfer function to every voxel of `values`.
PropertyMaps classify(const Volume& values, const TransferFunction& tf);

// The tissue label (TransferFunction::tissue_label) of every voxel: the ground truth.
Volume tissue_labels(const Volume& values, const TransferFunction& tf);

// A factor on one property of one tissue: a dataset's per-frame draw of the tissue's
// properties (ui/dataset/spec.h).
struct LabelScale {
    int label = 0;  // tissue label (tissue index + 1), as tissue_labels gives
    Property property = Property::speed_of_sound;
    double factor = 1.0;
};
// Every texel labelled `scale.label` gets its property times the factor, held to the
// property's accepted range (kPropertyInfo); a texel's label is the tissue covering it by
// half or more, so a boundary texel mixing two tissues scales as its majority does.
void scale_by_label(PropertyMaps& maps, const Volume& labels, std::span<const LabelScale> scales);

}  // namespace sonotrace::tissue
