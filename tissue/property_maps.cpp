#include "tissue/property_maps.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace sonotrace::tissue {

Volume PropertyMaps::impedance() const {
    Volume z(geometry());
    const auto& c = (*this)[Property::speed_of_sound].voxels();
    const auto& rho = (*this)[Property::density].voxels();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, z.size(), 4096), [&](const auto& r) {
        for (std::size_t n = r.begin(); n != r.end(); ++n)
            z.voxels()[n] = float(double(c[n]) * rho[n] * 1e-6);
    });
    return z;
}

PropertyMaps classify(const Volume& values, const TransferFunction& tf) {
    PropertyMaps maps;
    for (Volume& field : maps.fields) field = Volume(values.geometry());
    const std::size_t count = values.size();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 4096), [&](const auto& range) {
        for (std::size_t n = range.begin(); n != range.end(); ++n) {
            const AcousticProperties p = tf.evaluate(values.voxels()[n]);
            for (std::size_t f = 0; f < kPropertyCount; ++f)
                maps.fields[f].voxels()[n] = p.values[f];
        }
    });
    return maps;
}

Volume tissue_labels(const Volume& values, const TransferFunction& tf) {
    Volume labels(values.geometry());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, values.size(), 4096), [&](const auto& r) {
        for (std::size_t n = r.begin(); n != r.end(); ++n)
            labels.voxels()[n] = float(tf.tissue_label(values.voxels()[n]));
    });
    return labels;
}

}  // namespace sonotrace::tissue
