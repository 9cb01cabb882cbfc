// sonotrace-gui: the teaching demo, a live scanner on a desktop (Dear ImGui, GLFW,
// OpenGL 3.3). Headless use for tests and docs: --screenshot FILE --frames N renders
// until N B-mode frames have been shown (and the 3D view has an image), saves the
// window as PNG with a JSON of the view rectangles, and exits.
#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "imaging/picture.h"
#include "imaging/simulation.h"
#include "probe/transducer.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/data_dir.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"
#include "tissue/base/memory.h"
#include "tissue/transfer_function.h"
#include "ui/gui/gui_app.h"

namespace {

using namespace sonotrace;

struct Options {
    gui::AppOptions app;
    std::string screenshot;
    int frames = 3;
    int width = 1600, height = 960;
    double time_limit_s = 300.0;
    std::string json_path;
    int ui_frames = 0;  // with --json and no --screenshot: run this many UI frames
    // The UI redraws at most this often: llvmpipe (Mesa on the CPU) draws the window on
    // the cores the scanner needs, so a UI faster than the eye only slows the frames.
    double max_fps = 30.0;
    bool save = false;    // headless: save the last frame as the button does
    bool record = false;  // headless: record a clip from the first frame to the last
};

nlohmann::json rect_json(const gui::Rect& r) {
    return {r.x, r.y, r.w, r.h};
}

// The window's pixels (bottom-up in GL) as a top-down BGR picture.
cv::Mat read_window(int width, int height) {
    cv::Mat rgba(height, width, CV_8UC4);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadBuffer(GL_BACK);
    glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data);
    cv::Mat flipped, bgr;
    cv::flip(rgba, flipped, 0);
    cv::cvtColor(flipped, bgr, cv::COLOR_RGBA2BGR);
    return bgr;
}

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

int run(const Options& o) {
    if (o.frames < 1) throw base::InputError("--frames", "", "must be at least 1");
    // A still probe refines from its quality up to high, then waits for a move: more
    // frames than that never come (an --open scene refines once more).
    if (!o.app.animate && !o.screenshot.empty()) {
        const auto& stages = imaging::quality_names();
        const auto at = std::find_if(stages.begin(), stages.end(),
                                     [&](const auto& q) { return q.name == o.app.quality; });
        const int still = int(stages.end() - at) * (o.app.open_later.empty() ? 1 : 2);
        if (at != stages.end() && o.frames > still)
            throw base::InputError("--frames", std::to_string(o.frames),
                                   "a still probe shows " + std::to_string(still) + " frames (" +
                                       o.app.quality + " refined up to high" +
                                       (o.app.open_later.empty() ? "" : ", twice with --open") +
                                       "), then waits for the probe to move: ask for at most " +
                                       std::to_string(still) + ", or add --animate");
    }
    if (o.width < 640 || o.height < 480 || o.width > 8192 || o.height > 8192)
        throw base::InputError("--size", "", "window must be 640x480 to 8192x8192 pixels");
    if (!o.screenshot.empty()) {
        const auto dir = std::filesystem::path(o.screenshot).parent_path();
        if (!dir.empty() && !std::filesystem::is_directory(dir))
            throw base::InputError("--screenshot", o.screenshot, "its directory does not exist");
    }
    glfwSetErrorCallback([](int code, const char* text) {
        std::cerr << "sonotrace-gui: GLFW error " << code << ": " << text << "\n";
    });
    if (!glfwInit()) {
        std::cerr << "sonotrace-gui: cannot open a display (is DISPLAY set? headless: run under "
                     "xvfb-run -a)\n";
        return 1;
    }
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    const bool headless = !o.screenshot.empty() || !o.json_path.empty();
    GLFWwindow* window =
        glfwCreateWindow(o.width, o.height, "sonotrace: live ultrasound scanner", nullptr, nullptr);
    if (!window) {
        std::cerr << "sonotrace-gui: cannot create an OpenGL 3.3 window\n";
        glfwTerminate();
        return 1;
    }
    glfwMakeContextCurrent(window);
    glfwSwapInterval(headless ? 0 : 1);  // benchmarks measure the UI, not the display

    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGuiIO& io = ImGui::GetIO();
    io.IniFilename = nullptr;  // a fixed layout: nothing to remember
    const char* font = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
    if (std::filesystem::exists(font)) io.Fonts->AddFontFromFileTTF(font, 15.0f);
    ImGui::StyleColorsDark();
    ImGui_ImplGlfw_InitForOpenGL(window, true);
    ImGui_ImplOpenGL3_Init("#version 330");

    int status = 0;
    {
        gui::App app(o.app);
        using clock = std::chrono::steady_clock;
        const auto start = clock::now();
        std::vector<double> ui_frame_s;
        uint64_t frames_at_start = 0;
        clock::time_point measure_start;
        bool measuring = false;
        int ui_frames = 0;
        auto last = clock::now();
        const auto frame_budget = std::chrono::duration<double>(1.0 / o.max_fps);
        while (!glfwWindowShouldClose(window)) {
            const auto frame_start = clock::now();
            glfwPollEvents();
            ImGui_ImplOpenGL3_NewFrame();
            ImGui_ImplGlfw_NewFrame();
            ImGui::NewFrame();
            int fw = 0, fh = 0;
            glfwGetFramebufferSize(window, &fw, &fh);
            app.draw(fw, fh);
            ImGui::Render();
            glViewport(0, 0, fw, fh);
            glClearColor(0.08f, 0.08f, 0.1f, 1.0f);
            glClear(GL_COLOR_BUFFER_BIT);
            ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());

            if (o.record && !app.recording() && app.frames_shown() == 1) app.toggle_recording();
            const auto now = clock::now();
            // UI frame times once the first B-mode frame is up (loading excluded).
            if (app.frames_shown() > 0) {
                if (!measuring) {
                    measuring = true;
                    measure_start = now;
                    frames_at_start = app.frames_shown();
                } else {
                    ui_frame_s.push_back(std::chrono::duration<double>(now - last).count());
                }
                ++ui_frames;
            }
            last = now;
            const double elapsed = std::chrono::duration<double>(now - start).count();
            const bool enough_frames =
                app.frames_shown() >= uint64_t(o.frames) && !app.loading() &&
                (!o.app.context || app.context_repetitions() > 0 || !app.last_error().empty());
            const bool done_screenshot = !o.screenshot.empty() && enough_frames;
            const bool done_benchmark =
                o.screenshot.empty() && o.ui_frames > 0 && ui_frames >= o.ui_frames;
            if (done_screenshot) {
                if (o.save) app.save_frame();
                if (app.recording()) app.toggle_recording();
                base::OutputTransaction transaction;
                imaging::write_png(read_window(fw, fh), transaction.stage(o.screenshot));
                const nlohmann::json layout = {
                    {"width", fw},
                    {"height", fh},
                    {"slice", rect_json(app.slice_rect())},
                    {"bmode", rect_json(app.bmode_rect())},
                    {"context", rect_json(app.context_rect())},
                    {"energy", rect_json(app.energy_rect())},
                    {"frames_shown", app.frames_shown()},
                    {"context_repetitions", app.context_repetitions()},
                    {"context_renderer", app.context_on_gpu() ? "gpu" : "cpu"},
                    {"transmit", app.transmit_text()},
                    {"error", app.last_error()},
                    {"message", app.last_message()}};
                std::filesystem::path sidecar(o.screenshot);
                sidecar.replace_extension(".json");
                base::jsonio::write_json(layout, transaction.stage(sidecar.string()));
                transaction.commit();
                std::cerr << "sonotrace-gui: wrote " << o.screenshot << "\n";
            }
            if (done_screenshot || done_benchmark) {
                if (!o.json_path.empty()) {
                    const double span = std::chrono::duration<double>(now - measure_start).count();
                    const double median_s = median(ui_frame_s);
                    const nlohmann::json record = {
                        {"scene", o.app.scene},
                        {"animate", o.app.animate},
                        {"ui_frames", ui_frames},
                        {"seconds", span},
                        {"ui_frames_per_s", span > 0 ? ui_frames / span : 0.0},
                        {"median_ui_frame_ms", 1e3 * median_s},
                        {"bmode_frames", app.frames_shown() - frames_at_start},
                        {"bmode_frames_per_s",
                         span > 0 ? double(app.frames_shown() - frames_at_start) / span : 0.0},
                        {"last_simulation_ms", 1e3 * app.last_simulation_seconds()}};
                    base::jsonio::write_json(record, o.json_path);
                }
                break;
            }
            if (headless && elapsed > o.time_limit_s) {
                std::cerr << "sonotrace-gui: --time-limit of " << o.time_limit_s
                          << " s reached before " << o.frames << " frames (" << app.frames_shown()
                          << " shown; " << app.last_error() << ")\n";
                status = 1;
                break;
            }
            glfwSwapBuffers(window);
            std::this_thread::sleep_until(
                frame_start + std::chrono::duration_cast<clock::duration>(frame_budget));
        }
    }
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(window);
    glfwTerminate();
    return status;
}

}  // namespace

int main(int argc, char** argv) {
    sonotrace::base::keep_freed_memory();
    Options o;
    CLI::App cli(
        "sonotrace-gui: a live ultrasound scanner for teaching. Move the probe over the Colin27 "
        "head or a phantom and watch the B-mode form from traced particles; switch physics off "
        "and on to see each artifact vanish and return. Lengths in mm, angles in degrees.");
    std::vector<std::string> scenes;
    for (const auto& e : gui::scene_catalogue(base::phantom_catalogue_dir()))
        scenes.push_back(e.name);
    std::string scene_list;
    for (const auto& s : scenes) scene_list += (scene_list.empty() ? "" : ", ") + s;
    cli.add_option("--scene", o.app.scene,
                   "scene to open: " + scene_list + ", or a volume / phantom file")
        ->capture_default_str();
    std::string presets;
    for (const probe::Transducer& t : probe::transducer_presets())
        presets += (presets.empty() ? "" : ", ") + t.name;
    cli.add_option("--probe", o.app.probe, "probe preset (" + presets + "); empty = the scene's");
    cli.add_option("--quality", o.app.quality,
                   "quality while the probe moves: interactive, standard or high")
        ->capture_default_str();
    cli.add_option("--transmit", o.app.transmit,
                   "transmit at start: focused (line by line), plane or diverging waves (open "
                   "arrays: not the radial ring), beamformed from every element's channel "
                   "data")
        ->capture_default_str();
    cli.add_option("--transmits", o.app.transmits,
                   "unfocused transmits, their angles evenly over +-span (1 to 75)")
        ->capture_default_str();
    cli.add_option("--span", o.app.span_deg,
                   "outermost steering angle of the unfocused transmits (0 to 20) [degrees]")
        ->capture_default_str();
    cli.add_option("--slide", o.app.slide_mm,
                   "start this far along the surface from the scene's pose, laterally [mm]")
        ->capture_default_str();
    cli.add_option("--out", o.app.out_dir, "directory for saved frames and clips")
        ->capture_default_str();
    cli.add_flag("--animate", o.app.animate,
                 "slide the probe back and forth by itself (+-15 mm; demos and benchmarks)");
    cli.add_flag("!--no-context", o.app.context, "no 3D context view (saves CPU)");
    cli.add_option("--context-renderer", o.app.context_renderer,
                   "where the 3D context's particles are projected and averaged: gpu (OpenGL), "
                   "cpu (the reference renderer, on the cores), auto (OpenGL unless it is Mesa's "
                   "software rasterizer, which is slower than the cores)")
        ->capture_default_str()
        ->check(CLI::IsMember({"auto", "gpu", "cpu"}));
    cli.add_option("--open", o.app.open_later,
                   "once the first frame is shown, open this volume or phantom file as the "
                   "'open file' field does (a file that fails to load leaves the scene as it was)");
    cli.add_flag("--save", o.save,
                 "with --screenshot: save the last frame as the 'save frame' button does "
                 "(PNG + JSON sidecar in --out)");
    cli.add_flag("--record", o.record,
                 "with --screenshot: record the frames shown into a clip as the 'record clip' "
                 "button does (H.264 MP4 in --out)");
    cli.add_option(
        "--tf", o.app.tf, "transfer function of a volume scene: a preset (" + [] {
            std::string list;
            for (const std::string& p : tissue::transfer_function_presets())
                list += (list.empty() ? "" : ", ") + p;
            return list;
        }() + ") or a JSON file; empty = the volume's default");
    cli.add_option("--explain", o.app.explain,
                   "highlight this artifact of the explain panel and its control at start "
                   "(e.g. 'acoustic shadowing')");
    cli.add_option("--screenshot", o.screenshot,
                   "headless: save the window as PNG (and the view rectangles as .json) once "
                   "--frames B-mode frames have been shown, then exit");
    cli.add_option("--frames", o.frames,
                   "B-mode frames to show before the screenshot (a still probe refines: "
                   "interactive, standard, high)")
        ->capture_default_str();
    cli.add_option("--json", o.json_path,
                   "write UI frame rate, B-mode update rate and simulation time to this file "
                   "('-' = stdout) when the run ends");
    cli.add_option("--ui-frames", o.ui_frames,
                   "with --json and no --screenshot: exit after this many UI frames (benchmark)");
    cli.add_option("--time-limit", o.time_limit_s, "headless runs fail after this many seconds [s]")
        ->capture_default_str();
    cli.add_option("--max-fps", o.max_fps,
                   "the UI redraws at most this often, leaving the cores to the scanner [1/s]")
        ->capture_default_str()
        ->check(CLI::Range(1.0, 1000.0));
    std::string size = "1600x960";
    cli.add_option("--size", size, "window size WIDTHxHEIGHT [pixels]")->capture_default_str();
    try {
        cli.parse(argc, argv);
        if (std::sscanf(size.c_str(), "%dx%d", &o.width, &o.height) != 2)
            throw base::InputError("--size", size, "expected WIDTHxHEIGHT");
        return run(o);
    } catch (const CLI::ParseError& e) {
        // The help (0), or the message naming the option: bad input exits 1, as `sonotrace`.
        return cli.exit(e) == 0 ? 0 : 1;
    } catch (const std::exception& e) {
        std::cerr << "sonotrace-gui: error: " << e.what() << "\n";
        return 1;
    }
}
