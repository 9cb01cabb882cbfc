#include "phantoms/trace_setup.h"

#include <iostream>

#include "simulator/sources.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"

namespace sonotrace::phantoms {

namespace {

namespace jsonio = base::jsonio;
using nlohmann::json;

// The "trace" entry over the mode's defaults (paper: the paper's integrator alone, no
// absorption, scattering, diffuse lobes or roulette).
simulator::TraceSettings trace_settings(const Phantom& ph) {
    simulator::TraceSettings s;
    if (ph.paper_mode) {
        s.mode = simulator::PhysicsMode::paper;
        for (simulator::Physics p : {simulator::Physics::attenuation,
                                     simulator::Physics::scattering, simulator::Physics::diffuse})
            s.physics.set(p, false);
        s.lobe_exponent = simulator::LobeExponent::reflecting_density;
        s.roulette_energy = 0.0;
    }
    const std::string& src = ph.source;
    const json& t = ph.trace;
    // The tracer's physics switches by their record keys (simulator/physics_switches.h),
    // and the old name of attenuation.
    std::vector<std::string_view> known = {
        "absorption", "lobe_exponent", "lobe_weight", "lobe_scale", "roulette_energy",
        "step",       "frequency",     "ring",        "comment"};
    for (const simulator::PhysicsSwitch& sw : simulator::kPhysicsSwitches)
        if (!sw.image_only) known.push_back(sw.record_key);
    jsonio::require_known_keys(t, known, src, "trace");
    auto flag = [&](std::string_view key, simulator::Physics p) {
        if (!t.contains(key)) return;
        if (!t.at(key).is_boolean())
            throw base::InputError(src, "trace." + std::string(key), "must be true or false");
        s.physics.set(p, t.at(key).get<bool>());
    };
    for (const simulator::PhysicsSwitch& sw : simulator::kPhysicsSwitches)
        if (!sw.image_only) flag(sw.record_key, sw.id);
    if (t.contains("absorption")) {  // its name before the switches' names were one
        std::cerr << "sonotrace: warning: " << src
                  << ": trace.absorption is now called trace.attenuation (the old name goes in "
                     "the next release)\n";
        flag("absorption", simulator::Physics::attenuation);
    }
    if (t.contains("lobe_exponent")) {
        const std::string v = jsonio::get_string(t, "lobe_exponent", src, "trace");
        if (v == "roughness")
            s.lobe_exponent = simulator::LobeExponent::roughness;
        else if (v == "reflecting_density")
            s.lobe_exponent = simulator::LobeExponent::reflecting_density;
        else if (v == "density_ratio")
            s.lobe_exponent = simulator::LobeExponent::density_ratio;
        else
            throw base::InputError(src, "trace.lobe_exponent",
                                   "must be roughness, reflecting_density or density_ratio");
    }
    if (t.contains("lobe_weight")) {
        const std::string v = jsonio::get_string(t, "lobe_weight", src, "trace");
        if (v != "probability" && v != "energy")
            throw base::InputError(src, "trace.lobe_weight", "must be probability or energy");
        s.lobe_weight =
            v == "energy" ? simulator::LobeWeight::energy : simulator::LobeWeight::probability;
    }
    if (auto v = jsonio::get_optional_number(t, "lobe_scale", src, "trace", 1e-6, 1e6))
        s.lobe_scale = *v;
    if (auto v = jsonio::get_optional_number(t, "roulette_energy", src, "trace", 0.0, 1.0))
        s.roulette_energy = *v;
    if (auto v = jsonio::get_optional_number(t, "step", src, "trace", 0.01, 4.0))
        s.step_texels = *v;
    if (auto v = jsonio::get_optional_number(t, "frequency", src, "trace", 0.1, 100.0))
        s.frequency_mhz = *v;
    if (t.contains("ring")) {
        const json& r = t.at("ring");
        jsonio::require_object(r, src, "trace.ring");
        jsonio::require_known_keys(r, {"centre", "radius", "bins"}, src, "trace.ring");
        const glm::dvec3 c = jsonio::get_vec3(r, "centre", src, "trace.ring");
        simulator::RingDetector ring;
        ring.centre = {float(c.x), float(c.y)};
        ring.radius_mm = float(jsonio::get_number(r, "radius", src, "trace.ring", 1e-3, 1e4));
        ring.bins = int(jsonio::get_number(r, "bins", src, "trace.ring", 1.0, 100000.0));
        s.ring = ring;
    }
    s.validate(src);
    return s;
}

}  // namespace

simulator::TraceSetup trace_setup(const Phantom& ph, int particles) {
    if (!ph.injection)
        throw base::InputError(ph.source, "source",
                               "is required to trace a phantom (where the particles start)");
    simulator::TraceSetup setup;
    setup.name = ph.name;
    setup.description = ph.description;
    setup.settings = trace_settings(ph);
    const tissue::VolumeGeometry grid = plane_grid_2d(ph);
    if (ph.paper_mode) {
        setup.medium = rasterise_paper_density(ph, grid);
        setup.map = tissue::AcousticMap<2>::build_paper(setup.medium);
        setup.medium_label = "density d";
    } else {
        tissue::PropertyMaps maps = rasterise(ph, grid);
        setup.map = tissue::AcousticMap<2>::build(maps);
        setup.medium = maps[tissue::Property::speed_of_sound];
        setup.medium_label = "speed of sound";
        setup.medium_unit = "m/s";
    }
    const ParticleSource& src = *ph.injection;
    const int n = particles > 0 ? particles : src.particles;
    const glm::vec2 at(src.at), dir(src.direction);
    setup.sources = src.type == ParticleSource::Type::fan
                        ? simulator::fan_beam(at, dir, float(src.half_angle_deg), n)
                        : simulator::parallel_beam(at, dir, float(src.width_mm), n);
    // Consecutive particles form 16 "lines" so the trace spreads over the threads.
    const std::size_t count = setup.sources.size();
    for (std::size_t p = 0; p < count; ++p) setup.sources[p].line = uint32_t(p * 16 / count);
    setup.settings.record_paths = (n + 15) / 16;  // every path: a figure draws them all
    return setup;
}

}  // namespace sonotrace::phantoms
