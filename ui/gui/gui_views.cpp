// The application's views: the tissue slice, the B-mode frame, the 3D context, the
// energy map and the status line (its panels of controls are in gui_app.cpp, its saved
// frames and clips in gui_output.cpp).
#include <GL/gl.h>
#include <imgui.h>

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "imaging/picture.h"
#include "probe/array_geometry.h"
#include "tissue/tissue_table.h"
#include "ui/gui/gui_app.h"
#include "ui/gui/widgets.h"

namespace sonotrace::gui {

void App::draw_slice(float x, float y, float w, float h) {
    // ImGui keys a window by its title up to "###": the title changes, the panel stays.
    begin_panel(frame_ && frame_->settings.transmit
                    ? "Tissue under the probe (particles of a few transmits)###slice"
                    : "Tissue under the probe (beams of a few scan lines)###slice",
                x, y, w, h, kViewFlags);
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

}  // namespace sonotrace::gui
