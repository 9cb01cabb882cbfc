// The GUI's 3D context, one repetition at the GUI's view (the default head scene, its
// start pose's B-mode sector overlaid, 320 x 320, one sub-pixel per pixel): the CPU
// renderer (generation, projection and averaging on the cores) against the GPU path
// (generation on the cores, PbvrRenderer::splats; projection, depth test and averaging
// in OpenGL, gl::GlPbvr, timed to glFinish). Alternates the two, repetition by
// repetition, and prints the medians as JSON.
//
//   xvfb-run -a build/bench/bench_context [repetitions]   # Mesa's llvmpipe, this machine
//   build/bench/bench_context [repetitions]               # on a desktop with a GPU
#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GLFW/glfw3.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "imaging/pbvr/overlay.h"
#include "imaging/pbvr/pbvr.h"
#include "tissue/base/data_dir.h"
#include "ui/gl/gl_pbvr.h"
#include "ui/gui/scanner.h"

namespace {

using namespace sonotrace;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return 1e3 * std::chrono::duration<double>(Clock::now() - start).count();
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
    const int repetitions = argc > 1 ? std::max(1, std::atoi(argv[1])) : 16;
    if (!glfwInit()) {
        std::cerr << "bench_context: no display (run under xvfb-run -a)\n";
        return 1;
    }
    glfwWindowHint(GLFW_VISIBLE, GLFW_FALSE);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    GLFWwindow* window = glfwCreateWindow(64, 64, "bench_context", nullptr, nullptr);
    if (!window) {
        std::cerr << "bench_context: no OpenGL 3.3 context\n";
        return 1;
    }
    glfwMakeContextCurrent(window);
    const std::string renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));

    const auto scene = gui::load_scene("head-craniotomy", base::phantom_catalogue_dir());
    gui::ScanRequest request;
    request.scene = scene;
    request.pose = scene->start.pose;
    request.parameters.transducer = probe::find_transducer(scene->probe_preset, "bench");
    request.context.enabled = false;
    const gui::ScanFrame frame = *gui::simulate_request(request, imaging::Quality::interactive);
    const gui::ContextView view;
    const imaging::pbvr::OrbitCamera camera = gui::context_camera(*scene, view);
    imaging::pbvr::FrameOverlay overlay;
    frame.frame.image.image.convertTo(overlay.frame, CV_8U, 255.0);
    overlay.origin_mm = frame.frame.image.origin;
    overlay.pixel_mm = glm::dvec2(frame.frame.image.pixel_mm);
    overlay.position = frame.pose.position;
    overlay.axial = frame.pose.axial();
    overlay.lateral = frame.pose.lateral();
    overlay.elevation = frame.pose.elevation();
    overlay.transducer = frame.settings.transducer;
    imaging::pbvr::RenderSettings settings;
    settings.subpixel_level = 1;
    settings.clip_plane =
        imaging::pbvr::camera_side_of_plane(overlay, scene->context->geometry(), camera);
    const imaging::pbvr::RenderVolume volume(*scene->context, scene->context_tf);
    const std::vector<uint64_t> layer = imaging::pbvr::overlay_layer(overlay, camera, 1);

    imaging::pbvr::PbvrRenderer cpu(volume, scene->context_tf, camera, settings);
    cpu.set_overlay(layer);
    gl::GlPbvr gpu(camera.width, camera.height, 1, settings.background);
    gpu.set_overlay(layer);
    std::vector<double> cpu_ms, generate_ms, draw_ms, gpu_ms;
    std::size_t particles = 0;
    for (int r = 0; r < repetitions; ++r) {
        auto start = Clock::now();
        cpu.add_repetition();
        cpu_ms.push_back(ms_since(start));
        start = Clock::now();
        const std::vector<imaging::pbvr::Splat> splats = cpu.splats(uint32_t(r));
        generate_ms.push_back(ms_since(start));
        const auto draw_start = Clock::now();
        gpu.add_repetition(splats);
        glFinish();
        draw_ms.push_back(ms_since(draw_start));
        gpu_ms.push_back(ms_since(start));
        particles += splats.size();
    }
    const nlohmann::json record = {
        {"renderer", renderer},
        {"size", {camera.width, camera.height}},
        {"repetitions", repetitions},
        {"particles_per_repetition", double(particles) / repetitions},
        {"cpu_ms_per_repetition", median(cpu_ms)},
        {"gpu_ms_per_repetition", median(gpu_ms)},
        {"gpu_generation_ms", median(generate_ms)},
        {"gpu_draw_ms", median(draw_ms)},
        {"psnr_gpu_vs_cpu_db", imaging::pbvr::psnr(gpu.image(), cpu.image())}};
    std::cout << record.dump(2) << "\n";
    glfwDestroyWindow(window);
    glfwTerminate();
    return 0;
}
