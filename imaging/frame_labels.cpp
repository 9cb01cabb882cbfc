// The ground truth in a frame's pixels: tissue labels and shape instances where they lie,
// labels, true depth and echogenicity where the echoes show them, and the labels' colour
// pictures (declared in imaging/simulation.h).
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <vector>

#include "imaging/simulation.h"
#include "probe/transducer.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::imaging {

namespace {
// The texel (i, j) of the plane grid under a probe-plane point (centres at (i + 1/2) h in
// the map frame); false off the grid.
bool texel_under(const glm::dvec2& plane, const PlaneGrid& grid, int& i, int& j) {
    const glm::dvec3 spacing = grid.geometry.spacing;
    const glm::ivec3 dims = grid.geometry.dims;
    const glm::dvec2 map = plane + grid.to_map;
    i = int(std::floor(map.x / spacing.x + 0.5));
    j = int(std::floor(map.y / spacing.y + 0.5));
    return i >= 0 && j >= 0 && i < dims.x && j < dims.y;
}
}  // namespace

namespace {
// The texel under each pixel centre, nearest, as `type` (CV_8U or CV_16U), 0 outside.
template <typename T>
cv::Mat nearest_texels(const tissue::Volume& values, const PlaneGrid& grid,
                       const ScanConverted& frame, int type) {
    cv::Mat out(frame.image.rows, frame.image.cols, type, cv::Scalar(0));
    const float top = float(std::numeric_limits<T>::max());
    for (int r = 0; r < out.rows; ++r) {
        for (int c = 0; c < out.cols; ++c) {
            if (!frame.inside.at<uint8_t>(r, c)) continue;
            int i = 0, j = 0;
            if (!texel_under(frame.origin + glm::dvec2(c, r) * frame.pixel_mm, grid, i, j))
                continue;
            out.at<T>(r, c) = T(std::clamp(values.at(i, j, 0), 0.0f, top));
        }
    }
    return out;
}
}  // namespace

cv::Mat scan_convert_labels(const tissue::Volume& labels, const PlaneGrid& grid,
                            const ScanConverted& frame) {
    return nearest_texels<uint8_t>(labels, grid, frame, CV_8U);
}

cv::Mat scan_convert_instances(const tissue::Volume& instances, const PlaneGrid& grid,
                               const ScanConverted& frame) {
    return nearest_texels<uint16_t>(instances, grid, frame, CV_16U);
}

TruthAtEcho truth_at_echo(const tissue::Volume& labels, const tissue::PropertyMaps& maps,
                          const PlaneGrid& grid, const probe::Transducer& t,
                          const ScanConverted& frame) {
    const probe::ScanGeometry geometry(t);
    const glm::dvec3 spacing = grid.geometry.spacing;
    const tissue::Volume& speed = maps[tissue::Property::speed_of_sound];
    auto texel = [&](const glm::dvec2& plane, int& i, int& j) {
        return texel_under(plane, grid, i, j);
    };
    // Per line, the true depth at each displayed depth: the display puts an echo at
    // c0 t / 2, so true depth d shows at the integral of c0 / c over [0, d] along the line.
    // Walked at half a texel (c between texels taken as the nearest one's), tabled at
    // the same interval of displayed depth out to the frame's depth.
    const double step = 0.5 * std::min(spacing.x, spacing.y);
    const int shown_samples = int(std::ceil(geometry.depth_mm() / step)) + 2;
    std::vector<std::vector<float>> true_depth(std::size_t(geometry.lines()));
    tbb::parallel_for(0, geometry.lines(), [&](int l) {
        std::vector<float>& out = true_depth[std::size_t(l)];
        out.resize(std::size_t(shown_samples));
        double shown = 0.0, depth = 0.0;
        int n = 0;
        while (n < shown_samples) {
            // Every tabled displayed depth this step passes.
            int i = 0, j = 0;
            const double c = texel(geometry.point(l, depth + 0.5 * step), i, j)
                                 ? double(speed.at(i, j, 0))
                                 : tissue::kReferenceSpeed;
            const double next = shown + step * tissue::kReferenceSpeed / std::max(c, 1.0);
            while (n < shown_samples && n * step <= next) {
                out[std::size_t(n)] =
                    float(depth + step * (n * step - shown) / std::max(next - shown, 1e-12));
                ++n;
            }
            shown = next;
            depth += step;
        }
    });
    auto true_depth_at = [&](int l, double shown) {
        const std::vector<float>& d =
            true_depth[std::size_t(std::clamp(l, 0, geometry.lines() - 1))];
        const double x = std::clamp(shown / step, 0.0, double(shown_samples - 1));
        const int n = std::min(int(x), shown_samples - 2);
        return double(d[std::size_t(n)]) +
               (x - n) * double(d[std::size_t(n) + 1] - d[std::size_t(n)]);
    };
    const int rows = frame.image.rows, cols = frame.image.cols;
    TruthAtEcho out{cv::Mat(rows, cols, CV_8U, cv::Scalar(0)),
                    cv::Mat(rows, cols, CV_32F, cv::Scalar(0)),
                    cv::Mat(rows, cols, CV_32F, cv::Scalar(0))};
    const tissue::Volume& backscatter = maps[tissue::Property::backscatter];
    for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
            if (!frame.inside.at<uint8_t>(r, c)) continue;
            const glm::dvec2 plane = frame.origin + glm::dvec2(c, r) * frame.pixel_mm;
            const glm::dvec2 ld = geometry.line_and_depth(plane);
            const int l0 = int(std::floor(ld.x));
            const double f = ld.x - l0;
            const double depth =
                (1.0 - f) * true_depth_at(l0, ld.y) + f * true_depth_at(l0 + 1, ld.y);
            out.depth_mm.at<float>(r, c) = float(depth);
            int i = 0, j = 0;
            if (!texel(geometry.point(ld.x, depth), i, j)) continue;
            out.labels.at<uint8_t>(r, c) = uint8_t(std::clamp(labels.at(i, j, 0), 0.0f, 255.0f));
            out.echogenicity.at<float>(r, c) = backscatter.at(i, j, 0);
        }
    }
    return out;
}

cv::Mat scan_convert_labels_at_echo(const tissue::Volume& labels, const tissue::PropertyMaps& maps,
                                    const PlaneGrid& grid, const probe::Transducer& t,
                                    const ScanConverted& frame) {
    return truth_at_echo(labels, maps, grid, t, frame).labels;
}

cv::Vec3b label_colour(int label) {
    // BGR per tissue_table() entry (label - 1), chosen to read like an atlas.
    static const cv::Vec3b kColours[] = {
        {200, 120, 40},   // water: blue
        {40, 40, 200},    // blood: red
        {90, 220, 240},   // fat: yellow
        {80, 80, 170},    // muscle: brown-red
        {60, 100, 150},   // liver
        {120, 90, 200},   // kidney
        {200, 200, 200},  // brain: light grey
        {240, 160, 60},   // csf: light blue
        {255, 255, 255},  // cortical bone: white
        {0, 0, 0},        // air: black
        {150, 170, 190},  // soft tissue
        {80, 230, 250},   // dura (falx): pale yellow
        {220, 80, 220},   // choroid plexus: magenta
        {60, 140, 250},   // pia-arachnoid (sulci): orange
    };
    static_assert(std::size(kColours) == 14, "a colour per tissue_table() entry");
    return label >= 1 && label <= int(std::size(kColours)) ? kColours[label - 1]
                                                           : cv::Vec3b(0, 0, 0);
}

cv::Mat label_picture(const cv::Mat& labels) {
    cv::Mat out(labels.rows, labels.cols, CV_8UC3, cv::Scalar(0, 0, 0));
    for (int r = 0; r < labels.rows; ++r)
        for (int c = 0; c < labels.cols; ++c)
            out.at<cv::Vec3b>(r, c) = label_colour(labels.at<uint8_t>(r, c));
    return out;
}

}  // namespace sonotrace::imaging
