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

// The same bands, the inside's mean display level against the outside's (`level_db(s)`: a
// sample's grey level in dB, as the display's TGC and log compression give it): the
// difference of mean grey levels the eye compares on the picture. Between two regions of
// developed speckle it equals band_contrast_db (the mean of 10 log10 of an exponential
// intensity lies 2.51 dB below 10 log10 of its mean on both sides), but a few samples far
// above the rest cannot dominate it.
template <typename Level>
double band_level_difference_db(const ClearSamples& samples, Level&& level_db,
                                double band_mm = 2.0);

// ---- implementation ----

namespace detail {

// Per band of `band_mm` (true depth), the sums of value(s) and the counts of the inside's
// and the outside's samples; bands with fewer than 20 of either are emptied.
struct DepthBands {
    std::vector<double> in, out;
    std::vector<int> n_in, n_out;
};

template <typename Value>
DepthBands depth_bands(const ClearSamples& samples, Value&& value, double band_mm) {
    std::size_t bands = 0;
    for (const auto* list : {&samples.inside, &samples.outside})
        for (const TruthSample& s : *list)
            bands = std::max(bands, std::size_t(s.depth_mm / band_mm) + 1);
    DepthBands b{std::vector<double>(bands), std::vector<double>(bands), std::vector<int>(bands),
                 std::vector<int>(bands)};
    for (const TruthSample& s : samples.inside) {
        const std::size_t k = std::size_t(s.depth_mm / band_mm);
        b.in[k] += value(s), ++b.n_in[k];
    }
    for (const TruthSample& s : samples.outside) {
        const std::size_t k = std::size_t(s.depth_mm / band_mm);
        b.out[k] += value(s), ++b.n_out[k];
    }
    for (std::size_t k = 0; k < bands; ++k)
        if (b.n_in[k] < 20 || b.n_out[k] < 20) b.in[k] = b.out[k] = 0.0, b.n_in[k] = b.n_out[k] = 0;
    return b;
}

}  // namespace detail

template <typename Intensity>
double band_contrast_db(const ClearSamples& samples, Intensity&& intensity, double band_mm) {
    const detail::DepthBands b = detail::depth_bands(samples, intensity, band_mm);
    double inside = 0.0, expected = 0.0;
    for (std::size_t k = 0; k < b.in.size(); ++k)
        if (b.n_in[k] > 0) inside += b.in[k], expected += b.n_in[k] * b.out[k] / b.n_out[k];
    return 10.0 * std::log10(inside / expected + 1e-30);
}

template <typename Level>
double band_level_difference_db(const ClearSamples& samples, Level&& level_db, double band_mm) {
    const detail::DepthBands b = detail::depth_bands(samples, level_db, band_mm);
    double difference = 0.0;
    int counted = 0;
    for (std::size_t k = 0; k < b.in.size(); ++k)
        if (b.n_in[k] > 0)
            difference += b.in[k] - b.n_in[k] * b.out[k] / b.n_out[k], counted += b.n_in[k];
    return counted > 0 ? difference / counted : std::nan("");
}

}  // namespace sonotrace::imaging
