#include "simulator/scenes.h"

#include <cmath>
#include <numbers>

#include "tissue/error.h"
#include "tissue/resample.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"

namespace sonotrace::simulator {

namespace {

constexpr double kPi = std::numbers::pi;

tissue::VolumeGeometry grid(int nx, int ny, double h) {
    tissue::VolumeGeometry g;
    g.dims = {nx, ny, 1};
    g.spacing = {h, h, h};
    return g;
}

// Linear ramp 0 -> 1 across a transition of `width` (mm) centred on signed distance 0.
double ramp(double signed_distance, double width) {
    if (width <= 0.0) return signed_distance >= 0.0 ? 1.0 : 0.0;
    return std::clamp(signed_distance / width + 0.5, 0.0, 1.0);
}

// Smooth value noise in [-1, 1] with cells of `cell` mm (deterministic hash).
double value_noise(double x, double y, double cell) {
    auto hash = [](int i, int j) {
        uint32_t h = uint32_t(i) * 0x8da6b343u ^ uint32_t(j) * 0xd8163841u;
        h ^= h >> 13, h *= 0x5bd1e995u, h ^= h >> 15;
        return double(h & 0xffffff) / double(0xffffff) * 2.0 - 1.0;
    };
    const double fx = x / cell, fy = y / cell;
    const int i = int(std::floor(fx)), j = int(std::floor(fy));
    auto smooth = [](double t) { return t * t * (3 - 2 * t); };
    const double tx = smooth(fx - i), ty = smooth(fy - j);
    const double a = hash(i, j) * (1 - tx) + hash(i + 1, j) * tx;
    const double b = hash(i, j + 1) * (1 - tx) + hash(i + 1, j + 1) * tx;
    return a * (1 - ty) + b * ty;
}

TraceSettings paper_settings() {
    TraceSettings s;
    s.mode = PhysicsMode::paper;
    s.absorption = false;
    s.scattering = false;
    s.diffuse_reflection = false;
    s.lobe_exponent = LobeExponent::reflecting_density;
    s.roulette_energy = 0.0;
    return s;
}

Scene2D from_density(std::string name, std::string description, tissue::Volume density) {
    Scene2D scene;
    scene.name = std::move(name);
    scene.description = std::move(description);
    scene.map = tissue::AcousticMap<2>::build_paper(density);
    scene.medium = std::move(density);
    scene.medium_label = "density d";
    scene.medium_unit = "";
    scene.settings = paper_settings();
    return scene;
}

Scene2D figure2(int particles) {
    // Two interfaces: a vertical one at x = 30 mm (d 1.0 -> 1.6, refraction towards the
    // normal) and one tilted by 35 degrees (d 1.6 -> 1.0): particles meeting it beyond
    // the critical angle asin(1/1.6) = 38.7 degrees are totally reflected.
    const double h = 0.25;
    tissue::Volume d(grid(400, 300, h));
    const glm::dvec2 tilt_point(65.0, 37.5),
        tilt_normal(std::cos(kPi * 35 / 180), std::sin(kPi * 35 / 180));
    for (int j = 0; j < 300; ++j) {
        for (int i = 0; i < 400; ++i) {
            const glm::dvec2 p(i * h, j * h);
            const double in_b = ramp(p.x - 30.0, 1.5 * h) *
                                (1.0 - ramp(glm::dot(p - tilt_point, tilt_normal), 1.5 * h));
            d.at(i, j) = float(1.0 + 0.6 * in_b);
        }
    }
    Scene2D scene = from_density(
        "fig2",
        "two interfaces, fan injection: refraction, then total reflection of the outer particles",
        std::move(d));
    scene.sources = fan_beam({5.0f, 37.5f}, {1.0f, 0.0f}, 30.0f, particles);
    scene.settings.specular_reflection =
        false;  // refraction and total reflection only, as in the figure
    scene.settings.record_paths = particles;
    return scene;
}

Scene2D figure4(bool fan, int particles) {
    const double h = 0.25;
    const FibreGeometry fibre;
    const int n = int((fibre.bend_centre.x + fibre.exit_mm) / h) + 1;
    tissue::Volume d(grid(n, n, h));
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const double rho = fibre.offset_and_arc({i * h, j * h}).x / fibre.core_radius_mm;
            d.at(i, j) =
                float(fibre.cladding_density + (fibre.core_density - fibre.cladding_density) *
                                                   std::max(0.0, 1.0 - rho * rho));
        }
    }
    Scene2D scene = from_density(
        fan ? "fig4b" : "fig4a",
        std::string("bent fibre guide with a parabolic (circular cross-section) density, ") +
            (fan ? "fan" : "parallel") + " injection at the lower left end",
        std::move(d));
    const glm::vec2 start(float(fibre.start.x), float(fibre.start.y - 1.0));
    scene.sources =
        fan ? fan_beam(start, {0.0f, -1.0f}, 12.0f, particles)
            : parallel_beam(start, {0.0f, -1.0f}, float(1.6 * fibre.core_radius_mm), particles);
    scene.settings.specular_reflection = false;
    scene.settings.record_paths = particles;
    return scene;
}

Scene2D figure5(int particles) {
    // An axial Colin27 slice through the lateral ventricles (anterior at the top), with a
    // transfer function chosen, as in the paper, for visible effects rather than real
    // acoustics: d = 1 + 0.5 * intensity / (99th percentile).
    const tissue::LoadedVolume head =
        tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt});
    const double q99 = head.volume.quantile(0.99);
    const tissue::ProbeFrame frame{{0.0, 110.0, 18.0}, {1.0, 0.0, 0.0}, {0.0, -1.0, 0.0}};
    const auto g = tissue::probe_grid(frame, {180.0, 220.0, 0.0, 0.5}, "fig5");
    tissue::Volume d = tissue::resample(head.volume, g, tissue::Interpolation::trilinear, 0.0f);
    for (float& v : d.voxels()) v = float(1.0 + 0.5 * std::clamp(double(v) / q99, 0.0, 1.2));
    Scene2D scene = from_density(
        "fig5", "Colin27 axial slice, parallel injection from the upper right", std::move(d));
    // A parallel beam towards the lower left, entering through the top and right edges.
    const glm::vec2 size = scene.map.extent_mm();
    const glm::vec2 dir = glm::normalize(glm::vec2(-1.0f, 1.0f)), across(-dir.y, dir.x);
    const glm::vec2 centre = 0.5f * size;
    const float half_span = 0.5f * glm::length(size);
    constexpr int kLines = 16;
    for (int n = 0; n < particles; ++n) {
        const float u = (float(n) + 0.5f) / float(particles) * 2.0f - 1.0f;
        glm::vec2 p = centre + across * (u * half_span);
        // Back up against the beam direction to the map boundary.
        while (scene.map.inside(p - dir * 0.5f)) p -= dir * 0.5f;
        if (!scene.map.inside(p)) continue;
        scene.sources.push_back({p, dir, 1.0f, uint32_t(n * kLines / particles)});
    }
    scene.settings.record_paths = std::max(1, particles / kLines / 40);
    return scene;
}

Scene2D figure6(int particles) {
    // A homogeneous reflector (d = 3, 2 mm) on inhomogeneous matter (d = 2 +- 0.6 smooth
    // noise), under a homogeneous half-space d = 1. A 4 mm parallel beam meets it at 45
    // degrees at (50, 30) mm: eq. 10 gives R^2 = 0.14 there (a d = 1.5 reflector would
    // give 0.009, too weak for the figure's bright specular lobe). Paths are coloured by
    // energy, so the lobe weight is the paper's lossy interpretation. The ring detector
    // (radius 15 mm) records the intensity profile over the upper semicircle.
    const double h = 0.25, interface_y = 30.0;
    tissue::Volume d(grid(400, 300, h));
    for (int j = 0; j < 300; ++j) {
        for (int i = 0; i < 400; ++i) {
            const double x = i * h, y = j * h;
            const double below = ramp(y - interface_y, 1.5 * h);
            const double matter = ramp(y - interface_y - 2.0, 1.5 * h);
            const double value = 3.0 + matter * (-1.0 + 0.6 * value_noise(x, y, 1.5));
            d.at(i, j) = float(1.0 + below * (value - 1.0));
        }
    }
    Scene2D scene =
        from_density("fig6", "45-degree beam on a homogeneous reflector over inhomogeneous matter",
                     std::move(d));
    const glm::vec2 hit(50.0f, float(interface_y)), dir = glm::normalize(glm::vec2(1.0f, 1.0f));
    scene.sources = parallel_beam(hit - dir * 25.0f, dir, 4.0f, particles);
    scene.settings.diffuse_reflection = true;
    scene.settings.lobe_exponent = LobeExponent::reflecting_density;
    scene.settings.lobe_scale = 5.0;  // c = 5 * d1 = 15 at the reflector
    scene.settings.lobe_weight = LobeWeight::energy;
    scene.settings.roulette_energy = 1e-3;
    scene.settings.record_paths = particles;
    scene.settings.ring = RingDetector{hit, 15.0f, 90};
    return scene;
}

}  // namespace

glm::dvec2 FibreGeometry::offset_and_arc(glm::dvec2 p) const {
    const double bend_len = bend_radius_mm * kPi / 2.0;
    // Candidate 1: the straight entry, running up from `start`.
    const double s1 = std::clamp(start.y - p.y, 0.0, straight_mm);
    const glm::dvec2 c1(start.x, start.y - s1);
    // Candidate 2: the quarter circle about bend_centre, from angle 0 (pointing -x) to pi/2 (-y).
    const glm::dvec2 v = p - bend_centre;
    const double theta = std::clamp(std::atan2(-v.y, -v.x), 0.0, kPi / 2.0);
    const glm::dvec2 c2 =
        bend_centre + bend_radius_mm * glm::dvec2(-std::cos(theta), -std::sin(theta));
    // Candidate 3: the straight exit towards +x.
    const glm::dvec2 exit_start = bend_centre + glm::dvec2(0.0, -bend_radius_mm);
    const double s3 = std::max(0.0, p.x - exit_start.x);
    const glm::dvec2 c3(exit_start.x + s3, exit_start.y);
    const double d1 = glm::length(p - c1), d2 = glm::length(p - c2), d3 = glm::length(p - c3);
    // Sign: positive away from the bend centre.
    auto signed_distance = [&](const glm::dvec2& c, double d) {
        return glm::length(p - bend_centre) >= glm::length(c - bend_centre) ? d : -d;
    };
    if (d1 <= d2 && d1 <= d3) return {signed_distance(c1, d1), s1};
    if (d2 <= d3) return {signed_distance(c2, d2), straight_mm + bend_radius_mm * theta};
    return {signed_distance(c3, d3), straight_mm + bend_len + s3};
}

double FibreGeometry::length_mm() const {
    return straight_mm + bend_radius_mm * kPi / 2.0 + exit_mm;
}

std::vector<std::string> paper_scene_names() {
    return {"fig2", "fig4a", "fig4b", "fig5", "fig6"};
}

Scene2D make_paper_scene(const std::string& name, int particles) {
    if (particles < 1 || particles > 10000000) {
        throw tissue::InputError("--particles", "", "must be between 1 and 10000000");
    }
    // Consecutive particles form 16 "lines" so the trace spreads over the threads.
    auto split = [](Scene2D scene) {
        if (scene.name == "fig5") return scene;  // already split
        const std::size_t n = scene.sources.size();
        for (std::size_t p = 0; p < n; ++p) scene.sources[p].line = uint32_t(p * 16 / n);
        return scene;
    };
    if (name == "fig2") return split(figure2(particles));
    if (name == "fig4a") return split(figure4(false, particles));
    if (name == "fig4b") return split(figure4(true, particles));
    if (name == "fig5") return figure5(particles);
    if (name == "fig6") return split(figure6(particles));
    std::string known;
    for (const auto& n : paper_scene_names()) known += (known.empty() ? "" : ", ") + n;
    throw tissue::InputError("--config", "",
                             "unknown configuration '" + name + "' (known: " + known + ")");
}

tissue::PropertyMaps planar_interface(int nx, int ny, double h, glm::dvec2 point, glm::dvec2 normal,
                                      const tissue::AcousticProperties& a,
                                      const tissue::AcousticProperties& b,
                                      double smoothing_texels) {
    tissue::PropertyMaps maps;
    for (tissue::Volume& f : maps.fields) f = tissue::Volume(grid(nx, ny, h));
    normal = glm::normalize(normal);
    for (int j = 0; j < ny; ++j) {
        for (int i = 0; i < nx; ++i) {
            const double t =
                ramp(glm::dot(glm::dvec2(i * h, j * h) - point, normal), smoothing_texels * h);
            const tissue::AcousticProperties p = tissue::lerp(a, b, float(t));
            for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                maps.fields[f].at(i, j) = p.values[f];
        }
    }
    return maps;
}

tissue::PropertyMaps homogeneous(int nx, int ny, double h, const tissue::AcousticProperties& p) {
    tissue::PropertyMaps maps;
    for (std::size_t f = 0; f < tissue::kPropertyCount; ++f) {
        maps.fields[f] = tissue::Volume(grid(nx, ny, h), p.values[f]);
    }
    return maps;
}

}  // namespace sonotrace::simulator
