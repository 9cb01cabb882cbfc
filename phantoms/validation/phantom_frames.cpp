// The imaging cases' shared frames and measurements (phantoms/validation/phantom_frames.h).
#include "phantoms/validation/phantom_frames.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "phantoms/scene/scene.h"
#include "probe/array_geometry.h"
#include "tissue/base/half_maximum.h"

namespace sonotrace::validation {

PhantomFrame image_phantom(phantoms::Phantom phantom, const FrameOptions& o, uint64_t seed,
                           const std::string& transmit) {
    PhantomFrame out;
    const auto scene = scene::phantom_scene(std::move(phantom));
    const phantoms::Phantom& ph = *scene->phantom;
    out.transducer = probe::find_transducer(scene->probe_preset, ph.source);
    if (o.depth_mm > 0.0) out.transducer.depth_mm = o.depth_mm;
    if (o.lines > 0) out.transducer.lines = o.lines;
    if (o.focus_mm > 0.0) out.transducer.focus_mm = o.focus_mm;
    imaging::SimulationSettings s;
    s.transducer = out.transducer;
    s.quality = o.quality;
    s.seed = seed;
    s.imaging.speckle = o.speckle;
    // Display only (measurements use the envelope): TGC for the background's two-way
    // attenuation, and the gain that puts liver-like speckle at mid-grey at 7.6 MHz.
    const double alpha = ph.background[tissue::Property::attenuation];
    const double depth = out.transducer.depth_mm;
    s.imaging.tgc = {{0.0, 0.0},
                     {depth, 2.0 * alpha * out.transducer.frequency_mhz * depth / 10.0}};
    s.imaging.gain_db = 56.0;
    scene->apply_to(s);
    if (!transmit.empty()) s.transmit = probe::parse_transmit_scheme(transmit, ph.source, "");
    s.validate(ph.source);
    out.frame = imaging::simulate_plane(scene->mapper, scene->start, s, false).frame;
    out.phantom = ph;
    return out;
}

phantoms::Phantom catalogue(const CaseContext& ctx, const std::string& name) {
    return phantoms::load_phantom(ctx.phantom_dir + "/" + name + ".json");
}

const phantoms::Shape& shape(const phantoms::Phantom& p, phantoms::ShapeType type, int nth) {
    for (const auto& s : p.shapes)
        if (s.type == type && nth-- == 0) return s;
    throw std::runtime_error(p.source + ": the validation case needs another shape");
}

double property(const tissue::AcousticProperties& p, tissue::Property f) {
    return p[f];
}

double first_echo_depth(const imaging::LineData& env, int line, double from_mm, double to_mm) {
    float strongest = 0.0f;
    for (int i = 1; i + 1 < env.samples; ++i)
        if (env.depth_mm(i) >= from_mm && env.depth_mm(i) <= to_mm)
            strongest = std::max(strongest, env.at(line, i));
    if (!(strongest > 0.0f)) return std::nan("");
    int best = -1;
    for (int i = 1; i + 1 < env.samples && best < 0; ++i) {
        if (env.depth_mm(i) < from_mm || env.depth_mm(i) > to_mm) continue;
        const float v = env.at(line, i);
        if (v >= 0.5f * strongest && v >= env.at(line, i - 1) && v >= env.at(line, i + 1)) best = i;
    }
    const double a = env.at(line, best - 1), b = env.at(line, best), c = env.at(line, best + 1);
    const double shift = (a - 2 * b + c) != 0.0 ? 0.5 * (a - c) / (a - 2 * b + c) : 0.0;
    return env.depth_mm(best) + shift * (env.depth_mm(1) - env.depth_mm(0));
}

float line_peak(const imaging::LineData& env, int line, double from_mm, double to_mm) {
    float best = 0.0f;
    for (int i = 0; i < env.samples; ++i)
        if (env.depth_mm(i) >= from_mm && env.depth_mm(i) <= to_mm)
            best = std::max(best, env.at(line, i));
    return best;
}

LateralProfile lateral_profile(const PhantomFrame& f, double from_mm, double to_mm, double x_from,
                               double x_to) {
    const probe::ScanGeometry g(f.transducer);
    std::vector<double> x, peak;
    for (int l = 0; l < f.transducer.lines; ++l) {
        const double xl = g.point(l, 0.5 * (from_mm + to_mm)).x;
        if (xl < x_from || xl > x_to) continue;
        x.push_back(xl);
        peak.push_back(line_peak(f.frame.envelope, l, from_mm, to_mm));
    }
    return analyse_lateral(x, peak);
}

LateralProfile analyse_lateral(const std::vector<double>& x, const std::vector<double>& peak) {
    LateralProfile out;
    out.x = x, out.peak = peak;
    if (peak.size() < 3) return out;
    const auto top = std::size_t(std::max_element(peak.begin(), peak.end()) - peak.begin());
    const double half = 0.5 * peak[top];
    out.fwhm = base::half_maximum_at(
                   int(peak.size()), int(top), [&](int i) { return peak[std::size_t(i)]; },
                   [&](int i) { return x[std::size_t(i)]; })
                   .width();
    // Centre: the centroid of the lines at half the maximum or more (a 3-point parabola
    // at the top follows the Monte Carlo noise of the few particles that hit a target).
    double w = 0.0, m = 0.0;
    for (std::size_t i = 0; i < peak.size(); ++i) {
        if (peak[i] < half) continue;
        w += peak[i], m += peak[i] * x[i];
    }
    out.centre = m / w;
    return out;
}

double wire_echo_depth(const PhantomFrame& f, const glm::dvec2& at, double from_mm, double to_mm) {
    const probe::ScanGeometry g(f.transducer);
    const imaging::LineData& env = f.frame.envelope;
    imaging::LineData summed = env;
    summed.lines = 1;
    summed.values.assign(std::size_t(env.samples), 0.0f);
    for (int l = 0; l < env.lines; ++l) {
        if (std::abs(g.point(l, at.y).x - at.x) > 0.5) continue;
        for (int i = 0; i < env.samples; ++i) summed.at(0, i) += env.at(l, i) * env.at(l, i);
    }
    return first_echo_depth(summed, 0, from_mm, to_mm);
}

double mean(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? std::nan("") : s / double(v.size());
}
double mean_square(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x * x;
    return v.empty() ? std::nan("") : s / double(v.size());
}
double stddev(const std::vector<double>& v) {
    const double m = mean(v);
    return std::sqrt(std::max(0.0, mean_square(v) - m * m));
}

Figure frame_figure(const PhantomFrame& f, const std::string& caption,
                    const std::vector<glm::dvec2>& expected,
                    const std::vector<glm::dvec2>& measured) {
    const imaging::ScanConverted& sc = f.frame.image;
    cv::Mat grey;
    sc.image.convertTo(grey, CV_8U, 255.0);
    // Twice the frame's pixels (0.1 mm at the default 0.2), so the targets are visible.
    constexpr int kScale = 2;
    cv::Mat bgr;
    cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
    cv::resize(bgr, bgr, {}, kScale, kScale, cv::INTER_NEAREST);
    auto pixel = [&](const glm::dvec2& p) {
        const glm::dvec2 q = ((p - sc.origin) / sc.pixel_mm + 0.5) * double(kScale) - 0.5;
        return cv::Point(int(std::lround(q.x)), int(std::lround(q.y)));
    };
    for (const auto& p : expected)
        cv::circle(bgr, pixel(p), 14, cv::Scalar(0, 200, 0), 1, cv::LINE_AA);
    for (const auto& p : measured)
        cv::circle(bgr, pixel(p), 8, cv::Scalar(0, 0, 230), 1, cv::LINE_AA);
    return {caption, bgr};
}

}  // namespace sonotrace::validation
