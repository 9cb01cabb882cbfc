#include "imaging/picture.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "tissue/base/error.h"
#include "tissue/image_io.h"

namespace sonotrace::imaging {

namespace {

int opencv_colormap(Colormap c) {
    switch (c) {
        case Colormap::viridis:
            return cv::COLORMAP_VIRIDIS;
        case Colormap::inferno:
            return cv::COLORMAP_INFERNO;
        case Colormap::magma:
            return cv::COLORMAP_MAGMA;
        case Colormap::plasma:
            return cv::COLORMAP_PLASMA;
        case Colormap::turbo:
            return cv::COLORMAP_TURBO;
        case Colormap::cividis:
            return cv::COLORMAP_CIVIDIS;
        case Colormap::bone:
            return cv::COLORMAP_BONE;
        case Colormap::gray:
            break;
    }
    return -1;
}

// Maps an 8-bit grey image through the colormap (grey stays grey, as BGR).
cv::Mat colorize(const cv::Mat& gray8, Colormap c) {
    cv::Mat bgr;
    const int cmap = opencv_colormap(c);
    if (cmap < 0)
        cv::cvtColor(gray8, bgr, cv::COLOR_GRAY2BGR);
    else
        cv::applyColorMap(gray8, bgr, cmap);
    return bgr;
}

std::string label(double v) {
    char buffer[32];
    const double a = std::abs(v);
    if (a != 0.0 && (a < 0.01 || a >= 1e5))
        std::snprintf(buffer, sizeof buffer, "%.2e", v);
    else if (a < 10.0)
        std::snprintf(buffer, sizeof buffer, "%.3g", v);
    else
        std::snprintf(buffer, sizeof buffer, "%.0f", v);
    return buffer;
}

}  // namespace

cv::Mat render_field(const tissue::Volume& field, const FieldStyle& style) {
    const int w = field.dims().x, h = field.dims().y;
    cv::Mat values(h, w, CV_32F, const_cast<float*>(field.voxels().data()));
    double lo = 0.0, hi = 0.0;
    if (style.range) {
        std::tie(lo, hi) = *style.range;
    } else {
        cv::minMaxLoc(values, &lo, &hi);
    }
    if (!(hi > lo)) hi = lo + (lo == 0.0 ? 1.0 : std::abs(lo) * 1e-3);

    // Normalise to 0..255, linearly or on a log scale that keeps small gradients visible.
    cv::Mat unit;
    const double floor = 1e-3 * std::max(std::abs(hi), 1e-30);
    if (style.log_scale) {
        cv::Mat shifted;
        values.convertTo(shifted, CV_32F, 1.0 / floor, -lo / floor);
        cv::max(shifted, 0.0, shifted);
        cv::log(shifted + 1.0, unit);
        unit /= std::log(1.0 + (hi - lo) / floor);
    } else {
        values.convertTo(unit, CV_32F, 1.0 / (hi - lo), -lo / (hi - lo));
    }
    cv::Mat gray8;
    unit.convertTo(gray8, CV_8U, 255.0);
    const cv::Mat image = colorize(gray8, style.colormap);

    // Canvas: title above, colour bar and labels to the right.
    const int title_h = 28, bar_w = 18, label_w = 90, margin = 8;
    const int scale = style.scale > 0 ? style.scale : std::max(1, 320 / std::max(h, 1));
    cv::Mat shown;
    cv::resize(image, shown, cv::Size(w * scale, h * scale), 0, 0, cv::INTER_NEAREST);
    const int H = shown.rows + title_h + margin, W = shown.cols + margin * 3 + bar_w + label_w;
    cv::Mat canvas(H, W, CV_8UC3, cv::Scalar(24, 24, 24));
    shown.copyTo(canvas(cv::Rect(margin, title_h, shown.cols, shown.rows)));
    const cv::Scalar text(235, 235, 235);
    const int font = cv::FONT_HERSHEY_SIMPLEX;
    std::string title = style.title + (style.unit.empty() ? "" : " [" + style.unit + "]") +
                        (style.log_scale ? " (log)" : "");
    cv::putText(canvas, title, {margin, 19}, font, 0.55, text, 1, cv::LINE_AA);

    // Colour bar: top = hi.
    const int bar_x = margin * 2 + shown.cols, bar_h = shown.rows;
    cv::Mat ramp(bar_h, 1, CV_8U);
    for (int r = 0; r < bar_h; ++r)
        ramp.at<uint8_t>(r) = uint8_t(255 - 255 * r / std::max(bar_h - 1, 1));
    cv::Mat ramp_bgr;
    cv::resize(colorize(ramp, style.colormap), ramp_bgr, cv::Size(bar_w, bar_h), 0, 0,
               cv::INTER_NEAREST);
    ramp_bgr.copyTo(canvas(cv::Rect(bar_x, title_h, bar_w, bar_h)));
    for (int tick = 0; tick <= 4; ++tick) {
        const double t = tick / 4.0;  // fraction of the bar from the bottom
        double v = lo + t * (hi - lo);
        if (style.log_scale)
            v = lo + floor * (std::exp(t * std::log(1.0 + (hi - lo) / floor)) - 1.0);
        const int y = title_h + int((1.0 - t) * (bar_h - 1));
        cv::line(canvas, {bar_x + bar_w, y}, {bar_x + bar_w + 4, y}, text);
        cv::putText(canvas, label(v), {bar_x + bar_w + 7, y + 5}, font, 0.45, text, 1, cv::LINE_AA);
    }
    // Scale bar of 10 mm along the bottom-left of the map.
    if (style.pixel_mm > 0.0) {
        const int len = int(std::lround(10.0 / style.pixel_mm * scale));
        if (len > 4 && len < shown.cols) {
            const int y = title_h + shown.rows - 10, x0 = margin + 8;
            cv::line(canvas, {x0, y}, {x0 + len, y}, cv::Scalar(255, 255, 255), 2);
            cv::putText(canvas, "10 mm", {x0, y - 6}, font, 0.45, cv::Scalar(255, 255, 255), 1,
                        cv::LINE_AA);
        }
    }
    return canvas;
}

cv::Mat montage(const std::vector<cv::Mat>& pictures, int columns) {
    if (pictures.empty()) return {};
    columns = std::max(1, std::min<int>(columns, int(pictures.size())));
    const int rows = (int(pictures.size()) + columns - 1) / columns;
    int cell_w = 0, cell_h = 0;
    for (const cv::Mat& p : pictures)
        cell_w = std::max(cell_w, p.cols), cell_h = std::max(cell_h, p.rows);
    cv::Mat sheet(rows * cell_h, columns * cell_w, CV_8UC3, cv::Scalar(24, 24, 24));
    for (std::size_t n = 0; n < pictures.size(); ++n) {
        const int r = int(n) / columns, c = int(n) % columns;
        pictures[n].copyTo(
            sheet(cv::Rect(c * cell_w, r * cell_h, pictures[n].cols, pictures[n].rows)));
    }
    return sheet;
}

cv::Mat grey_levels(const cv::Mat& display) {
    cv::Mat grey(display.size(), CV_8U);
    for (int y = 0; y < display.rows; ++y)
        for (int x = 0; x < display.cols; ++x)
            grey.at<uint8_t>(y, x) =
                uint8_t(std::clamp(std::round(display.at<float>(y, x) * 255.0f), 0.0f, 255.0f));
    return grey;
}

void write_png(const cv::Mat& picture, const std::string& path) {
    cv::Mat rgb;
    if (picture.channels() == 3)
        cv::cvtColor(picture, rgb, cv::COLOR_BGR2RGB);
    else
        rgb = picture.clone();
    const OIIO::ImageSpec spec(rgb.cols, rgb.rows, rgb.channels(), OIIO::TypeDesc::UINT8);
    tissue::write_image_file(path, spec, OIIO::TypeDesc::UINT8, rgb.data,
                             OIIO::stride_t(rgb.step[0]));
}

}  // namespace sonotrace::imaging
