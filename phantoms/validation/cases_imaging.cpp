// Cases measured on simulated frames of catalogue phantoms (phantoms/*.json): wire depths,
// speed-of-sound displacement, refraction shift, mirror image, shadow, enhancement,
// resolution, speckle statistics and cyst contrast. Expectations are computed here from
// the phantom's parameters (shapes, tissue properties) and the transducer's.
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "imaging/scene/scene.h"
#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "phantoms/validation/broadband_reference.h"
#include "phantoms/validation/validation.h"
#include "probe/aperture.h"
#include "probe/pulse.h"
#include "tissue/base/half_maximum.h"
#include "tissue/tissue_table.h"

namespace sonotrace::validation {
namespace {

// A phantom imaged with its probe (depth and quality as the case needs).
struct PhantomFrame {
    phantoms::Phantom phantom;
    probe::Transducer transducer;
    imaging::Frame frame;
    // Probe-plane coordinates (x lateral from the face centre, y depth) of a phantom point.
    glm::dvec2 plane(const glm::dvec3& p) const {
        const glm::dvec3 d = p - phantom.pose.position;
        return {glm::dot(d, phantom.pose.lateral()), glm::dot(d, phantom.pose.axial())};
    }
    glm::dvec2 plane(const glm::dvec2& xy) const {
        return plane(glm::dvec3(xy, phantom.pose.position.z));
    }
};

struct FrameOptions {
    double depth_mm = 0.0;  // 0 = the preset's
    int lines = 0;
    imaging::Quality quality = imaging::Quality::high;
    bool speckle = true;
    double focus_mm = 0.0;  // 0 = the preset's
};

PhantomFrame image_phantom(phantoms::Phantom phantom, const FrameOptions& o, uint64_t seed) {
    PhantomFrame out;
    const auto scene = imaging::phantom_scene(std::move(phantom));
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
    s.validate(ph.source);
    out.frame = imaging::simulate_plane(scene->mapper, scene->start, s, false).frame;
    out.phantom = ph;
    return out;
}

phantoms::Phantom catalogue(const CaseContext& ctx, const std::string& name) {
    return phantoms::load_phantom(ctx.phantom_dir + "/" + name + ".json");
}

// The first shape of a type (the catalogue files are ours: a missing one is a bug).
const phantoms::Shape& shape(const phantoms::Phantom& p, phantoms::ShapeType type, int nth = 0) {
    for (const auto& s : p.shapes)
        if (s.type == type && nth-- == 0) return s;
    throw std::runtime_error(p.source + ": the validation case needs another shape");
}

double property(const tissue::AcousticProperties& p, tissue::Property f) {
    return p[f];
}
double impedance(const tissue::AcousticProperties& p) {
    return property(p, tissue::Property::speed_of_sound) * property(p, tissue::Property::density);
}
double intensity_reflection(double z1, double z2) {
    return std::pow((z2 - z1) / (z2 + z1), 2.0);
}

// ---- measurements on the envelope (lines x samples, before TGC and compression) ----

// Depth (mm, c0 t / 2) of the first echo of a line in [from, to]: the first local maximum
// at half the window's maximum or more (a wire's back wall can be the stronger echo),
// refined by a parabola through its neighbours.
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

// Largest envelope value of a line within [from, to] mm.
float line_peak(const imaging::LineData& env, int line, double from_mm, double to_mm) {
    float best = 0.0f;
    for (int i = 0; i < env.samples; ++i)
        if (env.depth_mm(i) >= from_mm && env.depth_mm(i) <= to_mm)
            best = std::max(best, env.at(line, i));
    return best;
}

// Lateral position (mm) and full width at half maximum of a target seen across the lines
// (the per-line peaks within a depth window), linear interpolation at the crossings.
struct LateralProfile {
    double centre = std::nan(""), fwhm = std::nan("");
    std::vector<double> x, peak;  // per line
};
LateralProfile analyse_lateral(const std::vector<double>& x, const std::vector<double>& peak);
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

// Envelope samples whose probe-plane position satisfies `inside`.
template <typename Inside>
std::vector<double> envelope_samples(const PhantomFrame& f, Inside inside) {
    const probe::ScanGeometry g(f.transducer);
    const imaging::LineData& env = f.frame.envelope;
    std::vector<double> out;
    for (int l = 0; l < env.lines; ++l)
        for (int i = 0; i < env.samples; ++i)
            if (inside(g.point(l, env.depth_mm(i)))) out.push_back(env.at(l, i));
    return out;
}

// Apparent depth of a wire's first echo: the intensity summed over the lines within
// 0.5 mm of it (the speckle averages, the wire's echo adds up), then the first local
// maximum at half the window's maximum or more.
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

// The frame as the user sees it, with circles: green = expected, red = measured.
Figure frame_figure(const PhantomFrame& f, const std::string& caption,
                    const std::vector<glm::dvec2>& expected = {},
                    const std::vector<glm::dvec2>& measured = {}) {
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

// The element sum of probe/aperture.h written out again for a linear array, over the
// pulse's whole spectrum, as the prediction the lateral resolution is held to
// (independent of the image pipeline, whose point targets go through probe::LineFields):
// the line at lateral position x_line (mm), the point (x, z); rectangular, Hann or Tukey
// weights across the clipped active span; elements of the preset's width (sinc
// directivity, cosine obliquity), 1/sqrt(r) cylindrical spreading, focusing delays to the
// transmit focus and to the point's depth, each field normalised to unit lateral power at
// its frequency; the echo's envelope peak over the pulse's spectrum (PulseSpectrum, f0 / 50
// apart), over +-6 periods.
struct ReferenceLinearArray {
    probe::Transducer t;
    PulseSpectrum spectrum;
    explicit ReferenceLinearArray(const probe::Transducer& transducer)
        : t(transducer), spectrum(transducer, 50.0, 6.0) {}
    static double weight(probe::Apodization a, double u) {
        if (u < 0.0 || u > 1.0) return 0.0;
        if (a == probe::Apodization::hann) return 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * u);
        if (a == probe::Apodization::tukey) {
            const double e = std::min(u, 1.0 - u);
            return e >= 0.25 ? 1.0 : 0.5 - 0.5 * std::cos(std::numbers::pi * e / 0.25);
        }
        return 1.0;
    }
    std::complex<double> field(double x_line, double width, probe::Apodization a, double focus,
                               double x, double z, double f) const {
        const double lambda = kC0 / f * 1e3, k = 2.0 * std::numbers::pi / lambda;
        const double half_array = 0.5 * t.elements * t.pitch_mm;
        width = std::max(width, 2.0 * t.pitch_mm);
        const double lo = std::max(x_line - 0.5 * width, -half_array),
                     hi = std::min(x_line + 0.5 * width, half_array);
        std::complex<double> sum = 0.0;
        double w2 = 0.0;
        for (int e = 0; e < t.elements; ++e) {
            const double xe = -half_array + (e + 0.5) * t.pitch_mm;
            if (xe < lo || xe > hi) continue;
            const double dx = x - xe, r = std::hypot(dx, z);
            const double s = std::numbers::pi * t.element_width_mm * (dx / r) / lambda;
            const double directivity = (s == 0.0 ? 1.0 : std::sin(s) / s) * (z / r);
            const double path = r - std::hypot(x_line - xe, focus) + focus - z;
            const double w = weight(a, (xe - lo) / (hi - lo));
            w2 += w * w;
            sum += w * directivity / std::sqrt(r) * std::polar(1.0, -k * path);
        }
        return sum / std::sqrt(lambda / t.pitch_mm * std::max(w2, 1e-30));
    }
    // The envelope peak of the echo on the line at x_line of a point at (x, z), the
    // receive focused at z, over the pulse's.
    double two_way(double x_line, double x, double z) const {
        const double tx = std::min(t.focus_mm / t.f_number, t.elements * t.pitch_mm);
        const double rx = std::min(z / t.rx_f_number, t.elements * t.pitch_mm);
        std::vector<std::complex<double>> h;
        for (double f : spectrum.frequency())
            h.push_back(field(x_line, tx, t.tx_apodization, t.focus_mm, x, z, f) *
                        field(x_line, rx, t.rx_apodization, z, x, z, f));
        return spectrum.peak(h);
    }
};

// A 0.1 mm wire target at (x, z) of the probe plane in water, imaged by `t` through the
// beams without being traced (speckle off).
PhantomFrame wire_in_water(const probe::Transducer& t, const tissue::AcousticProperties& water,
                           double x, double z, uint64_t seed) {
    PhantomFrame f;
    f.phantom.name = "lateral", f.phantom.source = "validation:resolution";
    f.phantom.size = {40.0, 40.0, 10.0};
    f.phantom.background = water;
    f.phantom.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
    f.transducer = t;
    imaging::SimulationSettings settings;
    settings.transducer = t;
    settings.quality = imaging::Quality::standard;
    settings.imaging.speckle = false;
    settings.seed = seed;
    tissue::PointTarget wire;
    wire.type = tissue::PointTarget::Type::wire;
    wire.at = {20.0 + x, z, 5.0};
    settings.targets = {wire};
    const imaging::PlaneGrid grid = imaging::plane_grid(t, f.phantom.pose, 0.25);
    const auto map = imaging::frame_map(phantoms::rasterise(f.phantom, grid.geometry), settings);
    f.frame = imaging::simulate_frame(map, grid, f.phantom.pose, settings);
    return f;
}

// ---- cases ----

CaseResult wire_depth(const CaseContext& ctx) {
    // The depth-calibration column of the QA phantom in a 1540 m/s background: each wire's
    // front face (centre minus radius) must appear within 0.5 mm of its depth (the issue's
    // bound; the echo is timed where the beam meets the wire's surface).
    // Transmit focus at 30 mm, mid-column, as a user sets it for a deep region of
    // interest: at 50 mm the beam is then ~5 mm wide instead of ~8.
    const PhantomFrame f = image_phantom(catalogue(ctx, "qa_multipurpose"),
                                         {60.0, 0, imaging::Quality::high, true, 30.0}, ctx.seed);
    CaseResult r;
    std::vector<glm::dvec2> expected, measured;
    for (const auto& s : f.phantom.shapes) {
        if (s.type != phantoms::ShapeType::wire || std::abs(s.a.x - 25.0) > 1e-6) continue;
        const glm::dvec2 at = f.plane(glm::dvec2(s.a));
        const double front = at.y - s.radius;
        // Search window +-1.5 mm, three times the tolerance: a wire outside it fails.
        const double seen = wire_echo_depth(f, at, front - 1.5, front + 1.5);
        r.measurements.push_back(
            {"apparent depth of the wire at " + std::to_string(int(at.y)) + " mm (front face)",
             seen, front, 0.5, "mm"});
        expected.push_back({at.x, front}), measured.push_back({at.x, seen});
    }
    if (ctx.pictures)
        r.figures.push_back(
            frame_figure(f,
                         "QA phantom (linear 7.6 MHz, high quality). Green: true wire "
                         "fronts of the calibration column; red: measured.",
                         expected, measured));
    return r;
}

CaseResult speed_displacement(const CaseContext& ctx) {
    // Wires under a slow fat layer of thickness L appear deeper than wires beside it by
    // L (c0/c_fat - c0/c_background): echo delays assume c0. Within 10 % (the issue).
    const PhantomFrame f = image_phantom(catalogue(ctx, "speed_layer"), {40.0, 0}, ctx.seed);
    const auto& layer = shape(f.phantom, phantoms::ShapeType::box);
    const double L = layer.b.y - layer.a.y;
    const double c_layer = property(layer.properties, tissue::Property::speed_of_sound);
    const double c_bg = property(f.phantom.background, tissue::Property::speed_of_sound);
    const double expected = L * (kC0 / c_layer - kC0 / c_bg);
    double under = 0.0, beside = 0.0;
    int n_under = 0, n_beside = 0;
    std::vector<glm::dvec2> measured;
    for (const auto& s : f.phantom.shapes) {
        if (s.type != phantoms::ShapeType::wire) continue;
        const glm::dvec2 at = f.plane(glm::dvec2(s.a));
        const double d = wire_echo_depth(f, at, at.y - s.radius - 3, at.y - s.radius + 3);
        measured.push_back({at.x, d});
        if (s.a.x > layer.a.x + 2 && s.a.x < layer.b.x - 2)
            under += d, ++n_under;
        else if (s.a.x > layer.b.x + 2 || s.a.x < layer.a.x - 2)
            beside += d, ++n_beside;
    }
    // The point targets (phantom "targets", imaged through the beam, not traced): their
    // echo delay is the straight path's travel time. Within 0.1 mm (issue 51).
    double targets_under = 0.0, targets_beside = 0.0;
    int n_targets_under = 0, n_targets_beside = 0;
    for (const auto& target : f.phantom.targets) {
        const glm::dvec2 at = f.plane(glm::dvec2(target.at));
        const double d = wire_echo_depth(f, at, at.y - 3.0, at.y + 3.0);
        measured.push_back({at.x, d});
        if (target.at.x > layer.a.x + 2 && target.at.x < layer.b.x - 2)
            targets_under += d, ++n_targets_under;
        else if (target.at.x > layer.b.x + 2 || target.at.x < layer.a.x - 2)
            targets_beside += d, ++n_targets_beside;
    }
    CaseResult r;
    r.measurements.push_back({"depth shift of the wires under the layer",
                              under / n_under - beside / n_beside, expected,
                              0.1 * std::abs(expected), "mm"});
    r.measurements.push_back({"depth shift of the point targets under the layer",
                              targets_under / n_targets_under - targets_beside / n_targets_beside,
                              expected, 0.1, "mm"});
    if (ctx.pictures)
        r.figures.push_back(frame_figure(f,
                                         "Wires at 30 mm and point targets at 36 mm; those on "
                                         "the left lie under 15 mm of fat (1450 m/s) and appear "
                                         "deeper. Red: measured.",
                                         {}, measured));
    return r;
}

CaseResult refraction_shift(const CaseContext& ctx) {
    // A slab of thickness T whose normal is tilted by i from the beam, speed c2 in c1:
    // inside, sin t = sin i c2 / c1; the beam leaves parallel, shifted sideways by
    // T sin(i - t) / cos t, so the line that reaches the wire starts that far to the
    // other side and the wire appears displaced by it. Its lateral position: the centroid
    // of the lines (256, 0.15 mm apart) whose echo reaches half the maximum. Tolerance
    // 0.15 mm: the wire is hit by few particles per line beyond the focus (Monte Carlo
    // noise of ~0.1 mm in the centroid between seeds), and the beam's rays shift by 0.6
    // to 1.9 mm across the aperture (incidences 26..54 degrees) around the axis's 1.03.
    const PhantomFrame f = image_phantom(catalogue(ctx, "refraction"), {45.0, 256}, ctx.seed);
    const auto& slab = shape(f.phantom, phantoms::ShapeType::layer);
    const auto& wire = shape(f.phantom, phantoms::ShapeType::wire);
    const glm::dvec2 normal = glm::normalize(glm::dvec2(slab.b));
    const double i = std::acos(std::abs(glm::dot(normal, glm::dvec2(f.phantom.pose.axial()))));
    const double c1 = property(f.phantom.background, tissue::Property::speed_of_sound);
    const double c2 = property(slab.properties, tissue::Property::speed_of_sound);
    const double t = std::asin(std::sin(i) * c2 / c1);
    const double T = slab.radius;
    const double shift = T * std::sin(i - t) / std::cos(t);
    // Sideways towards the normal's lateral component for c2 < c1: the wire appears on
    // the other side.
    const glm::dvec2 at = f.plane(glm::dvec2(wire.a));
    const double sign = glm::dot(normal, glm::dvec2(f.phantom.pose.lateral())) > 0 ? 1.0 : -1.0;
    const double expected_x = at.x - sign * shift;
    const double front = at.y - wire.radius;
    const LateralProfile p = lateral_profile(f, front - 3.0, front + 3.0, at.x - 5.0, at.x + 5.0);
    CaseResult r;
    r.measurements.push_back({"apparent lateral position of the wire (true " +
                                  std::to_string(at.x).substr(0, 4) + " mm)",
                              p.centre, expected_x, 0.15, "mm"});
    if (ctx.pictures)
        r.figures.push_back(frame_figure(
            f,
            "A wire under an oblique slow slab. Green: where Snell's law puts its image; red: "
            "measured; the true wire is 1 mm to the right.",
            {{expected_x, front}}, {{p.centre, front}}));
    return r;
}

CaseResult mirror_image(const CaseContext& ctx) {
    // A wire in front of an inclined air interface (total reflection): the beam reflected
    // at the interface reaches the wire, and the echo, timed along the line, is drawn at
    // the wire mirrored through the interface plane. Within 1 mm (the bound), in
    // the catalogue's liver and in the same phantom made scatter-free (the ghost must not
    // need speckle to carry its receive weight: by reciprocity it returns along the line).
    CaseResult r;
    for (const bool scattering : {true, false}) {
        phantoms::Phantom ph = catalogue(ctx, "mirror");
        if (!scattering) {
            ph.background[tissue::Property::backscatter] = 0.0f;
            ph.background[tissue::Property::scatterer_density] = 0.0f;
        }
        const PhantomFrame f = image_phantom(ph, {50.0, 0}, ctx.seed);
        const auto& mirror = shape(f.phantom, phantoms::ShapeType::half_space);
        const auto& wire = shape(f.phantom, phantoms::ShapeType::wire);
        const glm::dvec2 q = f.plane(glm::dvec2(mirror.a));
        glm::dvec2 n(glm::dot(glm::dvec3(mirror.b), f.phantom.pose.lateral()),
                     glm::dot(glm::dvec3(mirror.b), f.phantom.pose.axial()));
        n = glm::normalize(n);
        const glm::dvec2 w = f.plane(glm::dvec2(wire.a));
        // The echo comes from the wire's surface facing the reflected beam; mirrored, that
        // point lies one radius before the mirrored centre along the scan line (the
        // reflected ray's direction mirrors back to the beam's).
        const glm::dvec2 mirrored = w - 2.0 * glm::dot(w - q, n) * n;
        const glm::dvec2 image = mirrored - wire.radius * glm::dvec2(0.0, 1.0);
        // Beyond the interface (2 mm clear of it) the wire's image is the strongest echo
        // (the air is silent: no scatterers; the liver's mirror image is speckle). Its
        // position: the intensity centroid of the samples within 3 mm of the strongest one
        // at -10 dB or more. The ghost is the two-way beam of the mirrored path, spread
        // over several lines, and the few particles that take that path light it unevenly:
        // its strongest sample alone, or the top 3 dB within 1 mm, wander by 1-3 mm from
        // seed to seed (seeds 1-8), its -10 dB centroid by 0.2-1.0 mm.
        const probe::ScanGeometry g(f.transducer);
        const imaging::LineData& env = f.frame.envelope;
        double best = 0.0;
        glm::dvec2 strongest(std::nan(""));
        // Within 5 mm of where it should be (the point target's ghost lies elsewhere).
        constexpr double kSearchMm = 5.0;
        for (int l = 0; l < env.lines; ++l) {
            for (int i = 0; i < env.samples; ++i) {
                const glm::dvec2 p = g.point(l, env.depth_mm(i));
                if (glm::dot(p - q, n) < 2.0 || glm::length(p - image) > kSearchMm ||
                    env.at(l, i) <= best)
                    continue;
                best = env.at(l, i), strongest = p;
            }
        }
        constexpr double kBlobRadiusMm = 3.0, kBlobLevel = 0.1;
        double weight = 0.0;
        glm::dvec2 sum(0.0);
        for (int l = 0; l < env.lines; ++l) {
            for (int i = 0; i < env.samples; ++i) {
                const glm::dvec2 p = g.point(l, env.depth_mm(i));
                const double v = double(env.at(l, i)) * env.at(l, i);
                if (glm::length(p - strongest) > kBlobRadiusMm || v < kBlobLevel * best * best)
                    continue;
                weight += v, sum += v * p;
            }
        }
        const glm::dvec2 found = sum / weight;
        const std::string medium = scattering ? "liver" : "scatter-free liver";
        r.measurements.push_back(
            {"distance of the mirror image from the mirrored wire front (" + medium + ")",
             glm::length(found - image), 1.0, 0.0, "mm", Check::at_most});
        // The point target (phantom "targets": imaged through the beam, its ghost found by
        // rays from it, imaging/mirror_ghosts.h): the envelope's peak within 3 mm of it
        // mirrored, refined by parabolas across lines and along the line. Its path to the
        // mirrored point runs down the scan line in the background, so the echo time places
        // it at depth z c0 / c (liver is faster than c0: shallower).
        const glm::dvec2 target = f.plane(glm::dvec2(f.phantom.targets.at(0).at));
        const double c_bg = property(f.phantom.background, tissue::Property::speed_of_sound);
        glm::dvec2 target_image = target - 2.0 * glm::dot(target - q, n) * n;
        target_image.y *= kC0 / c_bg;
        int bl = -1, bi = -1;
        for (int l = 1; l + 1 < env.lines; ++l)
            for (int i = 1; i + 1 < env.samples; ++i)
                if (glm::length(g.point(l, env.depth_mm(i)) - target_image) <= 3.0 &&
                    (bl < 0 || env.at(l, i) > env.at(bl, bi)))
                    bl = l, bi = i;
        auto vertex = [](double a, double b, double c) {
            const double d = a - 2.0 * b + c;
            return d < 0.0 ? 0.5 * (a - c) / d : 0.0;
        };
        const glm::dvec2 target_found = g.point(
            bl + vertex(env.at(bl - 1, bi), env.at(bl, bi), env.at(bl + 1, bi)),
            env.depth_mm(bi) + vertex(env.at(bl, bi - 1), env.at(bl, bi), env.at(bl, bi + 1)) *
                                   (env.depth_mm(1) - env.depth_mm(0)));
        r.measurements.push_back(
            {"distance of the point target's ghost from the mirrored target (" + medium + ")",
             glm::length(target_found - target_image), 1.0, 0.0, "mm", Check::at_most});
        if (ctx.pictures)
            r.figures.push_back(frame_figure(
                f,
                (scattering ? "Liver" : "Scatter-free liver") +
                    std::string(" over an inclined air interface with a wire in front of it. "
                                "Green: the wire, the point target and both mirrored through the "
                                "interface; "
                                "red: the measured image."),
                {image, w, target_image, target}, {found, target_found}));
    }
    return r;
}

CaseResult shadow_and_enhancement(const CaseContext& ctx) {
    const PhantomFrame f = image_phantom(catalogue(ctx, "cyst_and_stone"), {50.0, 0}, ctx.seed);
    // The reference: the same phantom without its shapes (plain liver), same seed. The
    // scatterers are fixed in the tissue, so where the beams are alike the speckle is the
    // same and cancels from the ratio; and no reference column is half in a shadow.
    phantoms::Phantom plain_phantom = f.phantom;
    plain_phantom.shapes.clear();
    const PhantomFrame plain = image_phantom(plain_phantom, {50.0, 0}, ctx.seed);
    const auto& cyst = shape(f.phantom, phantoms::ShapeType::sphere);
    const auto& plaque = shape(f.phantom, phantoms::ShapeType::box);
    const tissue::AcousticProperties& liver = f.phantom.background;
    const double freq = f.transducer.frequency_mhz;
    const double a_liver = property(liver, tissue::Property::attenuation);  // dB/(cm MHz)
    // Mean intensity (envelope^2) in a 6 mm window below the object, +-1.5 mm about its
    // axis, with and without the objects.
    const glm::dvec2 cyst_c = f.plane(glm::dvec2(cyst.a)),
                     plaque_lo = f.plane(glm::dvec2(plaque.a)),
                     plaque_hi = f.plane(glm::dvec2(plaque.b));
    const double x_plaque = 0.5 * (plaque_lo.x + plaque_hi.x);
    auto ratio_db = [&](double x, double y0, double y1) {
        auto inside = [&](glm::dvec2 p) {
            return std::abs(p.x - x) <= 1.5 && p.y >= y0 && p.y <= y1;
        };
        return 10.0 * std::log10(mean_square(envelope_samples(f, inside)) /
                                 mean_square(envelope_samples(plain, inside)));
    };
    CaseResult r;
    // Shadow: two-way loss through the plaque (thickness d) instead of liver: the two
    // faces transmit (1 - R^2) each way, and the plaque attenuates a_p f d instead of the
    // liver's a_l f d. Tolerance 1.5 dB: ~150 independent speckle cells per window (the
    // shadowed speckle is not the reference's: the plaque reshapes the beams), a 4 sigma
    // error of a ratio of two means of ~1.4 dB.
    {
        const double d_cm = 0.1 * (plaque_hi.y - plaque_lo.y);
        const double R2 = intensity_reflection(impedance(liver), impedance(plaque.properties));
        const double a_p = property(plaque.properties, tissue::Property::attenuation);
        const double expected =
            2.0 * (2.0 * 10.0 * std::log10(1.0 - R2) - (a_p - a_liver) * freq * d_cm);
        // Below the mirror image of the liver above the plaque: the share R^2 the plaque's
        // top reflects meets the liver on its way back and returns through the same
        // reflection (R^4 = 0.04 of the liver, as bright as the shadow itself), drawn at
        // apparent depths down to twice the plaque's depth. The window starts 2 mm below.
        const double y0 = 2.0 * plaque_lo.y + 2.0, y1 = y0 + 6.0;
        const double measured = ratio_db(x_plaque, y0, y1);
        r.measurements.push_back(
            {"shadow contrast behind the plaque", measured, expected, 1.5, "dB"});
    }
    // Enhancement: the cyst (water) attenuates a_w instead of a_l over its chord; the mean
    // two-way gain over the window's chords, less the cyst walls' transmission. Within
    // 20 % (the issue).
    {
        const double a_w = property(cyst.properties, tissue::Property::attenuation);
        const double R2 = intensity_reflection(impedance(liver), impedance(cyst.properties));
        double chord = 0.0;
        for (int k = -15; k <= 15; ++k) {
            const double x = 0.1 * k;  // window +-1.5 mm
            chord += 2.0 * std::sqrt(std::max(0.0, cyst.radius * cyst.radius - x * x)) / 31.0;
        }
        const double expected =
            2.0 * ((a_liver - a_w) * freq * 0.1 * chord + 2.0 * 10.0 * std::log10(1.0 - R2));
        const double y0 = cyst_c.y + cyst.radius + 4.0, y1 = y0 + 6.0;
        const double measured = ratio_db(cyst_c.x, y0, y1);
        r.measurements.push_back({"posterior enhancement behind the cyst", measured, expected,
                                  0.2 * std::abs(expected), "dB"});
    }
    if (ctx.pictures)
        r.figures.push_back(frame_figure(f,
                                         "Liver with a fluid cyst (left: brighter behind) and a "
                                         "calcified plaque (right: shadow). No TGC difference "
                                         "between the columns compared."));
    return r;
}

// The on-axis two-way echo of a perpendicular plane at depth z on the middle line of a
// linear probe (t.lines odd), computed by image sources directly from the elements: the
// plane at depth z mirrors transmit element e to (x_e, 2z - y_e), so the echo is
//   sum_e sum_r a_e b_r D(theta)^2 exp(-ik (L_er - tau_e - tau_r - 2z)) / (sqrt(L_er) cos theta)
// (L_er: image-to-receiver distance, theta its angle from the elements' normal, which is
// also its angle from the plane's, D = sinc(pi p sin theta / lambda) cos theta, tau: the
// transmit and dynamic-receive focusing delays) times sqrt(lambda) from the stationary
// phase over the plane, over each field's unit-power norm sqrt((lambda / p) sum w^2). No
// lateral integral and no table; a perfect mirror at the focus with matched apertures
// would give 1. The weights a, b are the apertures' definitions (probe/aperture.h).
double plane_echo_by_image_sources(const probe::Transducer& t, double z) {
    const double lambda = t.wavelength_mm(), k = 2.0 * std::numbers::pi / lambda;
    const probe::LineArray array = probe::line_array(t, t.lines / 2);
    const std::vector<double> tx =
        probe::aperture_weights(array, t.active_aperture_mm(), t.tx_apodization);
    const std::vector<double> rx =
        probe::aperture_weights(array, t.receive_aperture_mm(z), t.rx_apodization);
    auto directivity = [&](double sin_theta, double cos_theta) {
        const double x = std::numbers::pi * t.pitch_mm * sin_theta / lambda;
        return (std::abs(x) < 1e-12 ? 1.0 : std::sin(x) / x) * cos_theta;
    };
    std::complex<double> sum = 0.0;
    double tx2 = 0.0, rx2 = 0.0;
    for (double w : tx) tx2 += w * w;
    for (double w : rx) rx2 += w * w;
    for (std::size_t e = 0; e < tx.size(); ++e) {
        if (tx[e] == 0.0) continue;
        const glm::dvec2 pe = array.position[e], image(pe.x, 2.0 * z - pe.y);
        const double tau_e = glm::length(glm::dvec2(0.0, t.focus_mm) - pe) - t.focus_mm;
        for (std::size_t q = 0; q < rx.size(); ++q) {
            if (rx[q] == 0.0) continue;
            const glm::dvec2 pr = array.position[q];
            const double L = glm::length(pr - image);
            const double sin_theta = (pr.x - pe.x) / L, cos_theta = (2.0 * z) / L;
            const double tau_r = glm::length(glm::dvec2(0.0, z) - pr) - z;
            const double d = directivity(sin_theta, cos_theta);
            sum += tx[e] * rx[q] * d * d / (std::sqrt(L) * cos_theta) *
                   std::polar(1.0, -k * (L - tau_e - tau_r - 2.0 * z));
        }
    }
    return std::abs(sum) * std::sqrt(lambda) * (t.pitch_mm / lambda) / std::sqrt(tx2 * rx2);
}

// Water without attenuation, and a speed-matched layer of it whose density reflects the
// amplitude fraction r against `below` (Z (1 + r) / (1 - r)).
tissue::AcousticProperties lossless_water() {
    tissue::AcousticProperties w;
    w[tissue::Property::speed_of_sound] = float(kC0);
    w[tissue::Property::density] = 1000.0f;
    return w;
}
// Everything deeper than z (a half-space facing the probe) made of `properties`.
phantoms::Shape plane_below(double z, const tissue::AcousticProperties& properties) {
    phantoms::Shape plane;
    plane.type = phantoms::ShapeType::half_space;
    plane.a = {20.0, z, 0.0}, plane.b = {0.0, 1.0, 0.0};
    plane.properties = properties;
    return plane;
}

tissue::AcousticProperties reflecting(const tissue::AcousticProperties& above, double r) {
    tissue::AcousticProperties p = above;
    p[tissue::Property::density] = float(above[tissue::Property::density] * (1.0 + r) / (1.0 - r));
    return p;
}

CaseResult flat_reflector(const CaseContext& ctx) {
    // The echo of a perpendicular flat reflector, moved from 6 to 40 mm in 0.5 mm steps,
    // in water without attenuation (a speed-matched density step, R = 0.05: scored, not
    // followed), against R times the plane echo by image sources (above): its mean level
    // within 1 dB, every depth within 1 dB, and no swing above 0.5 dB about a quadratic
    // trend (the swing the issue found had a 2 mm period).
    CaseResult r;
    probe::Transducer t = probe::find_transducer("linear", "validation");
    t.lines = 3;  // the frames' lines; the middle one is measured
    const tissue::AcousticProperties water = lossless_water();
    constexpr double kReflection = 0.05;  // amplitude; the beam carries unit power
    const tissue::AcousticProperties denser = reflecting(water, kReflection);
    std::vector<double> depth, measured_db, expected_db;
    for (double z = 6.0; z <= 40.0 + 1e-9; z += 0.5) {
        phantoms::Phantom ph;
        ph.name = "flat reflector", ph.source = "validation:flat_reflector";
        ph.size = {40.0, std::max(z, t.focus_mm) + 8.0, 10.0};
        ph.smoothing_mm = 0.1;
        ph.background = water;
        ph.shapes.push_back(plane_below(z, denser));
        ph.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
        const PhantomFrame f = image_phantom(
            ph, {std::max(z, t.focus_mm) + 4.0, 3, imaging::Quality::standard, false}, ctx.seed);
        depth.push_back(z);
        measured_db.push_back(20.0 * std::log10(line_peak(f.frame.envelope, 1, z - 1.0, z + 1.0)));
        expected_db.push_back(20.0 * std::log10(kReflection * plane_echo_by_image_sources(t, z)));
    }
    const std::size_t n = depth.size();
    double offset = 0.0;
    for (std::size_t i = 0; i < n; ++i) offset += (measured_db[i] - expected_db[i]) / double(n);
    std::vector<double> residual(n);
    double worst = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        residual[i] = measured_db[i] - expected_db[i] - offset;
        worst = std::max(worst, std::abs(residual[i]));
    }
    // The residual about its least-squares quadratic in depth (normal equations, 3 x 3).
    cv::Mat A(int(n), 3, CV_64F), b(int(n), 1, CV_64F), coef;
    for (std::size_t i = 0; i < n; ++i) {
        const double u = (depth[i] - 23.0) / 17.0;
        A.at<double>(int(i), 0) = 1.0, A.at<double>(int(i), 1) = u, A.at<double>(int(i), 2) = u * u;
        b.at<double>(int(i)) = residual[i];
    }
    cv::solve(A, b, coef, cv::DECOMP_SVD);
    double swing = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double u = (depth[i] - 23.0) / 17.0;
        const double trend =
            coef.at<double>(0) + coef.at<double>(1) * u + coef.at<double>(2) * u * u;
        swing = std::max(swing, std::abs(residual[i] - trend));
    }
    r.measurements.push_back(
        {"mean level against R x the plane echo (unit beam power)", offset, 0.0, 1.0, "dB"});
    r.measurements.push_back({"largest deviation from the on-axis two-way response (6-40 mm)",
                              worst, 1.0, 0.0, "dB", Check::at_most});
    r.measurements.push_back(
        {"largest residual about a quadratic trend", swing, 0.5, 0.0, "dB", Check::at_most});
    Plot plot{"echo of a flat reflector against depth (linear probe, focus 20 mm)",
              "depth of the reflector (mm)",
              "echo level (dB, one constant fitted)",
              {{"image sources of the aperture", {}, {}, false}, {"measured", {}, {}, true}},
              {t.focus_mm}};
    for (std::size_t i = 0; i < n; ++i) {
        plot.series[0].x.push_back(depth[i]), plot.series[0].y.push_back(expected_db[i] + offset);
        plot.series[1].x.push_back(depth[i]), plot.series[1].y.push_back(measured_db[i]);
    }
    r.plots.push_back(plot);
    return r;
}

CaseResult two_layers(const CaseContext& ctx) {
    // Water over two speed-matched layers (R12 = 0.3 at 10 mm, followed stochastically;
    // R23 = 0.2 at 20 mm): the second echo's intensity over the first's, each divided by
    // the on-axis plane echo at its depth (image sources, above), must be
    // R23^2 (1 - R12^2)^2 / R12^2 (the second echo crosses the first interface twice)
    // within 20 %. Averaged over the 27 lines within 8 mm of the centre, whose apertures
    // the array does not clip (the lines' particles choose reflection or transmission at
    // random: ~6 % spread per line).
    CaseResult r;
    constexpr double kR12 = 0.3, kR23 = 0.2, kZ1 = 10.0, kZ2 = 20.0;
    const tissue::AcousticProperties water = lossless_water();
    const tissue::AcousticProperties second = reflecting(water, kR12);
    const tissue::AcousticProperties third = reflecting(second, kR23);
    phantoms::Phantom ph;
    ph.name = "two layers", ph.source = "validation:two_layers";
    ph.size = {40.0, 40.0, 10.0};
    ph.smoothing_mm = 0.1;
    ph.background = water;
    ph.shapes = {plane_below(kZ1, second), plane_below(kZ2, third)};
    ph.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
    const PhantomFrame f =
        image_phantom(ph, {30.0, 65, imaging::Quality::standard, false}, ctx.seed);
    probe::Transducer centre = f.transducer;  // the middle line's apertures
    const double response2 = std::pow(
        plane_echo_by_image_sources(centre, kZ2) / plane_echo_by_image_sources(centre, kZ1), 2.0);
    const probe::ScanGeometry g(f.transducer);
    double sum = 0.0;
    int lines = 0;
    for (int l = 0; l < f.transducer.lines; ++l) {
        if (std::abs(g.point(l, 0.0).x) > 8.0) continue;
        const double a1 = line_peak(f.frame.envelope, l, kZ1 - 1.0, kZ1 + 1.0);
        const double a2 = line_peak(f.frame.envelope, l, kZ2 - 1.0, kZ2 + 1.0);
        sum += (a2 * a2) / (a1 * a1) / response2;
        ++lines;
    }
    const double expected = kR23 * kR23 * std::pow(1.0 - kR12 * kR12, 2.0) / (kR12 * kR12);
    r.measurements.push_back({"second / first echo intensity, on-axis response divided out (" +
                                  std::to_string(lines) + " lines)",
                              sum / lines, expected, 0.2 * expected, ""});
    return r;
}

CaseResult resolution(const CaseContext& ctx) {
    CaseResult r;
    // Axial: the echo of a flat interface (water over a bone-like half-space at 15 mm,
    // one reflection, no back wall) is the pulse-echo waveform's envelope: its FWHM in
    // depth is c0/2 times the envelope's in time. The waveform (an n-cycle sine (*) the
    // two-way impulse response, probe/pulse.h) is checked against a first-principles
    // construction in tests/test_psf.cpp; here the image must keep its width, within 10 %.
    const tissue::AcousticProperties water = [] {
        tissue::AcousticProperties p;
        p[tissue::Property::speed_of_sound] = float(kC0);
        p[tissue::Property::density] = 1000.0f;
        return p;
    }();
    tissue::AcousticProperties bone = water;
    bone[tissue::Property::speed_of_sound] = 3000.0f;
    bone[tissue::Property::density] = 1900.0f;
    {
        phantoms::Phantom ph;
        ph.name = "axial", ph.source = "validation:resolution";
        ph.size = {40.0, 30.0, 10.0};
        ph.smoothing_mm = 0.1;
        ph.background = water;
        phantoms::Shape s;
        s.type = phantoms::ShapeType::half_space;
        s.a = {20.0, 15.0, 0.0}, s.b = {0.0, 1.0, 0.0};
        s.properties = bone;
        ph.shapes.push_back(s);
        ph.pose = probe::Pose::looking({20.0, 0.0, 5.0}, {0, 1, 0}, {1, 0, 0});
        const PhantomFrame f =
            image_phantom(ph, {25.0, 32, imaging::Quality::high, false}, ctx.seed);
        const imaging::LineData& env = f.frame.envelope;
        const int l = env.lines / 2;
        int peak = 0;
        for (int i = 0; i < env.samples; ++i)
            if (env.at(l, i) > env.at(l, peak)) peak = i;
        const double fwhm =
            base::half_maximum(env.samples, peak, [&](int i) { return env.at(l, i); }).width() *
            (env.depth_mm(1) - env.depth_mm(0));
        const probe::Transducer& t = f.transducer;
        const double expected = probe::PulseEcho(t).axial_fwhm_mm();
        r.measurements.push_back({"axial FWHM (linear 7.6 MHz, B 0.79, one cycle)", fwhm, expected,
                                  0.1 * expected, "mm"});
        Plot plot{"axial profile of a flat interface's echo",
                  "depth from the peak (mm)",
                  "envelope / peak",
                  {{"pulse-echo envelope", {}, {}, false}, {"measured", {}, {}, true}},
                  {}};
        const probe::PulseEcho pulse(t);
        for (int i = std::max(0, peak - 12); i <= std::min(env.samples - 1, peak + 12); ++i) {
            plot.series[1].x.push_back(env.depth_mm(i) - env.depth_mm(peak));
            plot.series[1].y.push_back(env.at(l, i) / env.at(l, peak));
        }
        for (double d = -0.5; d <= 0.5; d += 0.01) {
            const double time_s = 2.0 * d * 1e-3 / kC0;
            plot.series[0].x.push_back(d);
            plot.series[0].y.push_back(
                std::hypot(pulse.in_phase(time_s), pulse.quadrature(time_s)));
        }
        r.plots.push_back(plot);
    }
    // Lateral: a 0.1 mm wire target at the transmit focus (20 mm), imaged through the
    // beams without being traced, across 512 lines 0.075 mm apart. With uniform (rectangular)
    // transmit and receive apertures of the same width D = z / F# at the focus, the
    // two-way field there is the square of the aperture's Fraunhofer pattern,
    // sinc^2(pi D x / (lambda z)): FWHM 0.886 lambda F# (sinc(u) = 1/sqrt 2 at
    // u = 1.3916) and a first side lobe of sinc^2 at u = 4.4934, -26.5 dB. Element
    // directivity and cylindrical spreading change both by under a percent at F/2.
    {
        probe::Transducer t = probe::find_transducer("linear", "validation");
        t.lines = 512;
        t.depth_mm = 24.0;
        t.tx_apodization = probe::Apodization::rectangular;
        t.rx_apodization = probe::Apodization::rectangular;
        t.rx_f_number = t.f_number;
        const PhantomFrame f = wire_in_water(t, water, 0.03, t.focus_mm, ctx.seed);
        const LateralProfile p = lateral_profile(f, t.focus_mm - 1.0, t.focus_mm + 1.0, -3.0, 3.0);
        const double lambda = t.wavelength_mm();
        const double expected = 0.886 * lambda * t.f_number;
        r.measurements.push_back({"lateral FWHM at the focus (20 mm, F/2, uniform apertures)",
                                  p.fwhm, expected, 0.1 * expected, "mm"});
        // First side lobe: the largest peak between the first zero (lambda F# from the
        // centre) and the second (2 lambda F#), on both sides.
        const double top = *std::max_element(p.peak.begin(), p.peak.end());
        double lobe = 0.0;
        for (std::size_t i = 0; i < p.x.size(); ++i) {
            const double off = std::abs(p.x[i] - p.centre);
            if (off > 1.1 * lambda * t.f_number && off < 1.9 * lambda * t.f_number)
                lobe = std::max(lobe, p.peak[i]);
        }
        const double sinc_lobe = std::sin(4.4934) / 4.4934;
        r.measurements.push_back({"first side lobe (two-way)", 20.0 * std::log10(lobe / top),
                                  40.0 * std::log10(std::abs(sinc_lobe)), 3.0, "dB"});
        Plot plot{"lateral profile of a 0.1 mm wire at the focus (512 lines)",
                  "lateral position (mm)",
                  "envelope / peak",
                  {{"sinc^2 of the uniform aperture", {}, {}, false}, {"measured", {}, {}, true}},
                  {}};
        for (std::size_t i = 0; i < p.x.size(); ++i) {
            if (std::abs(p.x[i] - p.centre) > 1.5) continue;
            plot.series[1].x.push_back(p.x[i]), plot.series[1].y.push_back(p.peak[i] / top);
        }
        for (double x = -1.5; x <= 1.5; x += 0.01) {
            const double u = std::numbers::pi * x / (lambda * t.f_number);
            const double sinc = std::abs(u) < 1e-9 ? 1.0 : std::sin(u) / u;
            plot.series[0].x.push_back(p.centre + x);
            plot.series[0].y.push_back(sinc * sinc);
        }
        r.plots.push_back(plot);
    }
    // Lateral at 10, 20 and 30 mm with the preset's apertures (transmit focus 20 mm at F/2,
    // Tukey; receive Hann) and rectangular ones, for a receive at F/2 and on the whole array: the
    // FWHM of a 0.1 mm wire across 768 lines 0.05 mm apart within 10 % of the broadband element
    // sum's, and its first side lobe within 2 dB.
    for (const bool rectangular : {false, true})
        for (const double rx_f : {2.0, 0.1}) {
            probe::Transducer t = probe::find_transducer("linear", "validation");
            t.lines = 768;
            t.rx_f_number = rx_f;
            if (rectangular) t.tx_apodization = t.rx_apodization = probe::Apodization::rectangular;
            const char* apertures = rectangular ? "rectangular" : "preset apodization";
            const ReferenceLinearArray reference(t);
            for (const double z : {10.0, 20.0, 30.0}) {
                t.depth_mm = z + 4.0;
                const double x0 = 0.013;  // off any line
                const PhantomFrame f = wire_in_water(t, water, x0, z, ctx.seed);
                const LateralProfile measured = lateral_profile(f, z - 1.0, z + 1.0, -3.0, 3.0);
                std::vector<double> predicted;
                for (const double xl : measured.x)
                    predicted.push_back(reference.two_way(xl, x0, z));
                const double expected = analyse_lateral(measured.x, predicted).fwhm;
                char quantity[96];
                std::snprintf(quantity, sizeof quantity, "lateral FWHM at %.0f mm, receive %s, %s",
                              z, rx_f < 1.0 ? "on the whole array" : "at F/2", apertures);
                r.measurements.push_back({quantity, measured.fwhm, expected, 0.1 * expected, "mm"});
                std::snprintf(quantity, sizeof quantity,
                              "first side lobe at %.0f mm, receive %s, %s", z,
                              rx_f < 1.0 ? "on the whole array" : "at F/2", apertures);
                r.measurements.push_back({quantity, first_side_lobe_db(measured.peak),
                                          first_side_lobe_db(predicted), 2.0, "dB"});
            }
        }
    return r;
}

// The envelope divided by the mean of the background at the same depth (+-0.5 mm): the
// samples more than 2 mm from every shape. Removes the depth trend of attenuation and
// focusing; contrast-to-noise ratios and mean/std within a depth band are unchanged by a
// per-depth scale but no longer mix depths.
imaging::LineData depth_normalised(const PhantomFrame& f) {
    const imaging::LineData& env = f.frame.envelope;
    const probe::ScanGeometry g(f.transducer);
    const probe::Pose& pose = f.phantom.pose;
    std::vector<double> row(std::size_t(env.samples), 0.0), count(row.size(), 0.0);
    for (int l = 0; l < env.lines; ++l) {
        for (int i = 0; i < env.samples; ++i) {
            const glm::dvec2 p = g.point(l, env.depth_mm(i));
            const glm::dvec3 world = pose.position + p.x * pose.lateral() + p.y * pose.axial();
            bool clear = true;
            for (const auto& s : f.phantom.shapes) clear = clear && s.signed_distance(world) > 2.0;
            if (clear) row[std::size_t(i)] += env.at(l, i), count[std::size_t(i)] += 1.0;
        }
    }
    const double dz = env.depth_mm(1) - env.depth_mm(0);
    const int half = std::max(1, int(0.5 / dz));
    imaging::LineData out = env;
    for (int i = 0; i < env.samples; ++i) {
        double m = 0.0, n = 0.0;
        for (int k = std::max(0, i - half); k <= std::min(env.samples - 1, i + half); ++k)
            m += row[std::size_t(k)], n += count[std::size_t(k)];
        const double scale = m > 0.0 ? n / m : 0.0;
        for (int l = 0; l < env.lines; ++l) out.at(l, i) = float(env.at(l, i) * scale);
    }
    return out;
}

CaseResult speckle_and_cysts(const CaseContext& ctx) {
    // Transmit focus at 35 mm, among the cysts and the speckle region: the scatter
    // profile is the transmit beam's, so a beam much wider than a cyst fills it in.
    // Three frames (seeds) pooled: the apodized apertures' two-way PSF is ~0.5 mm wide at
    // the focus, so a cyst holds fewer independent speckle cells than the bounds below
    // assume for one frame.
    constexpr int kFrames = 3;
    std::vector<PhantomFrame> frames;
    imaging::LineData raw;
    for (int k = 0; k < kFrames; ++k) {
        frames.push_back(image_phantom(catalogue(ctx, "qa_multipurpose"),
                                       {60.0, 0, imaging::Quality::high, true, 35.0},
                                       ctx.seed + 1000 * uint64_t(k)));
        if (k == 0) raw = frames.back().frame.envelope;
        frames.back().frame.envelope = depth_normalised(frames.back());
    }
    PhantomFrame& f = frames.front();
    auto pooled = [&](auto inside) {
        std::vector<double> all;
        for (const PhantomFrame& one : frames) {
            const std::vector<double> v = envelope_samples(one, inside);
            all.insert(all.end(), v.begin(), v.end());
        }
        return all;
    };
    CaseResult r;
    // Fully developed speckle: the envelope of a homogeneous scattering region is Rayleigh
    // distributed, mean/std = sqrt(pi / (4 - pi)) = 1.913; the bound is 0.15. The
    // region (x 8..16, depth 31..41 mm of the phantom) holds no targets and lies clear of
    // the enhancement behind the 6 mm cyst.
    const glm::dvec2 lo = f.plane(glm::dvec2(8.0, 31.0)), hi = f.plane(glm::dvec2(16.0, 41.0));
    const auto speckle = pooled(
        [&](glm::dvec2 p) { return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y; });
    const double snr = mean(speckle) / stddev(speckle);
    r.measurements.push_back({"speckle SNR (envelope mean / std)", snr,
                              std::sqrt(std::numbers::pi / (4.0 - std::numbers::pi)), 0.15, ""});
    // Cysts, against a background ring 1.5..4 mm outside each at the same depths, on lines
    // whose transmit aperture the array's ends do not clip (their beams are weaker).
    const double unclipped =
        0.5 * (f.transducer.array_length_mm() - f.transducer.active_aperture_mm());
    auto region = [&](const phantoms::Shape& s, double r0, double r1) {
        const glm::dvec2 c = f.plane(glm::dvec2(s.a));
        return pooled([&](glm::dvec2 p) {
            const double d = glm::length(p - c);
            return d >= r0 && d <= r1 && std::abs(p.y - c.y) <= s.radius &&
                   std::abs(p.x) <= unclipped;
        });
    };
    // Anechoic (the 6 mm cyst): inside only noise-free silence, so the contrast-to-noise
    // ratio (mu_b - mu_c) / sqrt(sigma_b^2 + sigma_c^2) tends to the background's
    // mu/sigma = 1.913. Tolerance 0.25: the speckle bound 0.15 plus leakage of the beam
    // into the cyst's edge.
    const auto& anechoic = shape(f.phantom, phantoms::ShapeType::sphere, 2);  // 6 mm
    const auto inside_a = region(anechoic, 0.0, anechoic.radius - 1.0);
    const auto ring_a = region(anechoic, anechoic.radius + 1.5, anechoic.radius + 4.0);
    const double cnr = (mean(ring_a) - mean(inside_a)) /
                       std::sqrt(std::pow(stddev(ring_a), 2) + std::pow(stddev(inside_a), 2));
    r.measurements.push_back({"anechoic cyst (6 mm) CNR", cnr, 1.913, 0.25, ""});
    // Hyperechoic: backscatter b sets both the scattering-event rate and the fraction each
    // event returns (tracer), so the scattered intensity scales as b^2: contrast
    // 20 log10(b_cyst / b_background). Mean intensities of ~300 speckle cells each over
    // the three frames: a 4 sigma error of the ratio ~1.2 dB; tolerance 1.5 dB.
    const auto& hyper = shape(f.phantom, phantoms::ShapeType::sphere, 3);
    const double b_in = property(hyper.properties, tissue::Property::backscatter);
    const double b_bg = property(f.phantom.background, tissue::Property::backscatter);
    const double contrast =
        10.0 * std::log10(mean_square(region(hyper, 0.0, hyper.radius - 1.0)) /
                          mean_square(region(hyper, hyper.radius + 1.5, hyper.radius + 4.0)));
    r.measurements.push_back(
        {"hyperechoic cyst (8 mm) contrast", contrast, 20.0 * std::log10(b_in / b_bg), 1.5, "dB"});
    if (ctx.pictures) {
        f.frame.envelope = raw;
        r.figures.push_back(frame_figure(f,
                                         "QA phantom (linear 7.6 MHz, focus 35 mm): the speckle "
                                         "region (green circles: its corners) is left of the "
                                         "axial wire pairs, above the lateral row.",
                                         {lo, hi}));
    }
    return r;
}

// A medium filling a 100 x 90 x 20 mm box (0.25 mm map) under the default frame's
// convex probe, imaged at the standard quality.
PhantomFrame convex_frame(const std::string& name, const nlohmann::json& background,
                          uint64_t seed) {
    const nlohmann::json j = {{"name", name},
                              {"size", {100, 90, 20}},
                              {"resolution", 0.25},
                              {"smoothing", 0.3},
                              {"background", background},
                              {"probe", {{"preset", "convex"}, {"at", {50, 0, 10}}}}};
    return image_phantom(phantoms::parse_phantom(j, "validation:" + name),
                         {0.0, 0, imaging::Quality::standard, true, 0.0}, seed);
}

// Radial streaks: over homogeneous brain at the standard quality (the default frame's
// convex probe, 32 particles a line), the per-line mean intensity over a depth band
// varies across lines no more than speckle allows. The expected spread of one line's
// band mean is sigma_I / sqrt(N_eff): sigma_I the intensity's standard deviation, N_eff
// the band's samples over the intensity's axial correlation length (1 + 2 x the sum of
// its autocorrelation coefficients until they fall below 0.02), both measured on the same
// lines: the statistics of a mean of correlated samples. The bound is 1.2 times
// that, over the central half of the lines (unclipped apertures), in 10 mm bands at
// 20-30, 40-50 and 60-70 mm. 64 lines estimate the spread within ~9 % (1 sigma).
CaseResult per_line_means(const CaseContext& ctx) {
    const PhantomFrame f = convex_frame("homogeneous brain", {{"tissue", "brain"}}, ctx.seed);
    const imaging::LineData& env = f.frame.envelope;
    auto intensity = [&](int l, int i) { return double(env.at(l, i)) * env.at(l, i); };
    const int first = env.lines / 4, last = 3 * env.lines / 4;
    CaseResult r;
    for (const double from : {20.0, 40.0, 60.0}) {
        const int i0 = int(from / env.depth_mm(1)), i1 = int((from + 10.0) / env.depth_mm(1));
        const int n = i1 - i0;
        std::vector<double> means, all;
        for (int l = first; l < last; ++l) {
            double m = 0.0;
            for (int i = i0; i < i1; ++i) m += intensity(l, i), all.push_back(intensity(l, i));
            means.push_back(m / n);
        }
        const double mu = mean(all), var = std::pow(stddev(all), 2);
        double correlation_length = 1.0;
        for (int k = 1; k < n / 4; ++k) {
            double c = 0.0;
            int pairs = 0;
            for (int l = first; l < last; ++l)
                for (int i = i0; i + k < i1; ++i, ++pairs)
                    c += (intensity(l, i) - mu) * (intensity(l, i + k) - mu);
            const double rho = c / pairs / var;
            if (rho < 0.02) break;
            correlation_length += 2.0 * rho;
        }
        const double allowed = std::sqrt(var * correlation_length / n);
        char quantity[96];
        std::snprintf(quantity, sizeof quantity,
                      "per-line mean spread over what speckle allows, %.0f-%.0f mm", from,
                      from + 10.0);
        // The lines' sample standard deviation (n - 1: their mean is estimated too).
        const double m = double(means.size()), spread = stddev(means) * std::sqrt(m / (m - 1.0));
        r.measurements.push_back({quantity, spread / allowed, 1.2, 0.0, "", Check::at_most});
    }
    if (ctx.pictures)
        r.figures.push_back(frame_figure(f, "homogeneous brain, convex 3.5 MHz, standard quality"));
    return r;
}

// Fully developed speckle through the whole pipeline (tracer, echo profile, RF): a
// scattering medium without attenuation under the default frame's convex probe. The
// envelope is Rayleigh distributed, mean/std = sqrt(pi / (4 - pi)) = 1.913 (the issue:
// +-0.15) at 20, 40 and 60 mm, in 3 mm bands over the central half of the lines. Its mean
// square against depth follows the lateral power integral of the two-way field,
// integral |T R|^2 dx (the issue: within 1.5 dB), computed here on the aperture's fields
// (probe::LineFields, not the image pipeline) across +-12 mm at lambda / 8, relative to
// the transmit focus.
CaseResult speckle_depth(const CaseContext& ctx) {
    const PhantomFrame f = convex_frame("scatterers without attenuation",
                                        {{"speed_of_sound", 1540},
                                         {"density", 1040},
                                         {"attenuation", 0},
                                         {"backscatter", 0.35},
                                         {"scatterer_density", 15},
                                         {"roughness", 0}},
                                        ctx.seed);
    const imaging::LineData& env = f.frame.envelope;
    const probe::Transducer& t = f.transducer;
    const int first = env.lines / 4, last = 3 * env.lines / 4;
    auto band = [&](double z) {
        std::vector<double> v;
        const int from = int((z - 1.5) / env.depth_mm(1)), to = int((z + 1.5) / env.depth_mm(1));
        for (int l = first; l < last; ++l)
            for (int i = from; i < to; ++i) v.push_back(env.at(l, i));
        return v;
    };
    CaseResult r;
    for (const double z : {20.0, 40.0, 60.0}) {
        const std::vector<double> v = band(z);
        char quantity[64];
        std::snprintf(quantity, sizeof quantity, "speckle SNR at %.0f mm", z);
        r.measurements.push_back({quantity, mean(v) / stddev(v),
                                  std::sqrt(std::numbers::pi / (4.0 - std::numbers::pi)), 0.15,
                                  ""});
    }
    const probe::LineFields fields(t, probe::line_array(t, t.lines / 2));
    auto lateral_power = [&](double z) {
        const double dx = t.wavelength_mm() / 8.0;
        const auto receive = fields.receive_aperture(z);
        double sum = 0.0;
        for (double x = -12.0; x <= 12.0; x += dx)
            sum += std::norm(fields.transmit({x, z}) * fields.receive({x, z}, receive)) * dx;
        return sum;
    };
    const double focus_image = mean_square(band(t.focus_mm)),
                 focus_power = lateral_power(t.focus_mm);
    for (const double z : {15.0, 25.0, 35.0, 65.0, 75.0}) {
        char quantity[96];
        std::snprintf(quantity, sizeof quantity, "mean level at %.0f mm against the focus's", z);
        r.measurements.push_back({quantity, 10.0 * std::log10(mean_square(band(z)) / focus_image),
                                  10.0 * std::log10(lateral_power(z) / focus_power), 1.5, "dB"});
    }
    if (ctx.pictures)
        r.figures.push_back(frame_figure(f, "scatterers without attenuation, convex 3.5 MHz"));
    return r;
}

}  // namespace

void add_imaging_cases(std::vector<Case>& out) {
    out.push_back({"wire_depth", "depth accuracy of the calibration wires",
                   "QA phantom, linear probe: the calibration wires at 10..50 mm in a 1540 m/s "
                   "background must appear at their depth (front face) within 0.5 mm.",
                   wire_depth});
    out.push_back({"speed_displacement", "speed-of-sound displacement behind a fat layer",
                   "Wires under a 15 mm fat layer (1450 m/s) appear deeper than their neighbours "
                   "by L (c0/c_fat - c0/c_background); within 10 %.",
                   speed_displacement});
    out.push_back({"refraction_shift", "lateral displacement by refraction (Snell)",
                   "A wire under a 10 mm slow slab tilted 40 degrees: the beam leaves the slab "
                   "shifted sideways by T sin(i - t)/cos(t) (Snell), so the wire appears that far "
                   "to the other side; within 0.15 mm.",
                   refraction_shift});
    out.push_back({"mirror_image", "mirror image behind an inclined reflector",
                   "A wire 7.5 mm and a point target 6.7 mm in front of an air interface tilted "
                   "20 degrees: their images must appear at them mirrored through the interface "
                   "plane, within 1 mm.",
                   mirror_image});
    out.push_back({"shadow_enhancement", "shadow behind a plaque, enhancement behind a cyst",
                   "Intensity 4..10 mm below each object against plain liver at the same "
                   "depths: the shadow equals the two-way transmission loss of the plaque "
                   "(faces and extra attenuation) within 1.5 dB; the enhancement equals the "
                   "two-way attenuation saved over the cyst's chord within 20 %.",
                   shadow_and_enhancement});
    out.push_back({"resolution", "axial and lateral resolution against theory",
                   "The axial FWHM of a flat interface's echo against the pulse-echo "
                   "waveform's envelope (within 10 %); the lateral FWHM and first side lobe of "
                   "a 0.1 mm wire target at the focus, uniform apertures at F/2, against "
                   "sinc^2: 0.886 lambda F# (within 10 %) and -26.5 dB (within 3 dB).",
                   resolution});
    out.push_back({"flat_reflector", "a flat reflector's echo against depth",
                   "The echo of a perpendicular flat reflector moved from 6 to 40 mm follows the "
                   "aperture's on-axis two-way response (image sources of the elements) within "
                   "1 dB, with no swing above 0.5 dB about a quadratic trend.",
                   flat_reflector});
    out.push_back({"two_layers", "echo ratio of two interfaces",
                   "Water over two layers (R12 = 0.3, R23 = 0.2): the second echo's intensity "
                   "over the first's, the on-axis plane response divided out, against "
                   "R23^2 (1 - R12^2)^2 / R12^2 within 20 %.",
                   two_layers});
    out.push_back({"speckle_cysts", "speckle statistics and cyst contrast",
                   "QA phantom: envelope SNR of the homogeneous region against the Rayleigh "
                   "value 1.913 (+-0.15); the anechoic cyst's CNR tends to the same value; the "
                   "hyperechoic cyst's contrast against 20 log10 of the backscatter ratio.",
                   speckle_and_cysts});
    out.push_back({"per_line_means", "no radial streaks at the standard quality",
                   "Homogeneous brain under the default frame's convex probe at the standard "
                   "quality: in 10 mm bands at 20, 40 and 60 mm, the spread of the per-line mean "
                   "intensities over the central half of the lines at most 1.2 times what "
                   "speckle allows (sigma_I / sqrt(N_eff), N_eff from the intensity's axial "
                   "correlation length).",
                   per_line_means});
    out.push_back({"speckle_depth", "speckle statistics and level against depth",
                   "A scattering medium without attenuation under the convex probe, the whole "
                   "pipeline: the envelope's SNR 1.913 +- 0.15 at 20, 40 and 60 mm; its mean "
                   "level against depth, relative to the transmit focus, within 1.5 dB of the "
                   "two-way field's lateral power integral (from the aperture).",
                   speckle_depth});
}

}  // namespace sonotrace::validation
