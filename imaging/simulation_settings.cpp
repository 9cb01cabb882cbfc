// SimulationSettings' names, quality levels, physics switches and validation
// (declared in imaging/simulation.h).
#include "imaging/simulation.h"

#include <iostream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "tissue/base/error.h"
#include "tissue/base/memory.h"

namespace sonotrace::imaging {

std::string to_string(ReceiveModel model) {
    return model == ReceiveModel::monostatic ? "monostatic" : "capture";
}

const std::vector<QualityName>& quality_names() {
    static const std::vector<QualityName> names = {{"interactive", Quality::interactive},
                                                   {"standard", Quality::standard},
                                                   {"high", Quality::high}};
    return names;
}

std::string to_string(Quality quality) {
    for (const QualityName& q : quality_names())
        if (q.quality == quality) return std::string(q.name);
    return "?";
}

Quality parse_quality(const std::string& name, const std::string& source,
                      const std::string& field) {
    std::string known;
    for (const QualityName& q : quality_names()) {
        if (q.name == name) return q.quality;
        known += (known.empty() ? "" : ", ") + std::string(q.name);
    }
    throw base::InputError(source, field, "unknown quality '" + name + "' (known: " + known + ")");
}

QualityLevel quality_level(Quality quality) {
    // Interactive and standard step a whole texel: interfaces are found and crossed
    // whatever the step (their plateaus, one decision each), rays bend in an index
    // smoothed over the Fresnel zone (millimetres: a dozen steps), and the echo profile
    // is smoothed over a pulse; half a texel changes the default frame's brain by under
    // 0.1 dB, or 0.4 dB traced in the slab (HeadContrast/StandardStep), at twice the
    // trace's cost. High
    // keeps half a texel of its finer map. Interactive's speckle sub-lines lie 1.5 beam
    // sigmas apart (a third fewer). Interactive channel frames draw 3 scatterers a
    // resolution cell, not 10: speckle not quite developed (SNR about 1.8) at a third of
    // the cost.
    switch (quality) {
        case Quality::interactive:
            return {0.5, 8, 1.0, 1.5, 3.0};
        case Quality::standard:
            return {0.25, 32, 1.0, 1.0, 10.0};
        case Quality::high:
            return {0.125, 128, 0.5, 1.0, 10.0};
    }
    return {0.25, 32, 1.0, 1.0, 10.0};
}

const simulator::PhysicsSwitch& physics_switch(std::string_view name) {
    for (const auto& n : simulator::kPhysicsSwitches)
        if (n.name == name) return n;
    throw std::logic_error("no physics switch " + std::string(name));
}

std::string physics_switch_help() {
    std::string help;
    for (const auto& n : simulator::kPhysicsSwitches)
        help +=
            (help.empty() ? "" : "; ") + std::string(n.name) + ": " + std::string(n.description);
    return help;
}

std::string disabled_names(const PhysicsSwitches& physics) {
    std::string names;
    for (const auto& n : simulator::kPhysicsSwitches)
        if (!physics.on(n.id)) {
            if (!names.empty()) names += ',';
            names += n.name;
        }
    return names;
}

PhysicsSwitches disabled_physics(const std::string& list, const std::string& source,
                                 const std::string& field) {
    PhysicsSwitches out;
    std::size_t start = 0;
    while (start <= list.size() && !list.empty()) {
        const std::size_t comma = std::min(list.find(',', start), list.size());
        std::string name = list.substr(start, comma - start);
        // Names a switch had before the names were one (accepted for one release).
        static const std::pair<std::string_view, std::string_view> kOldNames[] = {
            {"absorption", "attenuation"}};
        for (const auto& [old_name, now] : kOldNames) {
            if (name != old_name) continue;
            std::cerr << "sonotrace: warning: " << source << (field.empty() ? "" : ": " + field)
                      << ": physics '" << old_name << "' is now called '" << now
                      << "' (the old name goes in the next release)\n";
            name = std::string(now);
        }
        const auto& names = simulator::kPhysicsSwitches;
        const auto found =
            std::find_if(names.begin(), names.end(),
                         [&](const simulator::PhysicsSwitch& n) { return n.name == name; });
        if (found == names.end()) {
            std::string known;
            for (const auto& n : names) known += (known.empty() ? "" : ", ") + std::string(n.name);
            throw base::InputError(source, field,
                                   "unknown physics '" + name + "' (known: " + known + ")");
        }
        out.set(found->id, false);
        start = comma + 1;
    }
    return out;
}

void switch_off(const PhysicsSwitches& physics, simulator::TraceSettings& t) {
    t.physics &= physics;
}

void apply(const PhysicsSwitches& physics, SimulationSettings& s) {
    // The tracer's switches are these (its defaults are every one on); the transducer's
    // face reflects nothing with face reflection off, as the sidecar then says.
    s.trace.physics = physics;
    if (!physics.on(Physics::face)) s.transducer.face_reflectivity = 0.0;
    s.imaging.speckle = physics.on(Physics::speckle);
}

void SimulationSettings::validate(const std::string& source) const {
    transducer.validate(source);
    trace.validate(source);
    auto in_range = [&](double v, double lo, double hi, const char* field) {
        base::require_in_range(source, field, v, lo, hi);
    };
    auto within = [&](double v, ValueRange r, const char* field) {
        in_range(v, r.low, r.high, field);
    };
    within(step_texels, kStepTexelsRange, "step");
    if (trace_dimensions != 2 && trace_dimensions != 3)
        throw base::InputError(source, "trace", "must be 2d or 3d");
    if (refraction_smoothing_mm)
        within(*refraction_smoothing_mm, kRefractionSmoothingRange, "refraction-smoothing");
    in_range(imaging.sampling_mhz, 0.0, 1000.0, "sampling");
    if (imaging.sampling_mhz > 0.0 &&
        imaging.sampling_mhz <
            2.0 * transducer.frequency_mhz * (1.0 + 0.5 * transducer.bandwidth)) {
        throw base::InputError(source, "sampling",
                               "is below the Nyquist rate of the pulse (2 x (1 + B/2) x f0 = " +
                                   std::to_string(2.0 * transducer.frequency_mhz *
                                                  (1.0 + 0.5 * transducer.bandwidth)) +
                                   " MHz)");
    }
    in_range(imaging.speckle_cell_mm, 0.0, 10.0, "speckle-cell");
    in_range(imaging.profile_smoothing, 0.0, 10.0, "profile-smoothing");
    within(imaging.gain_db, kGainRange, "gain");
    within(imaging.dynamic_range_db, kDynamicRangeRange, "dynamic-range");
    within(imaging.pixel_mm, kPixelRange, "pixel");
    if (imaging.noise_snr_db) within(*imaging.noise_snr_db, kNoiseSnrRange, "noise-snr");
    if (transmit) {
        probe::validate_transmit_scheme(*transmit, transducer, source, "transmit");
        if (trace_dimensions != 2)
            throw base::InputError(source, "transmit",
                                   "unfocused transmits are traced in 2D (--trace 2d)");
        if (receive != ReceiveModel::monostatic)
            throw base::InputError(source, "transmit",
                                   "unfocused transmits receive on every element: --receive "
                                   "monostatic");
        ChannelSettings c;
        c.sampling_mhz = imaging.sampling_mhz;
        // The channels and, while they are beamformed, one transmit's analytic signals.
        const ChannelData layout = channel_layout(transducer, *transmit, c);
        base::check_allocation(channel_bytes(layout) * (1.0 + 2.0 / layout.transmits), source,
                               "transmit");
    }
    double previous = -1e300;
    for (const TgcPoint& p : imaging.tgc) {
        in_range(p.depth_mm, 0.0, 1000.0, "tgc.depth");
        in_range(p.gain_db, -200.0, 200.0, "tgc.gain");
        if (p.depth_mm <= previous)
            throw base::InputError(source, "tgc", "depths must increase along the curve");
        previous = p.depth_mm;
    }
}

}  // namespace sonotrace::imaging
