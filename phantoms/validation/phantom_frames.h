#pragma once
// What the imaging validation cases (phantoms/validation/cases_*.cpp) share: a catalogue
// phantom imaged with its probe, and the measurements on its envelope (lines x samples,
// before TGC and compression).
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "phantoms/validation/validation.h"
#include "probe/transducer.h"

namespace sonotrace::validation {

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

// `transmit`: empty for focused lines, else as simulate --transmit.
PhantomFrame image_phantom(phantoms::Phantom phantom, const FrameOptions& o, uint64_t seed,
                           const std::string& transmit = "");

phantoms::Phantom catalogue(const CaseContext& ctx, const std::string& name);

// The first shape of a type (the catalogue files are ours: a missing one is a bug).
const phantoms::Shape& shape(const phantoms::Phantom& p, phantoms::ShapeType type, int nth = 0);

double property(const tissue::AcousticProperties& p, tissue::Property f);

// Depth (mm, c0 t / 2) of the first echo of a line in [from, to]: the first local maximum
// at half the window's maximum or more (a wire's back wall can be the stronger echo),
// refined by a parabola through its neighbours.
double first_echo_depth(const imaging::LineData& env, int line, double from_mm, double to_mm);

// Largest envelope value of a line within [from, to] mm.
float line_peak(const imaging::LineData& env, int line, double from_mm, double to_mm);

// Lateral position (mm) and full width at half maximum of a target seen across the lines
// (the per-line peaks within a depth window), linear interpolation at the crossings.
struct LateralProfile {
    double centre = std::nan(""), fwhm = std::nan("");
    std::vector<double> x, peak;  // per line
};
LateralProfile analyse_lateral(const std::vector<double>& x, const std::vector<double>& peak);
LateralProfile lateral_profile(const PhantomFrame& f, double from_mm, double to_mm, double x_from,
                               double x_to);

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

// Apparent depth of a wire's first echo: the intensity summed over the lines within
// 0.5 mm of it (the speckle averages, the wire's echo adds up), then the first local
// maximum at half the window's maximum or more.
double wire_echo_depth(const PhantomFrame& f, const glm::dvec2& at, double from_mm, double to_mm);

double mean(const std::vector<double>& v);
double mean_square(const std::vector<double>& v);
double stddev(const std::vector<double>& v);

// The frame as the user sees it, with circles: green = expected, red = measured.
Figure frame_figure(const PhantomFrame& f, const std::string& caption,
                    const std::vector<glm::dvec2>& expected = {},
                    const std::vector<glm::dvec2>& measured = {});

}  // namespace sonotrace::validation
