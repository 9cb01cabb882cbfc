#include "imaging/trace_pictures.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

namespace sonotrace::imaging {

cv::Mat draw_paths(const tissue::Volume& medium, const std::vector<simulator::Path<2>>& paths,
                   const PathStyle& style) {
    const int w = medium.dims().x, h = medium.dims().y, s = std::max(1, style.scale);
    cv::Mat values(h, w, CV_32F, const_cast<float*>(medium.voxels().data()));
    double lo, hi;
    cv::minMaxLoc(values, &lo, &hi);
    if (!(hi > lo)) hi = lo + 1.0;
    cv::Mat gray, bgr;
    // Dimmed so the paths stand out.
    values.convertTo(gray, CV_8U, 150.0 / (hi - lo), -150.0 * lo / (hi - lo) + 40.0);
    cv::resize(gray, gray, cv::Size(w * s, h * s), 0, 0, cv::INTER_NEAREST);
    cv::cvtColor(gray, bgr, cv::COLOR_GRAY2BGR);
    // Colour by energy on the jet map reversed: blue = reference energy, red = weak.
    cv::Mat ramp(1, 256, CV_8U), ramp_bgr;
    for (int i = 0; i < 256; ++i) ramp.at<uint8_t>(i) = uint8_t(i);
    cv::applyColorMap(ramp, ramp_bgr, cv::COLORMAP_JET);
    const double mm_to_px = s / medium.geometry().spacing.x;
    for (const auto& path : paths) {
        for (std::size_t v = 1; v < path.vertices.size(); ++v) {
            const auto& a = path.vertices[v - 1];
            const auto& b = path.vertices[v];
            const double e = std::clamp(double(b.energy) / style.reference_energy, 0.0, 1.0);
            // log scale over 3 decades so attenuated paths stay distinguishable
            const double t = std::clamp(1.0 + std::log10(std::max(e, 1e-3)) / 3.0, 0.0, 1.0);
            const cv::Vec3b c = ramp_bgr.at<cv::Vec3b>(0, int(255 * (1.0 - t)));
            cv::line(
                bgr,
                cv::Point2d(a.position.x * mm_to_px + 0.5 * s, a.position.y * mm_to_px + 0.5 * s),
                cv::Point2d(b.position.x * mm_to_px + 0.5 * s, b.position.y * mm_to_px + 0.5 * s),
                cv::Scalar(c[0], c[1], c[2]), style.thickness, cv::LINE_AA);
        }
    }
    return bgr;
}

cv::Mat plot_profile(const std::vector<double>& x, const std::vector<double>& y,
                     const std::string& title, const std::string& x_label,
                     const std::string& y_label, const std::vector<double>& marker_x) {
    const int W = 720, H = 420, left = 80, right = 20, top = 40, bottom = 60;
    cv::Mat canvas(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
    if (x.empty() || x.size() != y.size()) return canvas;
    const double x0 = *std::min_element(x.begin(), x.end()),
                 x1 = *std::max_element(x.begin(), x.end());
    double y1 = *std::max_element(y.begin(), y.end());
    if (!(y1 > 0)) y1 = 1.0;
    auto px = [&](double v) {
        return left + (v - x0) / std::max(x1 - x0, 1e-12) * (W - left - right);
    };
    auto py = [&](double v) { return H - bottom - v / y1 * (H - top - bottom); };
    const cv::Scalar ink(40, 40, 40), grid(225, 225, 225);
    const int font = cv::FONT_HERSHEY_SIMPLEX;
    for (int t = 0; t <= 4; ++t) {
        const double gx = x0 + (x1 - x0) * t / 4.0, gy = y1 * t / 4.0;
        cv::line(canvas, {int(px(gx)), top}, {int(px(gx)), H - bottom}, grid);
        cv::line(canvas, {left, int(py(gy))}, {W - right, int(py(gy))}, grid);
        char buffer[32];
        std::snprintf(buffer, sizeof buffer, "%.0f", gx);
        cv::putText(canvas, buffer, {int(px(gx)) - 10, H - bottom + 20}, font, 0.45, ink, 1,
                    cv::LINE_AA);
        std::snprintf(buffer, sizeof buffer, "%.2g", gy);
        cv::putText(canvas, buffer, {8, int(py(gy)) + 5}, font, 0.45, ink, 1, cv::LINE_AA);
    }
    for (double m : marker_x) {
        for (int yy = top; yy < H - bottom; yy += 8) {
            cv::line(canvas, {int(px(m)), yy}, {int(px(m)), yy + 4}, cv::Scalar(60, 60, 220), 1);
        }
    }
    for (std::size_t i = 1; i < x.size(); ++i) {
        cv::line(canvas, cv::Point2d(px(x[i - 1]), py(y[i - 1])), cv::Point2d(px(x[i]), py(y[i])),
                 cv::Scalar(180, 90, 20), 2, cv::LINE_AA);
    }
    cv::rectangle(canvas, {left, top}, {W - right, H - bottom}, ink);
    cv::putText(canvas, title, {left, 26}, font, 0.6, ink, 1, cv::LINE_AA);
    cv::putText(canvas, x_label, {W / 2 - 60, H - 18}, font, 0.5, ink, 1, cv::LINE_AA);
    cv::putText(canvas, y_label, {8, top - 12}, font, 0.45, ink, 1, cv::LINE_AA);
    return canvas;
}

}  // namespace sonotrace::imaging
