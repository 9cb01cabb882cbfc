#pragma once
// Scan conversion: line data onto a Cartesian grid of square pixels covering the scanned
// region, for every array type (probe::ScanGeometry says which line and depth each pixel
// centre lies on).
//
// Two forms. scan_convert interpolates any line quantity bilinearly between the two
// lines and the two samples around a pixel. The display (scan_convert_display) is made
// from the detected baseband lines instead: between lines it interpolates the complex
// signal, z = (1 - f) a + f b, and restores the power that partial coherence takes from
// it, z sqrt(P_lin / P_coh), where P_lin = (1 - f) <|a|^2> + f <|b|^2> is the lines'
// power interpolated and P_coh = <|(1 - f) a + f b|^2> = (1 - f)^2 <|a|^2> + f^2 <|b|^2> +
// 2 f (1 - f) Re <a b*> the interpolated signal's, both local means over
// kCoherenceSigmas axial resolutions either side. Speckle between lines then stays
// circular Gaussian of the interpolated power: its envelope Rayleigh (SNR 1.91), where
// interpolating the detected envelope or its log averaged two partly independent grains
// (SNR 2.02-2.09). An echo that both lines see in phase (P_coh = P_lin) is interpolated
// as it is; one whose phase turns between the lines (a tilted reflector) keeps its level
// rather than cancelling midway.
#include <memory>
#include <vector>

#include <glm/glm.hpp>
#include <opencv2/core.hpp>

#include "imaging/bmode.h"
#include "probe/transducer.h"

namespace sonotrace::imaging {

struct ScanConverted {
    cv::Mat image;      // CV_32F, rows = depth (y), cols = lateral (x)
    cv::Mat inside;     // CV_8U, 255 where the pixel lies in the scanned region
    glm::dvec2 origin;  // probe-plane position (mm) of pixel (0, 0)'s centre
    double pixel_mm = 0.0;
};

// Line data onto pixels of `pixel_mm`, bilinear between lines and samples. Pixels outside
// the region are `outside`.
ScanConverted scan_convert(const LineData& data, const probe::Transducer& t, double pixel_mm,
                           float outside = 0.0f);

// The local means' half-width, in axial resolutions (BasebandLines::sigma_samples): long
// enough to hold several independent speckle grains, short against the depth over which
// the lines' coherence changes.
inline constexpr double kCoherenceSigmas = 16.0;
// The largest power a pixel's interpolation restores (P_lin / P_coh): where the two lines
// cancel over the whole window there is nothing left to restore.
inline constexpr float kMostRestoredPower = 16.0f;

// The display: `lines` (envelope(..., &baseband)) interpolated coherently between lines
// and linearly between samples (see the header), then TGC and log compression
// (Compression) at the pixel's depth; 0 outside the region.
ScanConverted scan_convert_display(const BasebandLines& lines, const probe::Transducer& t,
                                   const ImagingSettings& settings);

}  // namespace sonotrace::imaging
