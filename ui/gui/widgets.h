#pragma once
// The GUI's drawing helpers (Dear ImGui), shared by its panels (gui_app.cpp) and its
// views of the frame, slice, context and energy (gui_views.cpp).
#include <imgui.h>

#include <string>
#include <utility>
#include <vector>

#include <glm/glm.hpp>
#include <opencv2/core.hpp>

#include "imaging/simulation.h"
#include "probe/transducer.h"
#include "tissue/volume.h"
#include "ui/gui/gui_app.h"

namespace sonotrace::gui {

inline constexpr ImGuiWindowFlags kPanelFlags =
    ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse |
    ImGuiWindowFlags_NoSavedSettings;
inline constexpr ImGuiWindowFlags kViewFlags =
    kPanelFlags | ImGuiWindowFlags_NoScrollbar | ImGuiWindowFlags_NoScrollWithMouse;
inline const ImU32 kProbeColour = IM_COL32(90, 200, 255, 255);
inline const ImU32 kHighlight = IM_COL32(255, 190, 40, 255);

// Where a picture went on the screen.
struct Fit {
    ImVec2 origin, size;
    float scale = 1.0f;  // screen pixels per picture pixel
};

// A fixed window at (x, y) of w x h.
void begin_panel(const char* title, float x, float y, float w, float h, ImGuiWindowFlags flags);
// A titled separator between groups of controls.
void section(const char* title);
// `text` as the last item's tooltip (wrapped), when it is hovered.
void tooltip(const std::string& text);
// A vertical colour bar at `at` (top left) of `size`, `colours` from top to bottom, a
// tick and its text at each (fraction from the top, text), written to the bar's left.
void colour_bar(ImDrawList* draw, ImVec2 at, ImVec2 size, const std::vector<ImU32>& colours,
                const std::vector<std::pair<float, std::string>>& ticks, const char* title);
// A tissue's name as a legend shows it: the table's human name without its parenthesis.
std::string short_tissue_name(int label);
ImU32 label_colour_u32(int label);
// Points of a scan sector's outline in the probe plane (mm): the first line, the far
// arc, the last line, the face; for an array closed on itself, the far circle.
std::vector<glm::dvec2> sector_outline(const probe::Transducer& t);
std::string quality_label(imaging::Quality q);
// The absorbed energy as a picture (log scale).
cv::Mat energy_picture(const tissue::Volume& absorbed);
// Draws a picture as large as the window's content region allows, at its aspect,
// centred horizontally; `rect` receives its screen rectangle.
Fit show_image(void* texture, int width, int height, Rect* rect);
Fit show_image(const Texture& texture, Rect* rect);

}  // namespace sonotrace::gui
