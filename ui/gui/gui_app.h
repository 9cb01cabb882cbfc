#pragma once
// The demo GUI's panels (Dear ImGui): controls and explain panel on the left, four views
// on the right (tissue slice with the probe and live particle beams, B-mode, 3D context
// by PBVR, energy deposition), a status bar. The scanner (scanner.h) works on its own
// thread; this class only submits requests and shows what comes back.
#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <string>

#include "imaging/video.h"
#include "ui/gl/gl_pbvr.h"
#include "ui/gui/controls.h"
#include "ui/gui/scanner.h"

namespace sonotrace::gui {

struct AppOptions {
    std::string scene = "head-craniotomy";
    std::string probe;  // preset; empty = the scene's
    std::string quality = "interactive";
    // The transmit panel at start: focused, plane or diverging (open arrays), with the
    // transmits' number and outermost angle (degrees).
    std::string transmit = "focused";
    int transmits = 5;
    double span_deg = 8.0;
    double slide_mm = 0.0;  // start this far along the surface (lateral)
    std::string out_dir = "out/gui";
    bool animate = false;  // slide the probe back and forth by itself (benchmarks, demos)
    bool context = true;
    std::string open_later;  // opened like the "open file" field once a frame is shown
    std::string explain;     // an artifact of the explain panel to highlight at start
    std::string tf;          // the scene's transfer function if it is a volume; empty: its own
    // Where the 3D context is projected and averaged: "gpu" (OpenGL), "cpu" (the worker's
    // renderer), "auto" (OpenGL unless it runs in software, where the cores do it faster).
    std::string context_renderer = "auto";
};

// A GL texture holding an RGB(A) picture.
class Texture {
  public:
    Texture() = default;
    ~Texture();
    Texture(const Texture&) = delete;
    Texture& operator=(const Texture&) = delete;
    void upload(const cv::Mat& picture);  // CV_8UC3 RGB or CV_8UC1 grey
    bool empty() const { return id_ == 0; }
    void* imgui_id() const { return reinterpret_cast<void*>(uintptr_t(id_)); }
    int width() const { return width_; }
    int height() const { return height_; }

  private:
    unsigned id_ = 0;
    int width_ = 0, height_ = 0;
};

// Screen rectangles of the views (pixels, top-left origin), for screenshots and tests.
struct Rect {
    float x = 0, y = 0, w = 0, h = 0;
};

class App {
  public:
    explicit App(const AppOptions& options);
    ~App();

    // One UI frame: collect results, draw every panel (between ImGui::NewFrame and Render).
    void draw(int window_width, int window_height);

    // Saves the frame shown (PNG + JSON sidecar) in the output directory.
    void save_frame();
    // Starts or stops recording the B-mode frames into a clip there (H.264 MP4; Motion
    // JPEG AVI where FFmpeg writes no MP4).
    void toggle_recording();
    bool recording() const { return recording_.has_value(); }

    uint64_t frames_shown() const { return frames_shown_; }  // B-mode frames displayed
    int context_repetitions() const { return context_repetitions_; }
    bool context_on_gpu() const { return view_.gpu; }
    // --transmit's text of the transmit panel ("focused", "plane:-8:8:5", ...).
    std::string transmit_text() const { return parameters_.transmit.text(parameters_.transducer); }
    // True while a scene loads, or until --open's file has been tried.
    bool loading() const {
        return loading_.valid() || (!options_.open_later.empty() && !opened_later_);
    }
    const std::string& last_error() const { return error_; }
    const std::string& last_message() const { return message_; }
    Rect bmode_rect() const { return bmode_rect_; }
    Rect slice_rect() const { return slice_rect_; }
    Rect context_rect() const { return context_rect_; }
    Rect energy_rect() const { return energy_rect_; }
    double last_simulation_seconds() const { return last_seconds_; }

  private:
    void poll();
    void request();
    void move_probe(double lateral_mm, double elevation_mm, double rotate_deg, double tilt_deg);
    // Loads a scene in the background; `tf` as gui::load_scene takes it.
    void start_loading(const std::string& spec, const std::string& tf = "");
    // A volume's transfer function and the probe's pose as text (the --pose format).
    void draw_volume_controls();
    void apply_scene(std::shared_ptr<const Scene> scene);
    void handle_keys();

    void draw_controls(float x, float y, float w, float h);
    void draw_explain(float x, float y, float w, float h);
    void draw_slice(float x, float y, float w, float h);
    void draw_bmode(float x, float y, float w, float h);
    void draw_context(float x, float y, float w, float h);
    void draw_energy(float x, float y, float w, float h);
    void draw_status(float x, float y, float w, float h);
    bool highlight_begin(Control control);
    void highlight_end(bool pushed);

    AppOptions options_;
    Scanner scanner_;
    std::shared_ptr<const Scene> scene_;
    std::future<std::shared_ptr<const Scene>> loading_;
    std::string loading_name_;
    std::vector<SceneEntry> catalogue_;
    std::string open_path_;
    std::string tf_choice_;  // the opened volume's transfer function: preset or file
    std::string tf_file_;    // a transfer function file typed in
    std::string pose_text_;  // being edited; empty: shows the live pose

    ScanParameters parameters_;
    std::string probe_preset_;
    probe::Pose pose_;
    ContextView view_;
    bool frozen_ = false;
    bool dirty_ = true;  // parameters or pose changed since the last request
    Control highlighted_ = Control::none;
    bool scroll_to_highlight_ = false;  // bring the highlighted artifact into view once
    double animate_phase_ = 0.0;
    bool opened_later_ = false;

    std::optional<ScanFrame> frame_;  // what the views show
    std::optional<ContextImage> context_;
    Texture slice_texture_, bmode_texture_, context_texture_, energy_texture_;
    std::unique_ptr<gl::GlPbvr> gl_context_;  // the GPU path's ensemble
    uint64_t gl_ensemble_ = 0;
    imaging::pbvr::OrbitCamera gl_camera_;
    double gl_seconds_ = 0.0;
    uint64_t frames_shown_ = 0;
    int context_repetitions_ = 0;
    double last_seconds_ = 0.0;

    std::optional<imaging::VideoClip> recording_;
    std::string recording_path_;
    cv::Size recording_size_;
    int recorded_frames_ = 0;

    std::string error_, message_;
    Rect slice_rect_, bmode_rect_, context_rect_, energy_rect_;
};

}  // namespace sonotrace::gui
