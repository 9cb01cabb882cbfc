#pragma once
// `sonotrace trace`: particle paths over the medium and the energy maps, for a built-in
// configuration (the particle paper's figures) or a volume slice.
#include <string>

#include "simulator/trace_settings.h"
#include "ui/cli/command_common.h"
#include "ui/cli/volume_slice.h"

namespace sonotrace::ui {

struct TraceOptions {
    std::string config;   // fig2, fig4a, fig4b, fig5, fig6; empty = volume slice
    std::string phantom;  // JSON phantom with a "source" entry
    SliceOptions slice;
    std::string mode = "acoustic";
    int particles = 0;  // 0 = the configuration's default
    int lines = 16;
    std::string injection = "fan";
    double beam_angle_deg = 30.0;
    double beam_width_mm = 40.0;
    double contrast = 0.5;  // paper mode on a volume: d = 1 + contrast * normalised value
    double face_reflectivity = 0.0;
    std::string disable;        // comma list: refraction,specular,diffuse,scattering,absorption
    std::string lobe_exponent;  // empty = mode default
    std::string lobe_weight;
    double lobe_scale = -1.0;  // < 0 = configuration default
    double step_texels = 0.5;
    double frequency_mhz = 5.0;
    uint64_t seed = 1;
    int max_bounces = 64;
    int paths = -1;  // paths drawn per line; -1 = configuration default
    std::string echoes_csv;
    std::string out_dir = "out/trace";
    std::string json_path;
    int threads = 0;
    bool quiet = false;
};

CLI::App* add_trace_command(CLI::App& app, TraceOptions& options);
int run_trace_command(const TraceOptions& options);

}  // namespace sonotrace::ui
