#include "ui/gui/gui_app.h"
#include "tissue/base/data_dir.h"
#include "ui/gui/widgets.h"

#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_stdlib.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "imaging/picture.h"
#include "probe/array_geometry.h"
#include "probe/pose.h"
#include "tissue/base/error.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::gui {

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
    id_ = gl::texture_2d(GL_RGBA, rgba.cols, rgba.rows, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data, true,
                         id_);
    width_ = rgba.cols;
    height_ = rgba.rows;
}

// ---- the application ----

App::App(const AppOptions& options)
    : options_(options), catalogue_(scene_catalogue(base::phantom_catalogue_dir())) {
    parameters_.quality = imaging::parse_quality(options.quality, "--quality", "");
    if (!options.probe.empty()) probe::find_transducer(options.probe, "--probe");  // validates
    {
        TransmitControls& tx = parameters_.transmit;
        const auto& kinds = TransmitControls::kKinds;
        const auto kind = std::find_if(kinds.begin(), kinds.end(),
                                       [&](const auto& k) { return options.transmit == k.name; });
        if (kind == kinds.end()) {
            std::string names;
            for (const auto& k : kinds) names += (names.empty() ? "" : ", ") + std::string(k.name);
            throw base::InputError("--transmit", options.transmit, "must be one of " + names);
        }
        tx.kind = kind->kind;
        const SliderSpec &count = slider(Control::transmits), &span = slider(Control::span);
        if (!(options.transmits >= count.min && options.transmits <= count.max))
            throw base::InputError("--transmits", std::to_string(options.transmits),
                                   "must be 1 to " + base::number_text(count.max));
        if (!(options.span_deg >= span.min && options.span_deg <= span.max))
            throw base::InputError("--span", base::number_text(options.span_deg),
                                   "must be 0 to " + base::number_text(span.max) + " degrees");
        tx.count = options.transmits;
        tx.span_deg = options.span_deg;
    }
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
    if (!offers_unfocused_transmits(parameters_.transducer) &&
        parameters_.transmit.kind != TransmitControls::Kind::focused) {
        parameters_.transmit.kind = TransmitControls::Kind::focused;
        message_ = "the " + preset + " probe is a closed ring: it transmits focused beams only";
    }
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
            message_.clear();
            apply_scene(loading_.get());
            message_ = "scene " + scene_->title + (message_.empty() ? "" : "; " + message_);
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
                gl_context_ = std::make_unique<gl::GlPbvr>(
                    batch->width, batch->height, batch->subpixel_level, batch->background);
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
                if (!offers_unfocused_transmits(t))
                    parameters_.transmit.kind = TransmitControls::Kind::focused;
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
    // Unfocused transmits have no transmit focus and no scan lines: those sliders rest.
    const bool focused = parameters_.transmit.kind == TransmitControls::Kind::focused;
    ImGui::BeginDisabled(!focused);
    const SliderSpec& focus = slider(Control::focus);
    slider_double(Control::focus, &t.focus_mm, focus.min, slider_max(Control::focus, t), "%.0f");
    ImGui::EndDisabled();
    const SliderSpec& frequency = slider(Control::frequency);
    slider_double(Control::frequency, &t.frequency_mhz, frequency.min, frequency.max, "%.1f");
    {
        ImGui::BeginDisabled(!focused);
        const SliderSpec& lines = slider(Control::lines);
        double value = t.lines;
        slider_double(Control::lines, &value, lines.min, lines.max, "%.0f");
        t.lines = int(std::lround(value));
        ImGui::EndDisabled();
    }
    if (probe::array_type(t.type).fov_adjustable) {
        const SliderSpec& fov = slider(Control::fov);
        slider_double(Control::fov, &t.fov_deg, fov.min, slider_max(Control::fov, t), "%.0f");
    }
    {
        // Focused line by line, or unfocused waves (open arrays, 2D, monostatic receive).
        TransmitControls& tx = parameters_.transmit;
        int kind = int(tx.kind);
        std::array<const char*, TransmitControls::kKinds.size()> kinds;
        for (std::size_t k = 0; k < kinds.size(); ++k) kinds[k] = TransmitControls::kKinds[k].label;
        const bool pushed = highlight_begin(Control::transmit);
        ImGui::BeginDisabled(!offers_unfocused_transmits(t));
        if (ImGui::Combo("transmit", &kind, kinds.data(), int(kinds.size()))) {
            tx.kind = TransmitControls::Kind(kind);
            if (tx.kind != TransmitControls::Kind::focused) {
                parameters_.trace_dimensions = 2;
                parameters_.receive = imaging::ReceiveModel::monostatic;
            }
            changed = true;
        }
        ImGui::EndDisabled();
        highlight_end(pushed);
        tooltip(offers_unfocused_transmits(t)
                    ? switch_help(Control::transmit)
                    : "plane and diverging waves need an open array: choose a linear, "
                      "phased, convex or picmus probe");
        if (tx.kind != TransmitControls::Kind::focused) {
            const SliderSpec& count = slider(Control::transmits);
            double value = tx.count;
            slider_double(Control::transmits, &value, count.min, count.max, "%.0f");
            tx.count = int(std::lround(value));
            const SliderSpec& span = slider(Control::span);
            slider_double(Control::span, &tx.span_deg, span.min, span.max, "%.1f");
        }
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
        const bool unfocused = parameters_.transmit.kind != TransmitControls::Kind::focused;
        ImGui::BeginDisabled(unfocused);  // channel frames receive monostatically
        if (ImGui::Combo("receive", &receive, receive_names, 2)) {
            parameters_.receive = imaging::ReceiveModel(receive);
            changed = true;
        }
        ImGui::EndDisabled();
        highlight_end(pushed);
        tooltip(switch_help(Control::receive));
    }
    {
        bool slab = parameters_.trace_dimensions == 3;
        const bool pushed = highlight_begin(Control::trace);
        // Channel frames are traced in the plane.
        ImGui::BeginDisabled(parameters_.transmit.kind != TransmitControls::Kind::focused);
        if (ImGui::Checkbox("trace in 3D (slice thickness)", &slab)) {
            parameters_.trace_dimensions = slab ? 3 : 2;
            changed = true;
        }
        ImGui::EndDisabled();
        highlight_end(pushed);
        tooltip(switch_help(Control::trace));
    }
    // One toggle per physics switch (simulator/physics_switches.h), its label and help
    // from the row; face reflection only means something with the capture receive model.
    PhysicsSwitches& s = parameters_.physics;
    if (ImGui::BeginTable("switches", 2)) {
        for (const simulator::PhysicsSwitch& sw : simulator::kPhysicsSwitches) {
            ImGui::TableNextColumn();
            const Control c = physics_control(sw.id);
            const bool pushed = highlight_begin(c);
            ImGui::BeginDisabled(sw.id == imaging::Physics::face &&
                                 parameters_.receive != imaging::ReceiveModel::capture);
            bool on = s.on(sw.id);
            const std::string label(sw.label);
            if (ImGui::Checkbox(label.c_str(), &on)) {
                s.set(sw.id, on);
                changed = true;
            }
            ImGui::EndDisabled();
            highlight_end(pushed);
            tooltip(switch_help(c));
        }
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

}  // namespace sonotrace::gui
