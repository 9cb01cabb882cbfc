#pragma once
// Pictures of scalar fields for people: colour-mapped, titled, with a labelled colour
// bar, written as PNG through OpenImageIO.
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "tissue/volume.h"

namespace sonotrace::imaging {

enum class Colormap { gray, viridis, inferno, magma, plasma, turbo, cividis, bone };

struct FieldStyle {
    std::string title;  // e.g. "speed of sound"
    std::string unit;   // e.g. "m/s"
    Colormap colormap = Colormap::viridis;
    std::optional<std::pair<double, double>> range;  // default: the field's min..max
    bool log_scale = false;                          // colour by log10(1 + v / (1e-3*max))
    double pixel_mm = 0.0;                           // > 0 draws a 10 mm scale bar
    int scale = 0;  // output pixels per texel; 0: maps under 320 rows are enlarged to it
};

// Renders the k = 0 plane of `field` (rows = j, columns = i) as an 8-bit BGR picture with
// title, colour bar and tick labels.
cv::Mat render_field(const tissue::Volume& field, const FieldStyle& style);

// Arranges pictures of possibly different sizes in a grid (black background).
cv::Mat montage(const std::vector<cv::Mat>& pictures, int columns);

// A frame's display (CV_32F, 0..1) as 8-bit grey levels: round(v x 255), clamped. What
// `simulate` writes as png8, the video's frames, the dataset's bmode and the module's.
cv::Mat grey_levels(const cv::Mat& display);

// Writes an 8-bit BGR or grey cv::Mat as PNG (RGB order on disk) to `path` exactly (no
// staging: callers stage through base::OutputTransaction).
void write_png(const cv::Mat& picture, const std::string& path);

}  // namespace sonotrace::imaging
