#include "simulator/trace_settings.h"

#include <cmath>

#include "probe/array_geometry.h"
#include "tissue/base/error.h"

namespace sonotrace::simulator {

ProbeFace<2> probe_face(const probe::Transducer& t, const glm::dvec2& to_map) {
    ProbeFace<2> face;
    face.centre = glm::vec2(to_map);
    face.normal = {0.0f, 1.0f};
    face.half_width_mm = float(0.5 * t.array_length_mm());
    face.radius_mm = float(probe::array_geometry(t)->face_radius_mm());
    face.reflectivity = float(t.face_reflectivity);
    return face;
}

ProbeFace<3> probe_face(const probe::Transducer& t, const glm::dvec3& to_map) {
    const ProbeFace<2> in_plane = probe_face(t, glm::dvec2(to_map));
    ProbeFace<3> face;
    face.centre = glm::vec3(to_map);
    face.normal = {0.0f, 1.0f, 0.0f};
    face.elevation = {0.0f, 0.0f, 1.0f};
    face.half_width_mm = in_plane.half_width_mm;
    face.half_height_mm = float(0.5 * t.elevation_aperture_mm());
    face.radius_mm = in_plane.radius_mm;
    face.reflectivity = in_plane.reflectivity;
    return face;
}

std::string to_string(PhysicsMode mode) {
    return mode == PhysicsMode::acoustic ? "acoustic" : "paper";
}

std::string to_string(LobeExponent lobe) {
    switch (lobe) {
        case LobeExponent::roughness:
            return "roughness";
        case LobeExponent::reflecting_density:
            return "reflecting-density";
        case LobeExponent::density_ratio:
            return "density-ratio";
    }
    return "?";
}

std::string to_string(LobeWeight weight) {
    return weight == LobeWeight::probability ? "probability" : "energy";
}

void TraceSettings::validate(const std::string& source) const {
    auto in_range = [&](double v, double lo, double hi, const char* field) {
        base::require_in_range(source, field, v, lo, hi);
    };
    in_range(step_texels, 0.01, 4.0, "step");
    in_range(frequency_mhz, 0.1, 100.0, "frequency");
    in_range(lobe_scale, 0.0, 1e6, "lobe-scale");
    in_range(interface_threshold, 1e-6, 1.0, "interface-threshold");
    in_range(scattering_rate_per_mm, 0.0, 100.0, "scattering-rate");
    in_range(scatter_echo_fraction, 0.0, 1.0, "scatter-echo-fraction");
    in_range(roulette_energy, 0.0, 0.5, "roulette");
    in_range(roulette_loss_db_per_mm, 0.0, 100.0, "roulette-loss");
    in_range(follow_reflections_above, 0.0, 1.0, "follow-reflections-above");
    in_range(interface_reach_mm, 0.0, 100.0, "interface-reach");
    in_range(max_path_mm, 1.0, 1e6, "max-path");
    in_range(max_time_s, 0.0, 1.0, "max-time");
    in_range(max_bounces, 0, 1000000, "max-bounces");
    in_range(record_paths, 0, 1000000, "record-paths");
    in_range(record_paths_line_stride, 1, 1000000, "record-paths-line-stride");
    if (probe_face_2d) in_range(probe_face_2d->reflectivity, 0.0, 1.0, "probe-face.reflectivity");
    if (probe_face_3d) in_range(probe_face_3d->reflectivity, 0.0, 1.0, "probe-face.reflectivity");
    if (echo_profile) {
        in_range(echo_profile->bin_s, 1e-10, 1e-3, "echo-profile.bin");
        in_range(echo_profile->bins, 1, 1 << 20, "echo-profile.bins");
    }
    if (ring) {
        in_range(ring->radius_mm, 1e-3, 1e6, "ring.radius");
        in_range(ring->bins, 1, 100000, "ring.bins");
    }
}

}  // namespace sonotrace::simulator
