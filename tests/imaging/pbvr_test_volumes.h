#pragma once
// Volumes and transfer functions the PBVR tests render (test_pbvr*.cpp).
#include <algorithm>
#include <functional>
#include <vector>

#include <glm/glm.hpp>

#include "imaging/pbvr/colour_tf.h"
#include "imaging/pbvr/pbvr.h"
#include "tissue/volume.h"

namespace sonotrace::imaging::pbvr {

inline tissue::Volume make_volume(glm::ivec3 dims, double spacing,
                                  const std::function<float(int, int, int)>& value) {
    tissue::VolumeGeometry g;
    g.dims = dims;
    g.spacing = glm::dvec3(spacing);
    tissue::Volume v(g);
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) v.at(i, j, k) = value(i, j, k);
    return v;
}

// Opacity per mm rising linearly over 0..1 up to `top`; colour from dark to white.
inline ColourTransferFunction ramp(double top) {
    return ColourTransferFunction(
        "ramp", "test", {{0.0, glm::vec3(0.1f), 0.0}, {1.0, glm::vec3(1.0f), top}}, 1.0, 0.0, 1.0);
}

// Images of independent short runs, pixel by pixel and channel by channel, for tests that
// their mean is an unbiased estimate of a reference: sum over samples of
// (mean - reference)^2 / error^2, error^2 = variance x (1 / runs + extra), one degree of
// freedom per sample whose variance exceeds `floor` (constant samples say nothing).
class ImageEnsemble {
  public:
    void add(const RgbImage& image) {
        if (sum_.empty()) sum_.assign(3 * image.pixels.size(), 0.0), squares_ = sum_;
        for (std::size_t i = 0; i < sum_.size(); ++i) {
            const double v = image.pixels[i / 3][int(i % 3)];
            sum_[i] += v, squares_[i] += v * v;
        }
        ++runs_;
    }
    struct ChiSquare {
        double per_sample;
        int degrees;
    };
    ChiSquare against(const RgbImage& reference, double lift, double extra, double floor) const {
        double chi2 = 0.0;
        int degrees = 0;
        for (std::size_t i = 0; i < sum_.size(); ++i) {
            const double mean = sum_[i] / runs_;
            const double variance = (squares_[i] - runs_ * mean * mean) / (runs_ - 1);
            if (!(variance > floor)) continue;
            const double d = mean - (reference.pixels[i / 3][int(i % 3)] + lift);
            chi2 += d * d / (variance * (1.0 / runs_ + extra));
            ++degrees;
        }
        return {chi2 / std::max(degrees, 1), degrees};
    }

  private:
    std::vector<double> sum_, squares_;
    int runs_ = 0;
};

}  // namespace sonotrace::imaging::pbvr
