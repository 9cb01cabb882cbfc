#include "ui/gui/gui_app.h"
#include "tissue/base/data_dir.h"

#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_stdlib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "imaging/picture.h"
#include "phantoms/scene/records.h"
#include "probe/array_geometry.h"
#include "probe/pose.h"
#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::gui {

namespace {

constexpr ImGuiWindowFlags kPanelFlags = ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize |
                                         ImGuiWindowFlags_NoCollapse |
                                         ImGuiWindowFlags_NoSavedSettings;
constexpr ImGuiWindowFlags kViewFlags =
    kPanelFlags | ImGuiWindowFlags_NoScrollbar | ImGuiWindowFlags_NoScrollWithMouse;
const ImU32 kProbeColour = IM_COL32(90, 200, 255, 255);
const ImU32 kHighlight = IM_COL32(255, 190, 40, 255);

void begin_panel(const char* title, float x, float y, float w, float h, ImGuiWindowFlags flags) {
    ImGui::SetNextWindowPos(ImVec2(x, y));
    ImGui::SetNextWindowSize(ImVec2(w, h));
    ImGui::Begin(title, nullptr, flags);
}

void section(const char* title) {
    ImGui::Spacing();
    ImGui::Separator();
    ImGui::TextDisabled("%s", title);
}

void tooltip(const std::string& text) {
    if (!text.empty() && ImGui::IsItemHovered()) {
        ImGui::BeginTooltip();
        ImGui::PushTextWrapPos(ImGui::GetFontSize() * 28.0f);
        ImGui::TextUnformatted(text.c_str());
        ImGui::PopTextWrapPos();
        ImGui::EndTooltip();
    }
}

// A vertical colour bar at `at` (top left) of `size`, `colours` from top to bottom, a
// tick and its text at each (fraction from the top, text), written to the bar's left.
void colour_bar(ImDrawList* draw, ImVec2 at, ImVec2 size, const std::vector<ImU32>& colours,
                const std::vector<std::pair<float, std::string>>& ticks, const char* title) {
    const int n = int(colours.size());
    for (int k = 0; k + 1 < n; ++k) {
        const float y0 = at.y + size.y * float(k) / float(n - 1);
        const float y1 = at.y + size.y * float(k + 1) / float(n - 1);
        draw->AddRectFilledMultiColor(ImVec2(at.x, y0), ImVec2(at.x + size.x, y1),
                                      colours[std::size_t(k)], colours[std::size_t(k)],
                                      colours[std::size_t(k) + 1], colours[std::size_t(k) + 1]);
    }
    const ImU32 text = IM_COL32(220, 220, 220, 255);
    draw->AddRect(at, ImVec2(at.x + size.x, at.y + size.y), IM_COL32(160, 160, 160, 255));
    for (const auto& [fraction, label] : ticks) {
        const float y = at.y + fraction * size.y;
        const ImVec2 extent = ImGui::CalcTextSize(label.c_str());
        draw->AddLine(ImVec2(at.x - 4, y), ImVec2(at.x, y), text);
        draw->AddText(ImVec2(at.x - 6 - extent.x, y - 0.5f * extent.y), text, label.c_str());
    }
    const ImVec2 extent = ImGui::CalcTextSize(title);
    draw->AddText(ImVec2(at.x + size.x - extent.x, at.y - extent.y - 2), text, title);
}

// A tissue's name as a legend shows it: the table's human name without its parenthesis.
std::string short_tissue_name(int label) {
    const auto table = tissue::tissue_table();
    if (label < 1 || label > int(table.size())) return "label " + std::to_string(label);
    const std::string name(table[std::size_t(label) - 1].name);
    return name.substr(0, name.find(" ("));
}

ImU32 label_colour_u32(int label) {
    const cv::Vec3b bgr = imaging::label_colour(label);
    return IM_COL32(bgr[2], bgr[1], bgr[0], 255);
}

// Where a picture went on the screen.
struct Fit {
    ImVec2 origin, size;
    float scale = 1.0f;  // screen pixels per picture pixel
};

// Points of a scan sector's outline in the probe plane (mm): the first line, the far
// arc, the last line, the face; for an array closed on itself, the far circle.
std::vector<glm::dvec2> sector_outline(const probe::Transducer& t) {
    const probe::ScanGeometry scan(t);
    std::vector<glm::dvec2> out;
    if (scan.closed()) {
        const int arc = 96;
        for (int k = 0; k < arc; ++k)
            out.push_back(scan.point(-0.5 + double(scan.lines()) * k / arc, scan.depth_mm()));
        return out;
    }
    const double last = scan.lines() - 1;
    const int arc = 24;
    for (int k = 0; k <= arc; ++k) out.push_back(scan.point(last * k / arc, scan.depth_mm()));
    for (int k = arc; k >= 0; --k) out.push_back(scan.point(last * k / arc, 0.0));
    return out;
}

// The quality combo's entries, with the numbers from the quality levels themselves.
std::string quality_label(imaging::Quality q) {
    const imaging::QualityLevel level = imaging::quality_level(q);
    return imaging::to_string(q) + ": " + std::to_string(level.particles_per_line) + "/line, " +
           base::number_text(level.map_pixel_mm) + " mm";
}

cv::Mat energy_picture(const tissue::Volume& absorbed) {
    const glm::ivec3 n = absorbed.geometry().dims;
    float peak = 0.0f;
    for (float v : absorbed.voxels()) peak = std::max(peak, v);
    cv::Mat grey(n.y, n.x, CV_8U, cv::Scalar(0));
    if (peak > 0.0f) {
        // 40 dB of deposited energy, log scale.
        for (int j = 0; j < n.y; ++j)
            for (int i = 0; i < n.x; ++i) {
                const float v = absorbed.at(i, j, 0) / peak;
                const float db = v > 0.0f ? 10.0f * std::log10(v) : -100.0f;
                grey.at<uint8_t>(j, i) =
                    uint8_t(std::clamp((db + 40.0f) / 40.0f, 0.0f, 1.0f) * 255);
            }
    }
    cv::Mat bgr, rgb;
    cv::applyColorMap(grey, bgr, cv::COLORMAP_INFERNO);
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    return rgb;
}

}  // namespace

// ---- textures ----

Texture::~Texture() {
    if (id_) glDeleteTextures(1, &id_);
}

void Texture::upload(const cv::Mat& picture) {
    cv::Mat rgba;
    if (picture.channels() == 1)
        cv::cvtColor(picture, rgba, cv::COLOR_GRAY2RGBA);
    else
        cv::cvtColor(picture, rgba, cv::COLOR_RGB2RGBA);
    id_ =
        texture_2d(GL_RGBA, rgba.cols, rgba.rows, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data, true, id_);
    width_ = rgba.cols;
    height_ = rgba.rows;
}

namespace {

// Draws a picture as large as the window's content region allows, at its aspect,
// centred horizontally; `rect` receives its screen rectangle.
Fit show_image(void* texture, int width, int height, Rect* rect) {
    const ImVec2 avail = ImGui::GetContentRegionAvail();
    const ImVec2 cursor = ImGui::GetCursorScreenPos();
    const float w = float(width), h = float(height);
    Fit f;
    f.scale = std::max(1e-3f, std::min(avail.x / w, avail.y / h));
    f.origin = ImVec2(cursor.x + 0.5f * (avail.x - f.scale * w), cursor.y);
    f.size = ImVec2(f.scale * w, f.scale * h);
    ImGui::SetCursorScreenPos(f.origin);
    ImGui::Image(texture, f.size);
    *rect = {f.origin.x, f.origin.y, f.size.x, f.size.y};
    return f;
}

Fit show_image(const Texture& texture, Rect* rect) {
    return show_image(texture.imgui_id(), texture.width(), texture.height(), rect);
}

}  // namespace

// ---- the application ----

App::App(const AppOptions& options)
    : options_(options), catalogue_(scene_catalogue(base::phantom_catalogue_dir())) {
    parameters_.quality = imaging::parse_quality(options.quality, "--quality", "");
    if (!options.probe.empty()) probe::find_transducer(options.probe, "--probe");  // validates
    view_.enabled = options.context;
    if (options.context_renderer != "auto" && options.context_renderer != "gpu" &&
        options.context_renderer != "cpu")
        throw base::InputError("--context-renderer", options.context_renderer,
                               "must be auto, gpu or cpu");
    // Mesa's software rasterizer projects on the same cores as the CPU renderer, and
    // slower (bench/README.md): auto keeps the CPU renderer there.
    const char* gl_renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    const std::string name = gl_renderer ? gl_renderer : "";
    const bool software = name.find("llvmpipe") != std::string::npos ||
                          name.find("softpipe") != std::string::npos ||
                          name.find("Software") != std::string::npos;
    view_.gpu = options.context_renderer == "gpu" ||
                (options.context_renderer == "auto" && !software && !name.empty());
    // The first scene loads synchronously: without it there is nothing to show.
    apply_scene(load_scene(options.scene, base::phantom_catalogue_dir(), options.tf));
    if (options.slide_mm != 0.0) move_probe(options.slide_mm, 0.0, 0.0, 0.0);
    if (!options.explain.empty()) {
        std::string known;
        for (const Artifact& a : explain(*scene_, parameters_)) {
            if (a.name == options.explain) {
                highlighted_ = a.control;
                scroll_to_highlight_ = true;
            }
            known += (known.empty() ? "" : ", ") + a.name;
        }
        if (highlighted_ == Control::none)
            throw base::InputError("--explain", options.explain,
                                   "is not an artifact of this scene; it shows: " + known);
    }
}

App::~App() {
    if (recording_) recording_->close();
}

void App::apply_scene(std::shared_ptr<const Scene> scene) {
    scene_ = std::move(scene);
    const std::string preset =
        !options_.probe.empty() && probe_preset_.empty() ? options_.probe : scene_->probe_preset;
    probe_preset_ = preset;
    parameters_.transducer = probe::find_transducer(preset, "probe");
    pose_ = scene_->start.pose;
    parameters_.gain_db = scene_->gain_db;  // as `sonotrace simulate`
    pose_text_.clear();
    tf_choice_.clear();
    view_.zoom = scene_->context_zoom;
    frame_.reset();
    context_.reset();
    dirty_ = true;
}

void App::start_loading(const std::string& spec, const std::string& tf) {
    if (loading_.valid()) return;
    loading_name_ = spec + (tf.empty() ? "" : " with " + tf);
    message_ = "loading " + loading_name_ + " ...";
    loading_ = std::async(std::launch::async, [spec, tf] {
        return load_scene(spec, base::phantom_catalogue_dir(), tf);
    });
}

void App::draw_volume_controls() {
    const auto& source = scene_->volume;
    if (!source || source->is_default) return;
    section("volume");
    if (tf_choice_.empty()) tf_choice_ = source->tf->describe().value("name", "custom");
    if (ImGui::BeginCombo("transfer function", tf_choice_.c_str())) {
        for (const std::string& preset : tissue::transfer_function_presets())
            if (ImGui::Selectable(preset.c_str(), preset == tf_choice_)) {
                tf_choice_ = preset;
                start_loading(scene_->name, preset);
            }
        ImGui::EndCombo();
    }
    tooltip("how the volume's intensities become tissues: a preset, or a JSON file typed below");
    ImGui::InputText("##tf_file", &tf_file_);
    tooltip("a transfer function JSON file (docs/guide/volumes.md)");
    ImGui::SameLine();
    if (ImGui::Button("use file") && !tf_file_.empty()) {
        tf_choice_ = tf_file_;
        start_loading(scene_->name, tf_file_);
    }
    // The pose as --pose writes it: edit and apply, or go back to the volume's default.
    std::string shown = pose_text_.empty() ? pose_.to_string() : pose_text_;
    if (ImGui::InputText("pose", &shown)) pose_text_ = shown;
    tooltip(probe::kPoseHelp);
    if (ImGui::Button("apply pose") && !pose_text_.empty()) {
        try {
            const probe::Pose p = probe::parse_pose(pose_text_, "pose");
            scene_->require_inside(p, "pose");
            pose_ = scene_->clamp(p);
            pose_text_.clear();
            dirty_ = true;
            error_.clear();
        } catch (const std::exception& e) {
            error_ = e.what();
        }
    }
    ImGui::SameLine();
    if (ImGui::Button("default pose")) {
        pose_ = scene::default_volume_pose(*source);
        pose_text_.clear();
        dirty_ = true;
    }
    tooltip(source->loaded.anatomical
                ? "on the superior surface looking down (the file names its axes: RAS)"
                : "on the top face of the volume's box (the file names no anatomical axes)");
}

void App::move_probe(double lateral_mm, double elevation_mm, double rotate_deg, double tilt_deg) {
    probe::Pose p = pose_;
    p.position += lateral_mm * p.lateral() + elevation_mm * p.elevation();
    if (rotate_deg != 0.0) p = p.rotated(rotate_deg);
    if (tilt_deg != 0.0) p = p.tilted(tilt_deg);
    pose_ = scene_->clamp(scene_->settle(p));
    dirty_ = true;
}

void App::request() {
    ScanRequest r;
    r.scene = scene_;
    r.pose = pose_;
    r.parameters = parameters_;
    r.context = view_;
    // Every particle of 8 lines across the sector: their beams are drawn.
    r.paths_per_line = 100000;
    r.path_line_stride = std::max(1, parameters_.transducer.lines / 8);
    r.refine = true;
    scanner_.submit(std::move(r));
    dirty_ = false;
}

void App::poll() {
    if (loading_.valid() &&
        loading_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
        try {
            apply_scene(loading_.get());
            message_ = "scene " + scene_->title;
            error_.clear();
        } catch (const std::exception& e) {
            // The previous scene stays.
            error_ = std::string("could not load the scene: ") + e.what();
            message_.clear();
            loading_ = {};
        }
    }
    if (auto e = scanner_.take_error()) error_ = *e;
    if (auto f = scanner_.take_frame()) {
        frame_ = std::move(f);
        slice_texture_.upload(frame_->slice);
        cv::Mat grey;
        frame_->frame.image.image.convertTo(grey, CV_8U, 255.0);
        bmode_texture_.upload(grey);
        energy_texture_.upload(energy_picture(frame_->frame.absorbed));
        ++frames_shown_;
        last_seconds_ = frame_->seconds;
        if (recording_) {
            cv::Mat sized;
            cv::resize(grey, sized, recording_size_);
            recording_->write(sized);
            ++recorded_frames_;
        }
        if (error_.rfind("could not load", 0) != 0) error_.clear();
    }
    if (auto c = scanner_.take_context()) {
        context_ = std::move(c);
        context_texture_.upload(context_->rgb);
        context_repetitions_ = context_->repetitions;
    }
    // The GPU path: draw the repetitions the worker generated (the worker waits for them).
    // One repetition per UI frame: drawing is the UI thread's time.
    for (int k = 0; k < 1; ++k) {
        std::optional<ContextSplats> batch = scanner_.take_context_splats();
        if (!batch) break;
        try {
            if (!gl_context_ || batch->ensemble != gl_ensemble_ ||
                gl_context_->width() != batch->width || gl_context_->height() != batch->height) {
                gl_context_ = std::make_unique<GlPbvr>(batch->width, batch->height,
                                                       batch->subpixel_level, batch->background);
                gl_ensemble_ = batch->ensemble;
            }
            if (!batch->overlay.empty()) gl_context_->set_overlay(batch->overlay);
            gl_context_->add_repetition(batch->splats);
            gl_camera_ = batch->camera;
            gl_seconds_ = batch->seconds;
            context_repetitions_ = gl_context_->repetitions();
        } catch (const std::exception& e) {
            error_ = std::string("3D context on the GPU: ") + e.what();
            view_.gpu = false;  // the worker's CPU renderer from the next request on
            gl_context_.reset();
            dirty_ = true;
        }
    }
}

void App::handle_keys() {
    const ImGuiIO& io = ImGui::GetIO();
    if (io.WantCaptureKeyboard) return;
    const double step = io.KeyShift ? 5.0 : 1.0, angle = io.KeyShift ? 10.0 : 2.0;
    if (ImGui::IsKeyPressed(GLFW_KEY_LEFT)) move_probe(-step, 0, 0, 0);
    if (ImGui::IsKeyPressed(GLFW_KEY_RIGHT)) move_probe(step, 0, 0, 0);
    if (ImGui::IsKeyPressed(GLFW_KEY_UP)) move_probe(0, step, 0, 0);
    if (ImGui::IsKeyPressed(GLFW_KEY_DOWN)) move_probe(0, -step, 0, 0);
    if (ImGui::IsKeyPressed(GLFW_KEY_Q)) move_probe(0, 0, -angle, 0);
    if (ImGui::IsKeyPressed(GLFW_KEY_E)) move_probe(0, 0, angle, 0);
    if (ImGui::IsKeyPressed(GLFW_KEY_W)) move_probe(0, 0, 0, angle);
    if (ImGui::IsKeyPressed(GLFW_KEY_S) && !io.KeyCtrl) move_probe(0, 0, 0, -angle);
    if (ImGui::IsKeyPressed(GLFW_KEY_SPACE, false)) frozen_ = !frozen_;
    if (ImGui::IsKeyPressed(GLFW_KEY_S, false) && io.KeyCtrl) save_frame();
    if (ImGui::IsKeyPressed(GLFW_KEY_R, false)) toggle_recording();
}

void App::draw(int window_width, int window_height) {
    poll();
    handle_keys();
    if (options_.animate && scene_) {
        // Slide +-15 mm along the surface, about 4 s per sweep at 60 UI frames/s.
        const double previous = 15.0 * std::sin(animate_phase_);
        animate_phase_ += 2.0 * M_PI / 240.0;
        move_probe(15.0 * std::sin(animate_phase_) - previous, 0, 0, 0);
    }
    if (!options_.open_later.empty() && !opened_later_ && frames_shown_ > 0) {
        opened_later_ = true;
        open_path_ = options_.open_later;
        start_loading(open_path_);
    }
    if (dirty_ && !frozen_ && scene_) request();

    const float W = float(window_width), H = float(window_height);
    const float left = std::min(420.0f, 0.3f * W), status = 28.0f;
    const float controls_h = 0.74f * (H - status);
    draw_controls(0, 0, left, controls_h);
    draw_explain(0, controls_h, left, H - status - controls_h);
    const float vw = 0.5f * (W - left), vh = 0.5f * (H - status);
    draw_slice(left, 0, vw, vh);
    draw_bmode(left + vw, 0, vw, vh);
    draw_context(left, vh, vw, vh);
    draw_energy(left + vw, vh, vw, vh);
    draw_status(0, H - status, W, status);
}

bool App::highlight_begin(Control control) {
    if (control != highlighted_ || control == Control::none) return false;
    ImGui::PushStyleColor(ImGuiCol_FrameBg, IM_COL32(150, 100, 10, 255));
    ImGui::PushStyleColor(ImGuiCol_Text, kHighlight);
    return true;
}

void App::highlight_end(bool pushed) {
    if (pushed) ImGui::PopStyleColor(2);
}

void App::draw_controls(float x, float y, float w, float h) {
    begin_panel("Scanner", x, y, w, h, kPanelFlags);
    // Widgets take what the longest label leaves: no label is cut at any window size
    // the panel allows.
    float longest = ImGui::CalcTextSize("receive").x;
    for (const SliderSpec& spec : slider_specs())
        longest = std::max(
            longest,
            ImGui::CalcTextSize((std::string(spec.label) + " (" + spec.unit + ")").c_str()).x);
    ImGui::PushItemWidth(std::max(
        80.0f, ImGui::GetContentRegionAvail().x - longest - ImGui::GetStyle().ItemInnerSpacing.x));
    bool changed = false;
    // -- scene: the whole width, titles are long
    ImGui::TextDisabled("scene");
    ImGui::PushItemWidth(-FLT_MIN);
    if (ImGui::BeginCombo("##scene", scene_ ? scene_->title.c_str() : "")) {
        for (const SceneEntry& e : catalogue_)
            if (ImGui::Selectable(e.title.c_str(), scene_ && scene_->name == e.name))
                start_loading(e.name);
        ImGui::EndCombo();
    }
    ImGui::PopItemWidth();
    tooltip(scene_ ? scene_->description : "");
    ImGui::InputText("##open", &open_path_);
    tooltip(
        "a volume (NIfTI .nii/.nii.gz, DICOM, raw .json header, image stack) or a phantom "
        ".json");
    ImGui::SameLine();
    if (ImGui::Button("open file") && !open_path_.empty()) start_loading(open_path_);
    if (loading_.valid()) ImGui::TextDisabled("loading %s ...", loading_name_.c_str());
    if (scene_) draw_volume_controls();

    // -- probe
    section("probe");
    if (ImGui::BeginCombo("preset", probe_preset_.c_str())) {
        for (const probe::Transducer& t : probe::transducer_presets()) {
            if (ImGui::Selectable(t.name.c_str(), t.name == probe_preset_)) {
                probe_preset_ = t.name;
                parameters_.transducer = t;
                changed = true;
            }
            tooltip(t.description);
        }
        ImGui::EndCombo();
    }
    probe::Transducer& t = parameters_.transducer;
    auto slider_double = [&](Control c, double* value, double lo, double hi, const char* format) {
        const SliderSpec& spec = slider(c);
        const bool pushed = highlight_begin(c);
        const std::string label =
            std::string(spec.label) + (spec.unit[0] ? std::string(" (") + spec.unit + ")" : "");
        const bool moved =
            ImGui::SliderScalar(label.c_str(), ImGuiDataType_Double, value, &lo, &hi, format);
        highlight_end(pushed);
        tooltip(spec.help);
        *value = std::clamp(*value, lo, hi);  // typed-in values too
        changed |= moved;
    };
    const SliderSpec& depth = slider(Control::depth);
    slider_double(Control::depth, &t.depth_mm, depth.min, depth.max, "%.0f");
    const SliderSpec& focus = slider(Control::focus);
    slider_double(Control::focus, &t.focus_mm, focus.min, slider_max(Control::focus, t), "%.0f");
    const SliderSpec& frequency = slider(Control::frequency);
    slider_double(Control::frequency, &t.frequency_mhz, frequency.min, frequency.max, "%.1f");
    {
        const SliderSpec& lines = slider(Control::lines);
        double value = t.lines;
        slider_double(Control::lines, &value, lines.min, lines.max, "%.0f");
        t.lines = int(std::lround(value));
    }
    if (probe::array_type(t.type).fov_adjustable) {
        const SliderSpec& fov = slider(Control::fov);
        slider_double(Control::fov, &t.fov_deg, fov.min, slider_max(Control::fov, t), "%.0f");
    }

    // -- image
    section("image");
    const SliderSpec& gain = slider(Control::gain);
    slider_double(Control::gain, &parameters_.gain_db, gain.min, gain.max, "%.0f");
    const SliderSpec& range = slider(Control::dynamic_range);
    slider_double(Control::dynamic_range, &parameters_.dynamic_range_db, range.min, range.max,
                  "%.0f");
    {
        const SliderSpec& tgc = slider(Control::tgc);
        const bool pushed = highlight_begin(Control::tgc);
        ImGui::TextUnformatted("TGC (dB) at depth (mm)");
        highlight_end(pushed);
        tooltip(tgc.help);
        const float slider_w = std::max(22.0f, ImGui::CalcTextSize("160").x + 4.0f);
        for (int k = 0; k < kTgcSliders; ++k) {
            if (k) ImGui::SameLine();
            float v = float(parameters_.tgc_db[std::size_t(k)]);
            const double at_mm = t.depth_mm * (k + 0.5) / kTgcSliders;
            ImGui::PushID(k);
            ImGui::BeginGroup();
            const bool p2 = highlight_begin(Control::tgc);
            if (ImGui::VSliderFloat("##tgc", ImVec2(slider_w, 70), &v, float(tgc.min),
                                    float(tgc.max), v == 0.0f ? "" : "%+.0f")) {
                parameters_.tgc_db[std::size_t(k)] = std::clamp(double(v), tgc.min, tgc.max);
                changed = true;
            }
            highlight_end(p2);
            if (ImGui::IsItemHovered())
                ImGui::SetTooltip("%.0f mm: %+.0f dB on top of the automatic curve", at_mm, v);
            const std::string depth_text = std::to_string(int(std::lround(at_mm)));
            ImGui::SetCursorPosX(ImGui::GetCursorPosX() +
                                 0.5f * (slider_w - ImGui::CalcTextSize(depth_text.c_str()).x));
            ImGui::TextDisabled("%s", depth_text.c_str());
            ImGui::EndGroup();
            ImGui::PopID();
        }
        ImGui::SameLine();
        if (ImGui::Button("reset##tgc")) {
            parameters_.tgc_db.fill(0.0);
            changed = true;
        }
    }
    {
        const int q = int(parameters_.quality);
        if (ImGui::BeginCombo("quality", quality_label(parameters_.quality).c_str())) {
            for (int k = 0; k <= int(imaging::Quality::high); ++k)
                if (ImGui::Selectable(quality_label(imaging::Quality(k)).c_str(), k == q)) {
                    parameters_.quality = imaging::Quality(k);
                    changed = true;
                }
            ImGui::EndCombo();
        }
        tooltip(
            "particles per scan line and map pixel (mm) while the probe moves; a still "
            "probe refines up to high by itself");
    }

    // -- physics
    section("physics");
    {
        int receive = int(parameters_.receive);
        const bool pushed = highlight_begin(Control::receive);
        const char* receive_names[] = {"monostatic", "capture (probe face)"};
        if (ImGui::Combo("receive", &receive, receive_names, 2)) {
            parameters_.receive = imaging::ReceiveModel(receive);
            changed = true;
        }
        highlight_end(pushed);
        tooltip(switch_help(Control::receive));
    }
    {
        bool slab = parameters_.trace_dimensions == 3;
        const bool pushed = highlight_begin(Control::trace);
        if (ImGui::Checkbox("trace in 3D (slice thickness)", &slab)) {
            parameters_.trace_dimensions = slab ? 3 : 2;
            changed = true;
        }
        highlight_end(pushed);
        tooltip(switch_help(Control::trace));
    }
    PhysicsSwitches& s = parameters_.physics;
    auto toggle = [&](Control c, const char* label, bool* value) {
        const bool pushed = highlight_begin(c);
        changed |= ImGui::Checkbox(label, value);
        highlight_end(pushed);
        tooltip(switch_help(c));
    };
    if (ImGui::BeginTable("switches", 2)) {
        ImGui::TableNextColumn();
        toggle(Control::refraction, "refraction", &s.refraction);
        ImGui::TableNextColumn();
        toggle(Control::specular_reflection, "specular reflection", &s.specular_reflection);
        ImGui::TableNextColumn();
        toggle(Control::diffuse_reflection, "diffuse reflection", &s.diffuse_reflection);
        ImGui::TableNextColumn();
        toggle(Control::scattering, "scattering", &s.scattering);
        ImGui::TableNextColumn();
        toggle(Control::attenuation, "attenuation", &s.attenuation);
        ImGui::TableNextColumn();
        toggle(Control::shear_conversion, "shear waves in bone", &s.shear_conversion);
        ImGui::TableNextColumn();
        toggle(Control::multiple_bounces, "multiple bounces", &s.multiple_bounces);
        ImGui::TableNextColumn();
        ImGui::BeginDisabled(parameters_.receive != imaging::ReceiveModel::capture);
        toggle(Control::face_reflection, "face reflection", &s.face_reflection);
        ImGui::EndDisabled();
        ImGui::EndTable();
    }

    // -- probe motion and output
    section("probe pose");
    if (ImGui::Button("<")) move_probe(-2, 0, 0, 0);
    ImGui::SameLine();
    if (ImGui::Button(">")) move_probe(2, 0, 0, 0);
    ImGui::SameLine();
    if (ImGui::Button("rotate -")) move_probe(0, 0, -5, 0);
    ImGui::SameLine();
    if (ImGui::Button("rotate +")) move_probe(0, 0, 5, 0);
    ImGui::SameLine();
    if (ImGui::Button("tilt -")) move_probe(0, 0, 0, -5);
    ImGui::SameLine();
    if (ImGui::Button("tilt +")) move_probe(0, 0, 0, 5);
    if (ImGui::Button("reset pose")) {
        pose_ = scene_->start.pose;
        changed = true;
    }
    ImGui::SameLine();
    ImGui::Checkbox("freeze", &frozen_);
    tooltip("stop scanning (space); the last frame stays");
    ImGui::SameLine();
    if (ImGui::Button("save frame")) save_frame();
    tooltip("PNG + JSON sidecar in " + options_.out_dir + " (Ctrl+S)");
    ImGui::SameLine();
    if (ImGui::Button(recording_ ? "stop clip" : "record clip")) toggle_recording();
    tooltip("H.264 MP4 of the B-mode frames in " + options_.out_dir + " (R)");
    if (ImGui::Checkbox("3D context view", &view_.enabled)) changed = true;
    ImGui::TextDisabled("keys: arrows slide, Q/E rotate, W/S tilt, shift = larger steps");
    ImGui::TextDisabled("mouse: drag the slice to slide, wheel rotates (shift: tilts);");
    ImGui::TextDisabled("drag the 3D view to orbit, wheel zooms");
    if (changed) dirty_ = true;
    ImGui::PopItemWidth();
    ImGui::End();
}

void App::draw_explain(float x, float y, float w, float h) {
    begin_panel("Explain: what you see and why", x, y, w, h, kPanelFlags);
    if (scene_) {
        ImGui::PushTextWrapPos(0.0f);
        ImGui::TextDisabled("%s", scene_->description.c_str());
        Control hovered = Control::none;
        for (const Artifact& a : explain(*scene_, parameters_)) {
            ImGui::Bullet();
            ImGui::SameLine();
            const bool selected = highlighted_ == a.control && a.control != Control::none;
            ImGui::PushStyleColor(ImGuiCol_Text, selected ? kHighlight : IM_COL32_WHITE);
            ImGui::TextUnformatted(a.name.c_str());
            ImGui::PopStyleColor();
            if (selected && scroll_to_highlight_) {
                ImGui::SetScrollHereY(0.1f);
                scroll_to_highlight_ = false;
            }
            if (ImGui::IsItemHovered()) hovered = a.control;
            if (ImGui::IsItemClicked()) highlighted_ = selected ? Control::none : a.control;
            ImGui::Indent();
            ImGui::TextUnformatted(a.why.c_str());
            ImGui::TextDisabled("try: %s", a.how.c_str());
            if (ImGui::IsItemHovered()) hovered = a.control;
            ImGui::Unindent();
        }
        // Hovering an artifact highlights its control; clicking keeps it highlighted.
        if (hovered != Control::none) highlighted_ = hovered;
        ImGui::PopTextWrapPos();
    }
    ImGui::End();
}

void App::draw_slice(float x, float y, float w, float h) {
    begin_panel("Tissue under the probe (beams of a few scan lines)", x, y, w, h, kViewFlags);
    if (frame_ && !slice_texture_.empty()) {
        const Fit fit = show_image(slice_texture_, &slice_rect_);
        const ImVec2 size = fit.size;
        ImDrawList* draw = ImGui::GetWindowDrawList();
        const double texel = frame_->grid.geometry.spacing.x;
        auto to_screen = [&](glm::dvec2 map) {
            return ImVec2(fit.origin.x + float(map.x / texel) * fit.scale,
                          fit.origin.y + float(map.y / texel) * fit.scale);
        };
        // Beams: the particles of a few lines, brighter while they carry energy.
        std::vector<ImVec2> points;
        // At most 8 particles a line and 100 segments a path: cheap to draw at any quality.
        const int per_line = imaging::quality_level(frame_->quality).particles_per_line;
        const uint32_t every = uint32_t(std::max(1, per_line / 8));
        for (const auto& path : frame_->frame.paths) {
            if (path.vertices.size() < 2 || path.particle % every != 0) continue;
            const float e0 = std::max(path.vertices.front().energy, 1e-30f);
            const std::size_t n = path.vertices.size(), stride = (n + 99) / 100;
            for (std::size_t k = stride; k < n + stride - 1; k += stride) {
                const auto& a = path.vertices[k - stride];
                const auto& b = path.vertices[std::min(k, n - 1)];
                const float alpha = std::clamp(std::sqrt(b.energy / e0), 0.15f, 1.0f);
                draw->AddLine(to_screen(glm::dvec2(a.position)), to_screen(glm::dvec2(b.position)),
                              IM_COL32(255, 220, 60, int(160 * alpha)), 1.0f);
            }
        }
        // The sector and the probe body above the face.
        points.clear();
        for (const glm::dvec2& p : sector_outline(frame_->settings.transducer))
            points.push_back(to_screen(p + frame_->grid.to_map));
        draw->AddPolyline(points.data(), int(points.size()), IM_COL32(90, 200, 255, 160),
                          ImDrawFlags_Closed, 1.0f);
        const double half = 0.5 * frame_->settings.transducer.array_length_mm();
        const glm::dvec2 face = frame_->grid.to_map;
        const probe::ScanGeometry scan(frame_->settings.transducer);
        if (scan.closed()) {  // a ring of elements round a tip: the tip's disc
            const double r = scan.array().face_radius_mm();
            const ImVec2 centre = to_screen(face + glm::dvec2(0.0, -r));
            const float radius = to_screen(face + glm::dvec2(r, -r)).x - centre.x;
            draw->AddCircleFilled(centre, radius, IM_COL32(60, 70, 80, 230), 48);
            draw->AddCircle(centre, radius, kProbeColour, 48, 2.0f);
        } else {
            draw->AddRectFilled(to_screen(face + glm::dvec2(-half, -frame_->grid.top_margin_mm)),
                                to_screen(face + glm::dvec2(half, 0.0)), IM_COL32(60, 70, 80, 230));
            draw->AddRect(to_screen(face + glm::dvec2(-half, -frame_->grid.top_margin_mm)),
                          to_screen(face + glm::dvec2(half, 0.0)), kProbeColour, 0.0f, 0, 2.0f);
        }
        // Legend: the tissues of this slice, largest first, over the image's lower left.
        {
            const float line = ImGui::GetTextLineHeight(), pad = 4.0f;
            std::vector<std::pair<int, std::string>> rows;
            for (const auto& [label, share] : frame_->tissues)
                if (rows.size() < 10 && share > 1e-4)
                    rows.emplace_back(label, short_tissue_name(label));
            float widest = 0.0f;
            for (const auto& row : rows)
                widest = std::max(widest, ImGui::CalcTextSize(row.second.c_str()).x);
            const ImVec2 box(widest + line + 3 * pad, float(rows.size()) * line + 2 * pad);
            const ImVec2 corner(fit.origin.x + pad, fit.origin.y + size.y - box.y - pad);
            draw->AddRectFilled(corner, ImVec2(corner.x + box.x, corner.y + box.y),
                                IM_COL32(20, 20, 24, 200), 3.0f);
            for (std::size_t k = 0; k < rows.size(); ++k) {
                const float yy = corner.y + pad + float(k) * line;
                draw->AddRectFilled(ImVec2(corner.x + pad, yy + 2),
                                    ImVec2(corner.x + pad + line - 4, yy + line - 2),
                                    label_colour_u32(rows[k].first));
                draw->AddRect(ImVec2(corner.x + pad, yy + 2),
                              ImVec2(corner.x + pad + line - 4, yy + line - 2),
                              IM_COL32(120, 120, 120, 255));
                draw->AddText(ImVec2(corner.x + 2 * pad + line, yy), IM_COL32(230, 230, 230, 255),
                              rows[k].second.c_str());
            }
        }
        // Drag to slide the probe along the surface; the wheel rotates (shift: tilts).
        ImGui::SetCursorScreenPos(fit.origin);
        ImGui::InvisibleButton("slice_drag", size);
        const ImGuiIO& io = ImGui::GetIO();
        if (ImGui::IsItemActive() && io.MouseDelta.x != 0.0f)
            move_probe(-io.MouseDelta.x / fit.scale * texel, 0, 0, 0);
        if (ImGui::IsItemHovered() && io.MouseWheel != 0.0f)
            move_probe(0, 0, io.KeyShift ? 0.0 : 3.0 * io.MouseWheel,
                       io.KeyShift ? 3.0 * io.MouseWheel : 0.0);
    } else {
        ImGui::TextDisabled("scanning ...");
    }
    ImGui::End();
}

void App::draw_bmode(float x, float y, float w, float h) {
    begin_panel("B-mode", x, y, w, h, kViewFlags);
    if (frame_ && !bmode_texture_.empty()) {
        ImGui::Text("%s  %.0f ms", imaging::to_string(frame_->quality).c_str(),
                    1e3 * frame_->seconds);
        const Fit fit = show_image(bmode_texture_, &bmode_rect_);
        const ImVec2 size = fit.size;
        // Depth scale every 10 mm.
        ImDrawList* draw = ImGui::GetWindowDrawList();
        const imaging::ScanConverted& image = frame_->frame.image;
        for (int d = 0; d <= int(frame_->settings.transducer.depth_mm); d += 10) {
            const float yy =
                fit.origin.y + float((d - image.origin.y) / image.pixel_mm) * fit.scale;
            if (yy < fit.origin.y || yy > fit.origin.y + size.y) continue;
            draw->AddLine(ImVec2(fit.origin.x, yy), ImVec2(fit.origin.x + 6, yy),
                          IM_COL32(200, 200, 200, 255));
            if (d % 20 == 0)
                draw->AddText(ImVec2(fit.origin.x + 8, yy - 7), IM_COL32(200, 200, 200, 255),
                              (std::to_string(d) + " mm").c_str());
        }
        // Echo level: the grey scale's dB below the level that shows white (the dynamic
        // range maps linearly in dB onto black..white).
        const double range_db = frame_->settings.imaging.dynamic_range_db;
        const float bar_h = std::min(200.0f, 0.45f * size.y);
        std::vector<std::pair<float, std::string>> ticks;
        const int step = range_db > 60.0 ? 20 : 10;
        for (int db = 0; db <= int(range_db); db += step)
            ticks.emplace_back(float(db / range_db), db == 0 ? "0 dB" : "-" + std::to_string(db));
        colour_bar(
            draw, ImVec2(fit.origin.x + size.x - 18, fit.origin.y + ImGui::GetTextLineHeight() + 6),
            ImVec2(12, bar_h), {IM_COL32(255, 255, 255, 255), IM_COL32(0, 0, 0, 255)}, ticks,
            "echo");
        // The depth gain the frame was made with (gain + automatic TGC + sliders): what
        // brightens the deep image is drawn beside it, 1 px per dB from the depth scale.
        std::vector<ImVec2> curve;
        const probe::Transducer& tr = frame_->settings.transducer;
        const double gain_db = frame_->settings.imaging.gain_db;
        double deepest_db = 0.0;
        for (int k = 0; k <= 64; ++k) {
            const double d = tr.depth_mm * k / 64.0;
            const double db = gain_db + imaging::tgc_gain_db(frame_->settings.imaging.tgc, d);
            deepest_db = db;
            const float yy =
                fit.origin.y + float((d - image.origin.y) / image.pixel_mm) * fit.scale;
            curve.push_back(ImVec2(fit.origin.x + 60 + float(std::max(0.0, db)), yy));
        }
        draw->AddPolyline(curve.data(), int(curve.size()), IM_COL32(255, 200, 60, 220), 0, 1.5f);
        char gain_text[48];
        std::snprintf(gain_text, sizeof gain_text, "gain + TGC %+.0f dB", deepest_db);
        draw->AddText(ImVec2(curve.back().x + 4, curve.back().y - ImGui::GetTextLineHeight()),
                      IM_COL32(255, 200, 60, 255), gain_text);
    } else {
        ImGui::TextDisabled("scanning ...");
    }
    ImGui::End();
}

void App::draw_context(float x, float y, float w, float h) {
    begin_panel("3D context (particle-based volume rendering)", x, y, w, h, kViewFlags);
    if (!view_.enabled) {
        ImGui::TextDisabled("off (probe pose panel)");
    } else if ((gl_context_ && gl_context_->repetitions() > 0) ||
               (context_ && !context_texture_.empty())) {
        const bool gpu = gl_context_ && gl_context_->repetitions() > 0;
        ImGui::Text("%d repetitions, %.1f s (%s)", context_repetitions_,
                    gpu ? gl_seconds_ : context_->seconds, gpu ? "GPU" : "CPU");
        const Fit fit =
            gpu ? show_image(reinterpret_cast<void*>(uintptr_t(gl_context_->texture())),
                             gl_context_->width(), gl_context_->height(), &context_rect_)
                : show_image(context_texture_, &context_rect_);
        const ImVec2 size = fit.size;
        // The live probe sector, projected with the image's camera (drawn at once, before
        // the renderer catches up).
        const imaging::pbvr::OrbitCamera& cam = gpu ? gl_camera_ : context_->camera;
        const glm::dvec3 eye = cam.eye(), fwd = cam.forward(), right = cam.right(), up = cam.up();
        const double focal = cam.focal_px();
        std::vector<ImVec2> points;
        for (const glm::dvec2& p : sector_outline(parameters_.transducer)) {
            const glm::dvec3 world = pose_.position + p.x * pose_.lateral() + p.y * pose_.axial();
            const glm::dvec3 v = world - eye;
            const double z = glm::dot(v, fwd);
            if (z <= 1e-3) continue;
            const double px = glm::dot(v, right) / z * focal + 0.5 * cam.width;
            const double py = -glm::dot(v, up) / z * focal + 0.5 * cam.height;
            points.push_back(
                ImVec2(fit.origin.x + float(px) * fit.scale, fit.origin.y + float(py) * fit.scale));
        }
        ImGui::GetWindowDrawList()->AddPolyline(points.data(), int(points.size()), kProbeColour,
                                                ImDrawFlags_Closed, 1.5f);
        ImGui::SetCursorScreenPos(fit.origin);
        ImGui::InvisibleButton("orbit", size);
        const ImGuiIO& io = ImGui::GetIO();
        if (ImGui::IsItemActive() && (io.MouseDelta.x != 0.0f || io.MouseDelta.y != 0.0f)) {
            view_.azimuth_deg -= 0.4 * io.MouseDelta.x;
            view_.elevation_deg =
                std::clamp(view_.elevation_deg + 0.4 * io.MouseDelta.y, -85.0, 85.0);
            dirty_ = true;
        }
        if (ImGui::IsItemHovered() && io.MouseWheel != 0.0f) {
            view_.zoom = std::clamp(view_.zoom * std::pow(1.1, double(io.MouseWheel)), 0.5, 4.0);
            dirty_ = true;
        }
    } else {
        ImGui::TextDisabled("rendering ...");
    }
    ImGui::End();
}

void App::draw_energy(float x, float y, float w, float h) {
    begin_panel("Energy deposition (sedimentation)", x, y, w, h, kViewFlags);
    if (frame_ && !energy_texture_.empty()) {
        const Fit fit = show_image(energy_texture_, &energy_rect_);
        // The colour map's scale: 40 dB below the peak deposit (energy_picture).
        static const std::vector<ImU32> inferno = [] {
            cv::Mat ramp(1, 9, CV_8U), bgr;
            for (int k = 0; k < 9; ++k) ramp.at<uint8_t>(0, k) = uint8_t(255 - 255 * k / 8);
            cv::applyColorMap(ramp, bgr, cv::COLORMAP_INFERNO);
            std::vector<ImU32> out;
            for (int k = 0; k < 9; ++k) {
                const cv::Vec3b c = bgr.at<cv::Vec3b>(0, k);
                out.push_back(IM_COL32(c[2], c[1], c[0], 255));
            }
            return out;
        }();
        colour_bar(
            ImGui::GetWindowDrawList(),
            ImVec2(fit.origin.x + fit.size.x - 18, fit.origin.y + ImGui::GetTextLineHeight() + 6),
            ImVec2(12, std::min(160.0f, 0.4f * fit.size.y)), inferno,
            {{0.0f, "peak"}, {0.5f, "-20"}, {1.0f, "-40 dB"}}, "deposit");
    }
    ImGui::End();
}

void App::draw_status(float x, float y, float w, float h) {
    begin_panel("##status", x, y, w, h, kViewFlags | ImGuiWindowFlags_NoTitleBar);
    const ImGuiIO& io = ImGui::GetIO();
    ImGui::Text("UI %.0f frames/s", io.Framerate);
    ImGui::SameLine(150);
    if (frame_) {
        ImGui::Text("frame %llu: %s, %.0f ms, %.1f M particle-steps",
                    (unsigned long long)frames_shown_, imaging::to_string(frame_->quality).c_str(),
                    1e3 * frame_->seconds, 1e-6 * double(frame_->frame.stats.steps));
        ImGui::SameLine();
    }
    if (frozen_) {
        ImGui::TextColored(ImVec4(0.4f, 0.8f, 1.0f, 1.0f), "FROZEN");
        ImGui::SameLine();
    }
    if (recording_) {
        ImGui::TextColored(ImVec4(1.0f, 0.3f, 0.3f, 1.0f), "REC %d frames", recorded_frames_);
        ImGui::SameLine();
    }
    if (!error_.empty())
        ImGui::TextColored(ImVec4(1.0f, 0.35f, 0.3f, 1.0f), "%s", error_.c_str());
    else if (!message_.empty())
        ImGui::TextDisabled("%s", message_.c_str());
    ImGui::End();
}

void App::save_frame() {
    if (!frame_) return;
    try {
        const std::filesystem::path dir(options_.out_dir);
        int n = 0;
        while (std::filesystem::exists(dir / ("frame_" + std::to_string(n) + ".png"))) ++n;
        const std::string stem = (dir / ("frame_" + std::to_string(n))).string();
        base::OutputTransaction transaction;
        cv::Mat grey;
        frame_->frame.image.image.convertTo(grey, CV_8U, 255.0);
        imaging::write_png(grey, transaction.stage(stem + ".png"));
        const imaging::ScanConverted& image = frame_->frame.image;
        const nlohmann::json record = {
            {"command", "sonotrace-gui"},
            {"version", SONOTRACE_VERSION},
            {"seed", frame_->settings.seed},
            {"scene", scene_->name},
            {"probe", scene::transducer_json(frame_->settings.transducer)},
            {"pose", scene::pose_json(frame_->pose)},
            {"quality", imaging::to_string(frame_->quality)},
            {"trace", frame_->settings.trace_dimensions == 3 ? "3d" : "2d"},
            {"transfer_function",
             scene_->volume ? scene_->volume->tf->describe() : nlohmann::json(nullptr)},
            {"image",
             {{"width", image.image.cols},
              {"height", image.image.rows},
              {"pixel_spacing_mm", {image.pixel_mm, image.pixel_mm}},
              {"origin_mm", {image.origin.x, image.origin.y}},
              {"gain_db", frame_->settings.imaging.gain_db},
              {"dynamic_range_db", frame_->settings.imaging.dynamic_range_db}}},
            {"physics",
             {{"refraction", parameters_.physics.refraction},
              {"specular_reflection", parameters_.physics.specular_reflection},
              {"diffuse_reflection", parameters_.physics.diffuse_reflection},
              {"scattering", parameters_.physics.scattering},
              {"attenuation", parameters_.physics.attenuation},
              {"shear_conversion", parameters_.physics.shear_conversion},
              {"multiple_bounces", parameters_.physics.multiple_bounces},
              {"receive", imaging::to_string(frame_->settings.receive)}}},
            {"timings_s", frame_->frame.timings}};
        base::jsonio::write_json(record, transaction.stage(stem + ".json"));
        transaction.commit();
        message_ = "saved " + stem + ".png and .json";
    } catch (const std::exception& e) {
        error_ = std::string("could not save the frame: ") + e.what();
    }
}

void App::toggle_recording() {
    if (recording_) {
        recording_->close();
        message_ = "wrote " + recording_path_ + " (" + std::to_string(recorded_frames_) +
                   " frames, " + recording_->codec() + ")";
        recording_.reset();
        return;
    }
    if (!frame_) return;
    std::error_code error;
    std::filesystem::create_directories(options_.out_dir, error);
    recording_size_ = frame_->frame.image.image.size();
    // H.264 in MP4 plays in browsers and slides; Motion JPEG in AVI where FFmpeg writes
    // no MP4 at all.
    for (const char* container : {"mp4", "avi"}) {
        int n = 0;
        auto name = [&] {
            return (std::filesystem::path(options_.out_dir) /
                    ("clip_" + std::to_string(n) + "." + container))
                .string();
        };
        while (std::filesystem::exists(name())) ++n;
        recording_path_ = name();
        try {
            recording_.emplace(recording_path_, container, 10.0, recording_size_);
            break;
        } catch (const std::exception& e) {
            error_ = e.what();
        }
    }
    if (!recording_) return;
    recorded_frames_ = 0;
    message_ = "recording " + recording_path_ + " (" + recording_->codec() + ")" +
               (recording_->note().empty() ? "" : ": " + recording_->note());
}

}  // namespace sonotrace::gui
