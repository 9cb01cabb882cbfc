#include "tissue/property_maps.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

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

void scale_by_label(PropertyMaps& maps, const Volume& labels, std::span<const LabelScale> scales) {
    if (scales.empty()) return;
    if (labels.size() != maps.fields[0].size())
        throw std::invalid_argument("scale_by_label: labels and maps on different grids");
    int top = 0;
    for (const LabelScale& s : scales) top = std::max(top, s.label);
    // factor[label][property], 1 where nothing is drawn.
    std::vector<std::array<float, kPropertyCount>> factor(std::size_t(top) + 1);
    for (auto& f : factor) f.fill(1.0f);
    for (const LabelScale& s : scales)
        factor[std::size_t(s.label)][std::size_t(s.property)] *= float(s.factor);
    const std::size_t count = labels.size();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 4096), [&](const auto& range) {
        for (std::size_t n = range.begin(); n != range.end(); ++n) {
            const float l = labels.voxels()[n];
            if (!(l >= 1.0f && l <= float(top))) continue;
            const auto& f = factor[std::size_t(l)];
            for (std::size_t p = 0; p < kPropertyCount; ++p) {
                if (f[p] == 1.0f) continue;
                float& v = maps.fields[p].voxels()[n];
                v = std::clamp(v * f[p], float(kPropertyInfo[p].min), float(kPropertyInfo[p].max));
            }
        }
    });
}

}  // namespace sonotrace::tissue
