#include "imaging/pbvr/colour_tf.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "tissue/base/error.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/json_util.h"

namespace sonotrace::imaging::pbvr {

using base::InputError;
namespace jsonio = base::jsonio;

namespace {

// Opacity 1 would mean infinite extinction.
constexpr double kMaxOpacity = 1.0 - 1e-6;

// Colin27 T1 intensities (normalized by the 99th percentile, raw 164; see
// tissue/presets/mri-t1-head.json): air 0, skull core 0.06-0.11, ventricular CSF
// 0.15-0.22, grey matter ~0.5, white matter ~0.68, scalp fat and marrow >= 0.9.
constexpr const char* kHeadPreset = R"({
  "name": "head",
  "description": "T1 head MRI: skin and scalp tan, the skull band ivory, CSF clear (sulci and ventricles open), grey matter rose, white matter pale; opacity per 1 mm",
  "normalization": {"low_quantile": 0.0, "high_quantile": 0.99},
  "unit_length_mm": 1.0,
  "points": [
    {"value": 0.00, "colour": [0.0, 0.0, 0.0], "opacity": 0.0},
    {"value": 0.04, "colour": [0.95, 0.93, 0.86], "opacity": 0.0},
    {"value": 0.07, "colour": [0.96, 0.94, 0.86], "opacity": 0.6},
    {"value": 0.11, "colour": [0.96, 0.94, 0.86], "opacity": 0.6},
    {"value": 0.15, "colour": [0.5, 0.6, 0.8], "opacity": 0.0},
    {"value": 0.30, "colour": [0.7, 0.4, 0.4], "opacity": 0.0},
    {"value": 0.45, "colour": [0.78, 0.42, 0.42], "opacity": 0.25},
    {"value": 0.68, "colour": [0.93, 0.85, 0.78], "opacity": 0.4},
    {"value": 0.80, "colour": [0.86, 0.62, 0.48], "opacity": 0.5},
    {"value": 1.00, "colour": [0.88, 0.66, 0.52], "opacity": 0.7}
  ]
})";

constexpr const char* kRampPreset = R"({
  "name": "ramp",
  "description": "grey, opacity rising linearly from 0 to 0.2 per voxel over the window",
  "normalization": {"low_quantile": 0.0, "high_quantile": 1.0},
  "unit_length_mm": 1.0,
  "points": [
    {"value": 0.0, "colour": [0.2, 0.2, 0.2], "opacity": 0.0},
    {"value": 1.0, "colour": [1.0, 1.0, 1.0], "opacity": 0.2}
  ]
})";

// B-mode grey values (0..255 from a frame's sector mesh): echoes glow amber to white,
// dark tissue stays clear, so the sector shows inside the head without hiding it.
constexpr const char* kBmodePreset = R"({
  "name": "bmode",
  "description": "B-mode grey 0..255: clear below 35 %, amber to white and increasingly opaque above",
  "normalization": {"low_quantile": 0.0, "high_quantile": 1.0},
  "unit_length_mm": 1.0,
  "points": [
    {"value": 0.00, "colour": [0.2, 0.1, 0.0], "opacity": 0.0},
    {"value": 0.35, "colour": [0.6, 0.35, 0.05], "opacity": 0.0},
    {"value": 0.60, "colour": [1.0, 0.7, 0.2], "opacity": 0.35},
    {"value": 1.00, "colour": [1.0, 1.0, 0.85], "opacity": 0.9}
  ]
})";

struct Preset {
    const char* name;
    const char* json;
};
constexpr Preset kPresets[] = {
    {"head", kHeadPreset}, {"ramp", kRampPreset}, {"bmode", kBmodePreset}};

}  // namespace

ColourTransferFunction::ColourTransferFunction(std::string name, std::string source,
                                               std::vector<ColourPoint> points,
                                               double unit_length_mm, double low_quantile,
                                               double high_quantile)
    : name_(std::move(name)),
      source_(std::move(source)),
      points_(std::move(points)),
      unit_length_mm_(unit_length_mm),
      low_quantile_(low_quantile),
      high_quantile_(high_quantile) {
    if (points_.size() < 2) throw InputError(source_, "points", "needs at least two points");
    for (std::size_t i = 0; i < points_.size(); ++i) {
        const std::string field = "points[" + std::to_string(i) + "]";
        const ColourPoint& p = points_[i];
        base::require_in_range(source_, (field + ".value").c_str(), p.value, 0.0, 1.0);
        base::require_in_range(source_, (field + ".opacity").c_str(), p.opacity, 0.0, 1.0);
        for (int c = 0; c < 3; ++c)
            base::require_in_range(source_, (field + ".colour").c_str(), p.colour[c], 0.0, 1.0);
        if (i > 0 && !(p.value > points_[i - 1].value))
            throw InputError(source_, field + ".value", "values must increase");
    }
    base::require_in_range(source_, "unit_length_mm", unit_length_mm_, 1e-6, 1e6, "mm");
    if (!(high_quantile_ > low_quantile_))
        throw InputError(source_, "normalization.high_quantile", "must exceed low_quantile");
    build_tables();
}

void ColourTransferFunction::build_tables() {
    for (int e = 0; e < kEntries; ++e) {
        const double s = double(e) / (kEntries - 1);
        // piecewise-linear in the points, clamped outside
        std::size_t i = 0;
        while (i + 2 < points_.size() && s > points_[i + 1].value) ++i;
        const ColourPoint& a = points_[i];
        const ColourPoint& b = points_[i + 1];
        const double t = std::clamp((s - a.value) / (b.value - a.value), 0.0, 1.0);
        const double opacity = std::min(a.opacity + t * (b.opacity - a.opacity), kMaxOpacity);
        const glm::dvec3 colour = glm::mix(glm::dvec3(a.colour), glm::dvec3(b.colour), t);
        sigma_[std::size_t(e)] = float(-std::log(1.0 - opacity) / unit_length_mm_);
        red_[std::size_t(e)] = float(colour.x);
        green_[std::size_t(e)] = float(colour.y);
        blue_[std::size_t(e)] = float(colour.z);
    }
    range_max_.assign(1, sigma_);
    for (int width = 2; width <= kEntries; width *= 2) {
        const auto& below = range_max_.back();
        std::array<float, kEntries> level{};
        for (int e = 0; e + width <= kEntries; ++e)
            level[std::size_t(e)] =
                std::max(below[std::size_t(e)], below[std::size_t(e + width / 2)]);
        range_max_.push_back(level);
    }
    sigma_max_ = *std::max_element(sigma_.begin(), sigma_.end());
}

glm::vec3 ColourTransferFunction::colour(float s) const {
    return {lerp(red_, s), lerp(green_, s), lerp(blue_, s)};
}

float ColourTransferFunction::max_extinction(float s0, float s1) const {
    if (s1 < s0) std::swap(s0, s1);
    // Linear between entries: the maximum is at an end or at an entry inside.
    float result = std::max(extinction(s0), extinction(s1));
    // (integer ceil and floor: std::ceil/std::floor are calls on the x86-64 baseline, and
    // the renderer's set-up asks this of every cell of the volume)
    const int first = base::ceil_to_int(glm::clamp(s0, 0.0f, 1.0f) * float(kEntries - 1));
    const int last = base::floor_to_int(glm::clamp(s1, 0.0f, 1.0f) * float(kEntries - 1));
    if (last >= first) {
        const int span = last - first + 1;
        int level = 0;
        while ((2 << level) <= span) ++level;
        const auto& table = range_max_[std::size_t(level)];
        result = std::max(
            {result, table[std::size_t(first)], table[std::size_t(last - (1 << level) + 1)]});
    }
    return result;
}

void ColourTransferFunction::bind(const tissue::Volume& volume) {
    const float low =
        low_quantile_ == 0.0 ? volume.value_range().first : volume.quantile(low_quantile_);
    const float high =
        high_quantile_ == 1.0 ? volume.value_range().second : volume.quantile(high_quantile_);
    set_window(low, high);
}

ColourTransferFunction ColourTransferFunction::with_extinction_scaled(double factor) const {
    ColourTransferFunction copy = *this;
    for (ColourPoint& p : copy.points_)
        p.opacity = 1.0 - std::pow(1.0 - std::min(p.opacity, kMaxOpacity), factor);
    copy.name_ = name_ + " (opacity edited)";
    copy.build_tables();
    return copy;
}

nlohmann::json ColourTransferFunction::describe() const {
    nlohmann::json points = nlohmann::json::array();
    for (const ColourPoint& p : points_)
        points.push_back({{"value", p.value},
                          {"colour", {p.colour.x, p.colour.y, p.colour.z}},
                          {"opacity", p.opacity}});
    return {{"name", name_},
            {"source", source_},
            {"unit_length_mm", unit_length_mm_},
            {"normalization", {{"low_quantile", low_quantile_}, {"high_quantile", high_quantile_}}},
            {"points", points}};
}

std::vector<std::string> colour_tf_presets() {
    std::vector<std::string> names;
    for (const Preset& p : kPresets) names.emplace_back(p.name);
    return names;
}

ColourTransferFunction parse_colour_tf(const nlohmann::json& j, const std::string& source) {
    jsonio::require_object(j, source, "");
    jsonio::require_known_keys(
        j, {"name", "description", "normalization", "unit_length_mm", "points", "comment"}, source,
        "");
    const std::string name = j.contains("name") ? jsonio::get_string(j, "name", source, "")
                                                : std::filesystem::path(source).stem().string();
    double low = 0.0, high = 1.0;
    if (j.contains("normalization")) {
        const auto& n = j["normalization"];
        jsonio::require_object(n, source, "normalization");
        jsonio::require_known_keys(n, {"low_quantile", "high_quantile"}, source, "normalization");
        low = jsonio::get_optional_number(n, "low_quantile", source, "normalization", 0, 1)
                  .value_or(0.0);
        high = jsonio::get_optional_number(n, "high_quantile", source, "normalization", 0, 1)
                   .value_or(1.0);
    }
    const double unit =
        jsonio::get_optional_number(j, "unit_length_mm", source, "", 1e-6, 1e6).value_or(1.0);
    if (!j.contains("points") || !j["points"].is_array())
        throw InputError(source, "points", "must be an array of {value, colour, opacity}");
    std::vector<ColourPoint> points;
    for (std::size_t i = 0; i < j["points"].size(); ++i) {
        const std::string where = "points[" + std::to_string(i) + "]";
        const auto& p = j["points"][i];
        jsonio::require_object(p, source, where);
        jsonio::require_known_keys(p, {"value", "colour", "opacity", "comment"}, source, where);
        ColourPoint point;
        point.value = jsonio::get_number(p, "value", source, where, 0.0, 1.0);
        point.opacity = jsonio::get_number(p, "opacity", source, where, 0.0, 1.0);
        point.colour = glm::vec3(jsonio::get_vec3(p, "colour", source, where));
        points.push_back(point);
    }
    return ColourTransferFunction(name, source, std::move(points), unit, low, high);
}

ColourTransferFunction load_colour_tf(const std::string& spec) {
    for (const Preset& p : kPresets) {
        if (spec == p.name) return parse_colour_tf(jsonio::parse(p.json, "preset " + spec), spec);
    }
    if (!std::filesystem::exists(spec)) {
        std::string names;
        for (const auto& n : colour_tf_presets()) names += (names.empty() ? "" : ", ") + n;
        throw InputError(spec, "", "no such file, and not a preset (presets: " + names + ")");
    }
    return parse_colour_tf(jsonio::read_file(spec), spec);
}

}  // namespace sonotrace::imaging::pbvr
