#pragma once
// What every line of a trace shares (simulator/tracer.cpp, private to it): the settings
// turned into the step's units and switches once per trace, before the lines run, and the
// view of the map the lanes sample.
#include <cmath>
#include <limits>

#include "simulator/batch.h"
#include "simulator/deposit_tiles.h"
#include "simulator/interface_search.h"
#include "simulator/probe_face_geometry.h"
#include "simulator/step.h"
#include "simulator/trace_settings.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

// The probe face of the capture receive model, or null.
template <int Dim>
const ProbeFace<Dim>* probe_face_of(const TraceSettings& settings) {
    if constexpr (Dim == 2)
        return settings.probe_face_2d ? &*settings.probe_face_2d : nullptr;
    else
        return settings.probe_face_3d ? &*settings.probe_face_3d : nullptr;
}

template <int Dim>
struct TracerConstants {
    StepConstants<Dim> step;  // take_step()'s
    MapView<Dim> view;        // the lanes' and the interface search's view of the map
    float texel_mm = 1.0f, step_mm = 0.5f, seconds_per_mm = 0.0f;
    double max_time_s = 0.0;
    float follow_reflections_above = 0.0f;
    int max_bounces = 64;              // TraceSettings::max_bounces, 0 with bounces off
    float face_reflectivity = 0.0f;    // the probe face's, 0 with face reflection off
    double roulette_loss_per_s = 0.0;  // TraceSettings::roulette_loss_db_per_mm, per second
    double inverse_profile_bin = 0.0;  // 1 / EchoProfileSettings::bin_s
    bool profile_scattered = true;     // EchoProfileSettings::scattered
    float profile_scale = 0.0f;
    bool scatter_enabled = false, profile_enabled = false, deposit_maps = true;
    bool look_up_blocks = false;  // uniform blocks are looked up (kFewUniformBlocks)
    // Off with the probe face or the ring detector: the tight loop does not test them.
    bool uniform_runs = false;
    bool vector_steps = true;  // the vector stage has no probe face or ring detector test

    // `look_up_blocks`: the map has enough uniform blocks to be worth looking up (the
    // head's are mostly air the particles never reach: the lookup at every particle and
    // step costs more than the few steps run in blocks save; the general step gives the
    // uniform run's results to float rounding).
    TracerConstants(const tissue::AcousticMap<Dim>& map, const TraceSettings& settings,
                    const InterfaceSearch<Dim>& search, bool map_has_blocks) {
        const ProbeFace<Dim>* face = probe_face_of<Dim>(settings);
        texel_mm = search.texel_mm();
        step_mm = float(settings.step_texels) * texel_mm;
        scatter_enabled =
            settings.physics.on(Physics::scattering) && settings.mode == PhysicsMode::acoustic;
        profile_enabled = settings.echo_profile.has_value();
        deposit_maps = settings.deposition_maps;
        if (profile_enabled) {
            inverse_profile_bin = 1.0 / settings.echo_profile->bin_s;
            profile_scattered = settings.echo_profile->scattered;
        }
        profile_scale = float(settings.scattering_rate_per_mm) * step_mm *
                        float(settings.scatter_echo_fraction);
        follow_reflections_above = float(settings.follow_reflections_above);
        max_bounces = settings.physics.on(Physics::bounces) ? settings.max_bounces : 0;
        if (face)
            face_reflectivity = settings.physics.on(Physics::face) ? face->reflectivity : 0.0f;
        // dB/mm of path -> Np (intensity) per second of the particle's time at c0.
        roulette_loss_per_s = settings.roulette_loss_db_per_mm * std::log(10.0) / 10.0 *
                              tissue::kReferenceSpeed * 1e3;
        seconds_per_mm = float(1e-3 / tissue::kReferenceSpeed);  // times n gives 1/c
        look_up_blocks = settings.uniform_runs && map_has_blocks;
        const bool plain = face == nullptr && !(Dim == 2 && settings.ring);
        uniform_runs = look_up_blocks && plain;
        vector_steps = settings.vector_steps && plain;
        max_time_s = settings.max_time_s > 0.0 ? settings.max_time_s
                                               : std::numeric_limits<double>::infinity();
        StepConstants<Dim>& c = step;
        c.step_mm = step_mm;
        // alpha [dB/(cm MHz)] * f [MHz] / 10 [mm/cm] -> dB/mm; * ln(10)/10 -> Np/mm (intensity).
        c.attenuation_per_mm = float(tissue::attenuation_per_mm(1.0, settings.frequency_mhz));
        c.scattering_rate_per_mm = float(settings.scattering_rate_per_mm);
        c.threshold2 = search.threshold2();
        c.inverse_texel2 = search.inverse_texel2();
        c.step_time_per_index = double(step_mm) * seconds_per_mm;
        c.max_path_mm = settings.max_path_mm;
        c.max_time_s = max_time_s;
        for (int a = 0; a < Dim; ++a) c.extent[std::size_t(a)] = map.extent_mm()[a];
        c.deposition_maps = deposit_maps;
        c.attenuation = settings.physics.on(Physics::attenuation);
        c.scattering = scatter_enabled;
        c.refraction = settings.physics.on(Physics::refraction);
        c.profile = profile_enabled;
        c.profile_scale = profile_scale;
        c.receive = settings.receive_weights.get();
        MapView<Dim>& m = view;
        m.texels = reinterpret_cast<const float*>(map.texels());
        for (int a = 0; a < Dim; ++a) {
            const auto axis = std::size_t(a);
            m.dims[axis] = map.dims()[a];
            m.inverse_spacing[axis] = map.inverse_spacing()[a];
            m.deposit_tiles[axis] = DepositTiles<Dim>::tiles_along(map.dims()[a]);
        }
        m.deposit_texels = deposit_maps;
        m.prefetch_mm = step_mm;
        if (uniform_runs) {
            m.block_records = map.block_records();
            for (int a = 0; a < Dim; ++a) m.block_dims[std::size_t(a)] = map.block_dims()[a];
            m.block_shift = tissue::AcousticMap<Dim>::kBlockShift;
        }
    }
};

}  // namespace
}  // namespace sonotrace::simulator::detail
