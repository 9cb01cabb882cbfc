#pragma once
// Pictures of a trace: particle paths drawn over the medium, coloured by energy (blue =
// full, red = weak, as in Reis & Bertram's figure 6b), and line plots of profiles.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "simulator/records.h"
#include "tissue/volume.h"

namespace sonotrace::imaging {

struct PathStyle {
    int scale = 2;               // output pixels per texel
    float reference_energy = 1;  // energy drawn full blue
    int thickness = 1;
};

// The medium (k = 0 plane, grey, min..max) with the paths on top. Paths are in mm in the
// map frame (texel (i, j) at (i*h, j*h)).
cv::Mat draw_paths(const tissue::Volume& medium, const std::vector<simulator::Path<2>>& paths,
                   const PathStyle& style);

// A line plot of y over x with axes, ticks and labels; `marker_x` draws dashed vertical
// lines (e.g. the expected specular angle).
cv::Mat plot_profile(const std::vector<double>& x, const std::vector<double>& y,
                     const std::string& title, const std::string& x_label,
                     const std::string& y_label, const std::vector<double>& marker_x = {});

}  // namespace sonotrace::imaging
