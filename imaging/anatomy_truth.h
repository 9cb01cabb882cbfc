#pragma once
// Where a frame's envelope samples lie in the anatomy, for contrast measured on the
// envelope (the default head's ventricles against its parenchyma, issue 29): each sample
// placed along its scan line by walking the map's speed of sound (echo time = 2/c0 x the
// integral of n = c0/c), since brain at 1560 m/s shows the ventricles 0.8 mm shallower
// than they are at 60 mm; and classified by the tissue labels around it.
#include <algorithm>
#include <cmath>
#include <functional>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "imaging/bmode.h"
#include "probe/transducer.h"
#include "tissue/acoustic_map.h"
#include "tissue/volume.h"

namespace sonotrace::imaging {

struct TruthSample {
    int line = 0, sample = 0;
    double depth_mm = 0.0;  // true depth along the line
    glm::dvec2 map{0.0};    // its point in the map frame, mm
};

struct ClearSamples {
    std::vector<TruthSample> inside,
        outside;  // labels within clear_mm all `inside` / all `outside`
};

// How far from other labels a sample must lie (mm): a constant, or a function of the
// sample's true depth, for a clearance that follows the beam's width.
struct Clearance {
    Clearance(double mm) : at_depth([mm](double) { return mm; }) {}
    explicit Clearance(std::function<double(double depth_mm)> f) : at_depth(std::move(f)) {}
    std::function<double(double depth_mm)> at_depth;
};

// How a line's samples are placed in the map.
enum class TruthWalk {
    nominal,    // at c0 t / 2 along the straight line
    straight,   // along the straight line, timed through the map's speed of sound
    refracted,  // along the line's ray bent by the map's refractive index (the ray
                // equation d(n dr/ds)/ds = grad n, with the index the tracer refracts in:
                // the soft tissue smoothed over the Fresnel zone), timed through it
};

// The samples of `envelope` deeper than `from_mm` and shallower than `to_mm` (true depth,
// the path length along the walk) whose labels within `clear_mm` are all `inside_label`,
// or all `outside_label`. `to_map` takes the scan geometry's frame to the map's
// (PlaneGrid::to_map).
ClearSamples clear_samples(const LineData& envelope, const probe::ScanGeometry& geometry,
                           const glm::dvec2& to_map, const tissue::AcousticMap<2>& map,
                           const tissue::Volume& labels, int inside_label, int outside_label,
                           const Clearance& clear_mm, double from_mm, double to_mm,
                           TruthWalk walk = TruthWalk::straight);

// The inside's mean intensity (envelope squared) against the outside's at the same depths
// (bands of `band_mm`; a band counts with at least 20 samples of each, weighted by its
// inside samples), in dB. `intensity(s)` gives a sample's intensity.
template <typename Intensity>
double band_contrast_db(const ClearSamples& samples, Intensity&& intensity, double band_mm = 2.0);

// ---- implementation ----

template <typename Intensity>
double band_contrast_db(const ClearSamples& samples, Intensity&& intensity, double band_mm) {
    std::size_t bands = 0;
    for (const auto* list : {&samples.inside, &samples.outside})
        for (const TruthSample& s : *list)
            bands = std::max(bands, std::size_t(s.depth_mm / band_mm) + 1);
    std::vector<double> in(bands), out(bands);
    std::vector<int> n_in(bands), n_out(bands);
    for (const TruthSample& s : samples.inside) {
        const std::size_t b = std::size_t(s.depth_mm / band_mm);
        in[b] += intensity(s), ++n_in[b];
    }
    for (const TruthSample& s : samples.outside) {
        const std::size_t b = std::size_t(s.depth_mm / band_mm);
        out[b] += intensity(s), ++n_out[b];
    }
    double inside = 0.0, expected = 0.0;
    for (std::size_t b = 0; b < bands; ++b) {
        if (n_in[b] < 20 || n_out[b] < 20) continue;
        inside += in[b], expected += n_in[b] * out[b] / n_out[b];
    }
    return 10.0 * std::log10(inside / expected + 1e-30);
}

}  // namespace sonotrace::imaging
