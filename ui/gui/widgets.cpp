#include "ui/gui/widgets.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "imaging/picture.h"
#include "probe/array_geometry.h"
#include "tissue/base/error.h"
#include "tissue/tissue_table.h"

namespace sonotrace::gui {

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

}  // namespace sonotrace::gui
