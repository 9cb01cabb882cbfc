#pragma once
// `sonotrace render`: particle-based volume rendering of a volume (the 3D tissue
// context), with an optional ray-cast reference and its PSNR.
#include <string>
#include <vector>

#include "imaging/pbvr/pbvr.h"
#include "ui/cli/command_common.h"

namespace sonotrace::ui {

struct RenderOptions {
    // Volumes and their transfer functions, by position: regular volumes (the first is
    // rendered by particles, others become tetrahedral meshes) and .vtk meshes.
    std::vector<std::string> volumes{"default"};
    std::vector<std::string> tfs{"head"};
    std::string depth_sampling = "cdf";
    double azimuth_deg = imaging::pbvr::kHeadAzimuthDeg;
    double elevation_deg = imaging::pbvr::kHeadElevationDeg;
    double distance_mm = 0.0;  // 0 = fit
    double fov_deg = 30.0;
    int width = 512, height = 512;
    int repetitions = imaging::pbvr::RenderSettings{}.repetitions;
    int subpixel = imaging::pbvr::RenderSettings{}.subpixel_level;
    double radius_scale = imaging::pbvr::RenderSettings{}.radius_scale;
    std::string sampling = "uniform";
    std::string shading = "blinn-phong";
    std::string background = "0,0,0";
    std::string cut_away = "auto";
    double time_limit_s = 0.0;
    uint64_t seed = 1;
    std::string frame;    // simulate sidecar: probe, scan plane and B-mode in the view
    bool sector = false;  // also the frame's sector as a mesh (fused rendering)
    std::string sector_tf = "bmode";
    std::string reference;  // also ray-cast the reference to this PNG and report PSNR
    double reference_step_mm = 0.25;
    std::string renderer = "cpu";  // or "gpu" (OpenGL through EGL)
    std::string out = "out/render.png";
    std::string json_path;
    int threads = 0;
    bool quiet = false;
};

CLI::App* add_render_command(CLI::App& app, RenderOptions& options);
int run_render_command(const RenderOptions& options);

}  // namespace sonotrace::ui
