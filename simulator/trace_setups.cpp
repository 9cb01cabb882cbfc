#include "simulator/trace_setups.h"

#include <cmath>
#include <numbers>

#include "tissue/base/error.h"
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

TraceSettings paper_settings() {
    TraceSettings s;
    s.mode = PhysicsMode::paper;
    s.physics.set(Physics::attenuation, false);
    s.physics.set(Physics::scattering, false);
    s.physics.set(Physics::diffuse, false);
    s.lobe_exponent = LobeExponent::reflecting_density;
    s.roulette_energy = 0.0;
    return s;
}

TraceSetup from_density(std::string name, std::string description, tissue::Volume density) {
    TraceSetup setup;
    setup.name = std::move(name);
    setup.description = std::move(description);
    setup.map = tissue::AcousticMap<2>::build_paper(density);
    setup.medium = std::move(density);
    setup.medium_label = "density d";
    setup.medium_unit = "";
    setup.settings = paper_settings();
    return setup;
}

TraceSetup figure5(int particles) {
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
    TraceSetup setup = from_density(
        "fig5", "Colin27 axial slice, parallel injection from the upper right", std::move(d));
    // A parallel beam towards the lower left, entering through the top and right edges.
    const glm::vec2 size = setup.map.extent_mm();
    const glm::vec2 dir = glm::normalize(glm::vec2(-1.0f, 1.0f)), across(-dir.y, dir.x);
    const glm::vec2 centre = 0.5f * size;
    const float half_span = 0.5f * glm::length(size);
    constexpr int kLines = 16;
    for (int n = 0; n < particles; ++n) {
        const float u = (float(n) + 0.5f) / float(particles) * 2.0f - 1.0f;
        glm::vec2 p = centre + across * (u * half_span);
        // Back up against the beam direction to the map boundary.
        while (setup.map.inside(p - dir * 0.5f)) p -= dir * 0.5f;
        if (!setup.map.inside(p)) continue;
        setup.sources.push_back({p, dir, 1.0f, uint32_t(n * kLines / particles)});
    }
    setup.settings.record_paths = std::max(1, particles / kLines / 40);
    return setup;
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

TraceSetup make_paper_setup(const std::string& name, int particles) {
    if (particles < 1 || particles > 10000000) {
        throw base::InputError("--particles", "", "must be between 1 and 10000000");
    }
    if (name == "fig5") return figure5(particles);
    throw base::InputError("--config", "",
                           "unknown configuration '" + name +
                               "' (known: fig2, fig4a, fig4b, fig6 from the phantom catalogue, "
                               "fig5)");
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

tissue::AcousticProperties lossless_medium(double speed, double density) {
    tissue::AcousticProperties p;
    p[tissue::Property::speed_of_sound] = float(speed);
    p[tissue::Property::density] = float(density);
    return p;
}

TraceSettings interfaces_only_settings() {
    TraceSettings s;
    s.physics.set(Physics::attenuation, false);
    s.physics.set(Physics::scattering, false);
    s.physics.set(Physics::diffuse, false);
    s.roulette_energy = 0.0;
    return s;
}

tissue::PropertyMaps homogeneous(int nx, int ny, double h, const tissue::AcousticProperties& p) {
    tissue::PropertyMaps maps;
    for (std::size_t f = 0; f < tissue::kPropertyCount; ++f) {
        maps.fields[f] = tissue::Volume(grid(nx, ny, h), p.values[f]);
    }
    return maps;
}

}  // namespace sonotrace::simulator
