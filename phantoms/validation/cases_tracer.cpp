// Cases measured on the tracer's own records (paths, echo events, energy maps): Snell's
// law, the critical angle, the oblique-incidence reflection coefficient, the fibre guide
// of Reis & Bertram's figure 4, reverberation between parallel reflectors and between
// the probe face and a reflector, and sedimentation (figure 5).
#include <cmath>
#include <numbers>

#include "imaging/picture.h"
#include "imaging/trace_pictures.h"
#include "phantoms/trace_setup.h"
#include "phantoms/validation/validation.h"
#include "simulator/interactions.h"
#include "simulator/trace_setups.h"
#include "simulator/tracer.h"

namespace sonotrace::validation {
namespace {

using simulator::Sources;
using simulator::TraceSettings;
using tissue::AcousticProperties;
using tissue::Property;

// ---- an interface tilted by 20 degrees (not grid-aligned) through (30, 30) mm ----

constexpr double kH = 0.25, kTilt = 20.0;
const glm::dvec2 kCentre(30.0, 30.0);
glm::dvec2 interface_normal() {
    return {std::sin(glm::radians(kTilt)), std::cos(glm::radians(kTilt))};
}

tissue::PropertyMaps interface_maps(const AcousticProperties& a, const AcousticProperties& b) {
    return simulator::planar_interface(240, 240, kH, kCentre, interface_normal(), a, b, 2.0);
}

// Direction at `incidence_deg` from the interface normal.
glm::dvec2 incident(double incidence_deg) {
    const glm::dvec2 n = interface_normal(), t(n.y, -n.x);
    const double a = glm::radians(incidence_deg);
    return std::cos(a) * n + std::sin(a) * t;
}

// One particle aimed at the interface centre; its path.
simulator::Path<2> shoot(const tissue::AcousticMap<2>& map, double incidence_deg,
                         TraceSettings settings) {
    const glm::dvec2 dir = incident(incidence_deg);
    settings.record_paths = 1;
    settings.max_path_mm = 38.0;  // ends well inside the map, far from the interface
    const Sources<2> src = {{glm::vec2(kCentre - 20.0 * dir), glm::vec2(dir), 1.0f, 0}};
    return simulator::trace(map, src, settings).paths.at(0);
}

// Final direction of a path (over its last 8 vertices: 1 mm, clear of the interface).
glm::dvec2 final_direction(const simulator::Path<2>& path) {
    const auto& v = path.vertices;
    return glm::normalize(glm::dvec2(v.back().position - v[v.size() - 9].position));
}

double angle_to_normal_deg(glm::dvec2 dir) {
    return glm::degrees(std::acos(std::min(1.0, std::abs(glm::dot(dir, interface_normal())))));
}

tissue::Volume speed_field(const tissue::PropertyMaps& maps) {
    return maps[Property::speed_of_sound];
}

CaseResult refraction_angle(const CaseContext& ctx) {
    // c 1500 -> 1800 m/s: sin(theta_t) = sin(theta_i) c2 / c1 below the critical angle.
    const double c1 = 1500.0, c2 = 1800.0;
    const auto maps =
        interface_maps(simulator::lossless_medium(c1, 1000), simulator::lossless_medium(c2, 1000));
    const auto map = tissue::AcousticMap<2>::build(maps);
    TraceSettings s = simulator::interfaces_only_settings();
    s.physics.set(simulator::Physics::specular, false);  // isolate refraction
    CaseResult r;
    Plot plot{"transmitted angle against Snell's law (c 1500 -> 1800 m/s)",
              "incidence (deg)",
              "transmitted angle (deg)",
              {{"Snell: asin(sin(i) c2/c1)", {}, {}, false}, {"measured", {}, {}, true}},
              {}};
    std::vector<simulator::Path<2>> paths;
    for (double incidence = 2.0; incidence <= 54.0; incidence += 4.0) {
        const double expected =
            glm::degrees(std::asin(std::sin(glm::radians(incidence)) * c2 / c1));
        const auto path = shoot(map, incidence, s);
        const glm::dvec2 out = final_direction(path);
        const double measured = glm::dot(out, interface_normal()) > 0.0
                                    ? angle_to_normal_deg(out)
                                    : std::nan("");  // reflected: fails
        // 0.5 deg: the interface normal comes from a 50-sample patch of a 2-texel ramp,
        // and the direction is read over 1 mm of float path.
        r.measurements.push_back(
            {"transmitted angle at " + std::to_string(int(incidence)) + " deg incidence", measured,
             expected, 0.5, "deg"});
        plot.series[1].x.push_back(incidence), plot.series[1].y.push_back(measured);
        if (int(incidence) % 8 == 2) paths.push_back(path);
    }
    for (double i = 0.0; i <= 56.0; i += 0.5) {
        plot.series[0].x.push_back(i);
        plot.series[0].y.push_back(
            glm::degrees(std::asin(std::min(1.0, std::sin(glm::radians(i)) * c2 / c1))));
    }
    // The reverse direction (fast -> slow) bends towards the normal, at any incidence.
    const auto reverse = tissue::AcousticMap<2>::build(
        interface_maps(simulator::lossless_medium(c2, 1000), simulator::lossless_medium(c1, 1000)));
    for (double incidence : {10.0, 30.0, 60.0, 80.0}) {
        const double expected =
            glm::degrees(std::asin(std::sin(glm::radians(incidence)) * c1 / c2));
        const glm::dvec2 out = final_direction(shoot(reverse, incidence, s));
        r.measurements.push_back({"fast -> slow: transmitted angle at " +
                                      std::to_string(int(incidence)) + " deg incidence",
                                  angle_to_normal_deg(out), expected, 0.5, "deg"});
    }
    r.plots.push_back(plot);
    if (ctx.pictures) {
        imaging::PathStyle style;
        r.figures.push_back(
            {"paths at 2, 10, 18, ... degrees over the speed of sound (dark "
             "1500, bright 1800 m/s); refraction away from the normal",
             imaging::draw_paths(speed_field(maps), paths, style)});
    }
    return r;
}

CaseResult critical_angle(const CaseContext&) {
    // Slow -> fast: theta_c = asin(c1 / c2). Scan the incidence in 0.1 degree steps.
    const double c1 = 1500.0, c2 = 1800.0;
    const auto map = tissue::AcousticMap<2>::build(
        interface_maps(simulator::lossless_medium(c1, 1000), simulator::lossless_medium(c2, 1000)));
    TraceSettings s = simulator::interfaces_only_settings();
    s.physics.set(simulator::Physics::specular, false);
    const double critical = glm::degrees(std::asin(c1 / c2));
    double last_transmitted = 0.0, first_reflected = 90.0;
    Plot plot{"transmitted (1) or totally reflected (0) around the critical angle",
              "incidence (deg)",
              "transmitted",
              {{"measured", {}, {}, true}},
              {critical}};
    for (double incidence = critical - 3.0; incidence <= critical + 3.0; incidence += 0.1) {
        const bool transmitted =
            glm::dot(final_direction(shoot(map, incidence, s)), interface_normal()) > 0.0;
        if (transmitted)
            last_transmitted = std::max(last_transmitted, incidence);
        else
            first_reflected = std::min(first_reflected, incidence);
        plot.series[0].x.push_back(incidence), plot.series[0].y.push_back(transmitted ? 1 : 0);
    }
    CaseResult r;
    // 0.5 deg, as for refraction (the normal's estimate decides on which side a ray falls).
    r.measurements.push_back(
        {"largest transmitted incidence", last_transmitted, critical, 0.5, "deg"});
    r.measurements.push_back(
        {"smallest totally reflected incidence", first_reflected, critical, 0.5, "deg"});
    // Beyond it every particle reflects, and a mirror keeps the angle (the law of
    // reflection, within the same 0.5 deg).
    for (double incidence : {60.0, 65.0, 70.0, 75.0, 80.0}) {
        const glm::dvec2 out =
            final_direction(shoot(map, incidence, simulator::interfaces_only_settings()));
        const bool reflected = glm::dot(out, interface_normal()) < 0.0;
        r.measurements.push_back(
            {"reflection angle at " + std::to_string(int(incidence)) + " deg incidence",
             reflected ? angle_to_normal_deg(out) : std::nan(""), incidence, 0.5, "deg"});
    }
    r.plots.push_back(plot);
    return r;
}

CaseResult reflected_fraction(const CaseContext&) {
    // Z 1.5 -> 4.5 MRayl (c 1500 -> 1800, rho 1000 -> 2500): R^2 of the oblique-incidence
    // pressure coefficient (Z2 cos i - Z1 cos t) / (Z2 cos i + Z1 cos t), for 11 angles.
    // 4000 particles each: the reflected fraction is binomial; tolerance 3 sigma (99.7 %).
    const double c1 = 1500.0, c2 = 1800.0, z1 = 1.5, z2 = 4.5;
    const auto map = tissue::AcousticMap<2>::build(
        interface_maps(simulator::lossless_medium(c1, 1000), simulator::lossless_medium(c2, 2500)));
    TraceSettings s = simulator::interfaces_only_settings();
    constexpr int kParticles = 4000;
    CaseResult r;
    Plot plot{"reflected energy fraction against the oblique-incidence coefficient",
              "incidence (deg)",
              "reflected fraction",
              {{"R^2 (eq. 10, acoustic)", {}, {}, false}, {"measured", {}, {}, true}},
              {}};
    auto coefficient = [&](double incidence) {
        const double sin_t = std::sin(glm::radians(incidence)) * c2 / c1;
        if (sin_t >= 1.0) return 1.0;
        return double(simulator::reflected_fraction(float(z1), float(z2),
                                                    float(std::cos(glm::radians(incidence))),
                                                    float(std::sqrt(1.0 - sin_t * sin_t))));
    };
    for (int a = 0; a <= 10; ++a) {
        const double incidence = 5.0 * a;
        const double expected = coefficient(incidence);
        const glm::dvec2 dir = incident(incidence), t(interface_normal().y, -interface_normal().x);
        Sources<2> src;
        for (int p = 0; p < kParticles; ++p) {
            // Starts spread along the interface by +-2 mm.
            const glm::dvec2 start = kCentre - 15.0 * dir + t * (4.0 * p / kParticles - 2.0);
            src.push_back({glm::vec2(start), glm::vec2(dir), 1.0f, uint32_t(p / 500)});
        }
        s.seed = 1000 + uint64_t(a);
        const auto result = simulator::trace(map, src, s);
        const double measured = double(result.stats.reflections) / kParticles;
        const double sigma = std::sqrt(expected * (1.0 - expected) / kParticles);
        r.measurements.push_back(
            {"reflected fraction at " + std::to_string(int(incidence)) + " deg", measured, expected,
             3.0 * sigma, ""});
        plot.series[1].x.push_back(incidence), plot.series[1].y.push_back(measured);
    }
    for (double i = 0.0; i <= 56.0; i += 0.5) {
        plot.series[0].x.push_back(i), plot.series[0].y.push_back(coefficient(i));
    }
    r.plots.push_back(plot);
    return r;
}

CaseResult fibre_guide(const CaseContext& ctx) {
    // Figure 4: a bent fibre with a parabolic density profile (core radius 5 mm). Ray
    // optics of the bend (simulator/trace_setups.h) guides every injected particle: none may
    // leave the core, and the track's width (largest |offset| from the centreline over the
    // first and the last third) may grow by at most 5 % (the bound).
    const simulator::FibreGeometry fibre;
    CaseResult r;
    for (const char* name : {"fig4a", "fig4b"}) {
        simulator::TraceSetup scene = phantoms::trace_setup(
            phantoms::load_phantom(ctx.phantom_dir + "/paper_" + name + ".json"), 21);
        const auto result = simulator::trace(scene.map, scene.sources, scene.settings);
        const double length = fibre.length_mm() - 6.0;
        double first = 0.0, last = 0.0, worst = 0.0;
        for (const auto& path : result.paths) {
            for (const auto& v : path.vertices) {
                const glm::dvec2 oa = fibre.offset_and_arc(glm::dvec2(v.position));
                worst = std::max(worst, std::abs(oa.x));
                if (oa.y < length / 3) first = std::max(first, std::abs(oa.x));
                if (oa.y > 2 * length / 3 && oa.y < length) last = std::max(last, std::abs(oa.x));
            }
        }
        const std::string injection = std::string(name) == "fig4a" ? "parallel" : "fan";
        r.measurements.push_back({injection + " injection: largest distance from the centreline",
                                  worst, fibre.core_radius_mm, 0.0, "mm", Check::at_most});
        r.measurements.push_back({injection + " injection: track width, last third / first third",
                                  last / first, 1.05, 0.0, "", Check::at_most});
        if (ctx.pictures) {
            imaging::PathStyle style;
            r.figures.push_back({injection + " injection into the bent fibre (density 1.5 on the "
                                             "axis, 1.0 outside the core)",
                                 imaging::draw_paths(scene.medium, result.paths, style)});
        }
    }
    return r;
}

// Returned energy at the probe face over apparent depth c0 t / 2 (mm), in bins.
struct ReturnHistogram {
    double bin_mm = 0.025;
    std::vector<double> energy, energy2;  // sum of w and of w^2 per bin
    double window(double from_mm, double to_mm, bool squares = false) const {
        double sum = 0.0;
        for (std::size_t i = 0; i < energy.size(); ++i) {
            const double d = (double(i) + 0.5) * bin_mm;
            if (d >= from_mm && d < to_mm) sum += squares ? energy2[i] : energy[i];
        }
        return sum;
    }
    // Depth of the first echo in a window: the first bin holding half the window's
    // largest bin or more (a plate's internal multiple, T^2 R against R, can be the
    // stronger by chance), refined by the centroid of it and its neighbours.
    double first_peak(double from_mm, double to_mm) const {
        double strongest = 0.0;
        for (std::size_t i = 0; i < energy.size(); ++i) {
            const double d = (double(i) + 0.5) * bin_mm;
            if (d >= from_mm && d < to_mm) strongest = std::max(strongest, energy[i]);
        }
        std::size_t first = energy.size();
        for (std::size_t i = 0; i < energy.size() && first == energy.size(); ++i) {
            const double d = (double(i) + 0.5) * bin_mm;
            if (d >= from_mm && d < to_mm && strongest > 0.0 && energy[i] >= 0.5 * strongest)
                first = i;
        }
        if (first == energy.size()) return std::nan("");
        double w = 0.0, m = 0.0;
        for (std::size_t i = first > 0 ? first - 1 : 0; i <= first + 1 && i < energy.size(); ++i) {
            w += energy[i], m += energy[i] * (double(i) + 0.5) * bin_mm;
        }
        return m / w;
    }
};

ReturnHistogram returns_at_face(const simulator::TraceResult<2>& result, double max_mm) {
    ReturnHistogram h;
    h.energy.assign(std::size_t(max_mm / h.bin_mm), 0.0);
    h.energy2 = h.energy;
    for (const auto& e : result.echoes) {
        if (e.kind != simulator::EchoKind::returned_to_probe) continue;
        const double depth = 0.5 * kC0 * 1e3 * e.time_s;  // round trip -> apparent depth
        const auto bin = std::size_t(depth / h.bin_mm);
        if (!(depth >= 0.0) || bin >= h.energy.size()) continue;
        const double w = double(e.energy) * e.weight;
        h.energy[bin] += w, h.energy2[bin] += w * w;
    }
    return h;
}

Plot histogram_plot(const ReturnHistogram& h, const std::string& title,
                    const std::vector<double>& expected_mm) {
    Plot p{title,
           "apparent depth c0 t / 2 (mm)",
           "log10 returned energy",
           {{"returned", {}, {}, false}},
           expected_mm};
    for (std::size_t i = 0; i < h.energy.size(); ++i) {
        p.series[0].x.push_back((double(i) + 0.5) * h.bin_mm);
        p.series[0].y.push_back(std::log10(h.energy[i] + 1e-3));
    }
    return p;
}

CaseResult reverberation(const CaseContext&) {
    CaseResult r;
    // (a) A plate over a deep reflector, parallel to an absorbing probe face at y0 = 2 mm;
    // the capture model (particles come back themselves). The plate (c 2750 m/s, rho 1190
    // kg/m^3: R = ((Z2-Z1)/(Z2+Z1))^2 = 0.129 per face against water of 1540 m/s) is 2 mm
    // thick (a plateau of 4 texels between the faces' ramps: two sharp interfaces) and
    // lossy (5 dB/(cm MHz) at 5 MHz: a round trip inside keeps A = 10^(-1) of the
    // energy). 4 mm below it a bone-like half-space (5.7 MRayl, R_h = 0.33, no back face).
    // The deep echo returns through the plate; each round trip across the gap adds one
    // reflection at the half-space and one at the plate from below, whose incoherent
    // reflectance with internal multiples is R_p = R + T^2 R A / (1 - R^2 A). So the
    // reverberations follow the deep echo every `gap` in c0 t / 2, each R_h R_p of the
    // one before (the transmission through the plate on the way up is common to all).
    // Internal multiples arrive 1.1 mm after their packet with weight T^2 A ~ 0.08:
    // inside the +-2 mm windows.
    {
        const double y0 = 2.0, top1 = 10.0, thickness = 2.0, gap = 4.0;
        const double deep = top1 + thickness + gap;
        const double c_plate = 2750.0, rho_plate = 1190.0, alpha_plate = 5.0, f_mhz = 5.0;
        const double z1 = kC0 * 1000.0, z2 = c_plate * rho_plate, z3 = 3000.0 * 1900.0;
        const double R = std::pow((z2 - z1) / (z2 + z1), 2.0), T = 1.0 - R;
        const double A = std::pow(10.0, -alpha_plate * f_mhz * 0.2 * thickness / 10.0);
        const double Rp = R + T * T * R * A / (1.0 - R * R * A);
        const double Rh = std::pow((z3 - z1) / (z3 + z1), 2.0);
        const int nx = 80, ny = 120;  // 20 x 30 mm
        auto plate = simulator::lossless_medium(c_plate, rho_plate);
        plate[Property::attenuation] = float(alpha_plate);
        tissue::PropertyMaps maps =
            simulator::homogeneous(nx, ny, kH, simulator::lossless_medium(kC0, 1000.0));
        for (int j = 0; j < ny; ++j) {
            const double y = j * kH;
            // Linear blends over 2 texels across each face, centred on the face.
            auto ramp = [](double d) { return std::clamp(d / (2 * kH) + 0.5, 0.0, 1.0); };
            const double in_plate = ramp(y - top1) * (1.0 - ramp(y - top1 - thickness));
            auto p = tissue::lerp(simulator::lossless_medium(kC0, 1000.0), plate, float(in_plate));
            p = tissue::lerp(p, simulator::lossless_medium(3000.0, 1900.0), float(ramp(y - deep)));
            for (int i = 0; i < nx; ++i)
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                    maps.fields[f].at(i, j) = p.values[f];
        }
        const auto map = tissue::AcousticMap<2>::build(maps);
        TraceSettings s = simulator::interfaces_only_settings();
        s.physics.set(simulator::Physics::attenuation, true);
        s.frequency_mhz = f_mhz;
        simulator::ProbeFace<2> face;
        face.centre = {10.0f, float(y0)};
        face.normal = {0.0f, 1.0f};
        face.half_width_mm = 9.0f;
        face.reflectivity = 0.0f;
        s.probe_face_2d = face;
        Sources<2> src;
        constexpr int kLines = 16, kPerLine = 10000;
        for (int line = 0; line < kLines; ++line) {
            auto beam = simulator::parallel_beam({10.0f, float(y0) + 0.01f}, {0.0f, 1.0f}, 8.0f,
                                                 kPerLine, uint32_t(line));
            src.insert(src.end(), beam.begin(), beam.end());
        }
        const auto result = simulator::trace(map, src, s);
        const ReturnHistogram h = returns_at_face(result, 40.0);
        // Apparent depth of the deep echo: the plate is crossed faster than c0.
        const double first = deep - y0 - thickness * (1.0 - kC0 / c_plate);
        std::vector<double> expected_mm, peaks, energies, squares;
        for (int k = 0; k < 3; ++k) {
            const double at = first + k * gap;
            expected_mm.push_back(at);
            peaks.push_back(h.first_peak(at - 0.5 * gap, at + 0.5 * gap));
            energies.push_back(h.window(at - 0.5 * gap, at + 0.5 * gap));
            squares.push_back(h.window(at - 0.5 * gap, at + 0.5 * gap, true));
        }
        // The first echo of each window is the direct one; the mean spacing over two round
        // trips. Tolerance 0.1 mm: under one step (0.125 mm), which bounds where the
        // tracer meets each interface; the timing at the interface's middle removes most
        // of that, binning is 0.025 mm.
        r.measurements.push_back({"plate over reflector: mean reverberation spacing",
                                  0.5 * (peaks[2] - peaks[0]), gap, 0.1, "mm"});
        // Monte-Carlo noise of a sum of particle energies w: variance sum w^2; the ratio's
        // relative sigma adds both windows' in quadrature; 4 sigma.
        for (int k = 0; k < 2; ++k) {
            const double ratio = energies[k + 1] / energies[k];
            const double sigma =
                ratio * std::sqrt(squares[k] / (energies[k] * energies[k]) +
                                  squares[k + 1] / (energies[k + 1] * energies[k + 1]));
            r.measurements.push_back({"plate over reflector: energy of reverberation " +
                                          std::to_string(k + 1) + " / " + std::to_string(k),
                                      ratio, Rh * Rp, 4.0 * sigma, ""});
        }
        r.plots.push_back(histogram_plot(
            h, "plate 4 mm above a reflector: returns (dashed: deep echo + k gap)", expected_mm));
    }
    // (b) A reflector parallel to a reflecting face: water over bone-like 5.7 MRayl at
    // depth d below the face (r_f = 0.4). Returns at d, 2d, ... with energies
    // E1 = R^2 (1 - r_f), E2 = E1 r_f R^2.
    {
        constexpr double kY0 = 2.0, kDepth = 12.0, kFace = 0.4;
        const auto map = tissue::AcousticMap<2>::build(simulator::planar_interface(
            160, 160, kH, {20.0, kDepth}, {0.0, 1.0}, simulator::lossless_medium(kC0, 1000),
            simulator::lossless_medium(3000, 1900), 2.0));
        const double z1 = 1.54, z2 = 5.7, R2 = std::pow((z2 - z1) / (z2 + z1), 2.0);
        TraceSettings s = simulator::interfaces_only_settings();
        simulator::ProbeFace<2> face;
        face.centre = {20.0f, float(kY0)};
        face.normal = {0.0f, 1.0f};
        face.half_width_mm = 15.0f;
        face.reflectivity = float(kFace);
        s.probe_face_2d = face;
        Sources<2> src;
        for (int line = 0; line < 8; ++line) {
            auto beam = simulator::parallel_beam({20.0f, float(kY0) + 0.01f}, {0.0f, 1.0f}, 10.0f,
                                                 2500, uint32_t(line));
            src.insert(src.end(), beam.begin(), beam.end());
        }
        const auto result = simulator::trace(map, src, s);
        const ReturnHistogram h = returns_at_face(result, 45.0);
        const double d = kDepth - kY0;
        const double p1 = h.first_peak(0.5 * d, 1.5 * d), p2 = h.first_peak(1.5 * d, 2.5 * d);
        const double e1 = h.window(0.5 * d, 1.5 * d), e2 = h.window(1.5 * d, 2.5 * d);
        // Positions within 0.1 mm, as for the plate.
        r.measurements.push_back({"face: depth of the first echo", p1, d, 0.1, "mm"});
        r.measurements.push_back({"face: spacing of the reverberation", p2 - p1, d, 0.1, "mm"});
        // e2 / e1 = r_f R^2: the reflections at the plate are binomial with p = R^2 over the
        // n1 = e1 / (1 - r_f) particles that came back once; 4 sigma.
        const double n1 = e1 / (1.0 - kFace);
        const double sigma = kFace * std::sqrt(R2 * (1.0 - R2) / n1);
        r.measurements.push_back(
            {"face: second / first return energy", e2 / e1, kFace * R2, 4.0 * sigma, ""});
        r.plots.push_back(histogram_plot(
            h, "reflector 10 mm below a 40 % face: returns at d, 2d, 3d", {d, 2 * d, 3 * d}));
    }
    return r;
}

CaseResult sedimentation(const CaseContext& ctx) {
    // Figure 5: Colin27 in paper mode, a parallel beam from the upper right. Particles
    // inside a denser feature meet its far ("lower") side at growing angles and are
    // totally reflected back into it, so energy gathers at the lower interfaces. Measured:
    // mean fluence on texels where the density falls along the beam (lower interfaces)
    // over the mean where it rises (upper interfaces), weighted by |grad d . beam|.
    // The paper reports accumulation at the lower interfaces: the ratio must exceed 1.
    simulator::TraceSetup scene = simulator::make_paper_setup("fig5", 40000);
    scene.settings.record_paths = 0;
    const auto result = simulator::trace(scene.map, scene.sources, scene.settings);
    const tissue::Volume& d = scene.medium;
    const glm::ivec3 n = d.geometry().dims;
    const glm::dvec2 beam = glm::normalize(glm::dvec2(-1.0, 1.0));
    double lower = 0.0, lower_w = 0.0, upper = 0.0, upper_w = 0.0;
    for (int j = 2; j + 2 < n.y; ++j) {
        for (int i = 2; i + 2 < n.x; ++i) {
            const glm::dvec2 g(0.5 * (d.at(i + 1, j) - d.at(i - 1, j)),
                               0.5 * (d.at(i, j + 1) - d.at(i, j - 1)));
            const double along = glm::dot(g, beam);
            if (std::abs(along) < 0.01) continue;  // not an interface
            const double f = result.fluence.at(i, j);
            if (along < 0.0)
                lower += -along * f, lower_w += -along;
            else
                upper += along * f, upper_w += along;
        }
    }
    CaseResult r;
    r.measurements.push_back({"fluence at lower interfaces / at upper interfaces",
                              (lower / lower_w) / (upper / upper_w), 1.0, 0.0, "",
                              Check::at_least});
    if (ctx.pictures) {
        imaging::FieldStyle style;
        style.title = "fluence (paper mode, beam towards the lower left)";
        style.colormap = imaging::Colormap::inferno;
        style.log_scale = true;
        r.figures.push_back(
            {"intensity profile of figure 5: accumulations at the lower sides "
             "of features",
             imaging::render_field(result.fluence, style)});
    }
    return r;
}

}  // namespace

void add_tracer_cases(std::vector<Case>& out) {
    out.push_back({"refraction_angle", "refraction angle follows Snell's law",
                   "A particle crosses a smoothed interface tilted 20 degrees to the grid (c 1500 "
                   "-> 1800 m/s) at 14 incidences; its final direction must match asin(sin(i) "
                   "c2/c1) within 0.5 degrees (the interface normal comes from a patch fit of a "
                   "2-texel ramp; directions are read over 1 mm of path).",
                   refraction_angle});
    out.push_back({"critical_angle", "total reflection beyond the critical angle",
                   "Slow to fast (1500 -> 1800 m/s): incidences in 0.1 degree steps around "
                   "asin(c1/c2) = 56.44 degrees; the last transmitted and the first totally "
                   "reflected must both lie within 0.5 degrees of it, and beyond it the "
                   "reflection angle must equal the incidence within 0.5 degrees.",
                   critical_angle});
    out.push_back({"reflected_fraction", "reflected energy fraction against the angle",
                   "Z 1.5 -> 4.5 MRayl: for 11 incidences, 4000 particles each decide between "
                   "reflection and transmission with the oblique-incidence intensity "
                   "coefficient; the reflected fraction is binomial and must lie within 3 "
                   "standard deviations (99.7 %) of R^2.",
                   reflected_fraction});
    out.push_back({"fibre_guide", "fibre guide confinement and track width (figure 4)",
                   "The bent fibre of the particle paper with parallel and fan injection: no "
                   "particle may leave the 5 mm core, and the track's width in the last third "
                   "may exceed the first third's by at most 5 %.",
                   fibre_guide});
    out.push_back({"reverberation", "reverberation spacing and decay",
                   "Capture model. (a) A lossy 2 mm plate 4 mm above a bone-like reflector: "
                   "reverberations follow the deep echo every 4 mm (the gap), each R_h R_p of the "
                   "one before (R_p: the plate's reflectance with its internal multiples). (b) A "
                   "reflector 10 mm below a face reflecting 40 %: "
                   "returns at 10 and 20 mm, the second r_f R^2 of the first. Tolerances: 0.1 mm "
                   "for positions, 4 sigma of the counting noise for ratios.",
                   reverberation});
    out.push_back({"sedimentation", "sedimentation at lower interfaces (figure 5)",
                   "Paper mode on the Colin27 slice of figure 5, parallel beam towards the lower "
                   "left: the mean fluence at interfaces where the density falls along the beam "
                   "(the features' lower sides) over that where it rises must exceed 1, the "
                   "accumulation the paper calls sedimentation.",
                   sedimentation});
}

}  // namespace sonotrace::validation
