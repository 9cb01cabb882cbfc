#pragma once
// The colour and opacity transfer function of the volume renderer.
//
// Control points map a normalized intensity s (0..1 spans the volume's window between
// two quantiles, as the tissue transfer functions do) to a colour and an opacity,
// linearly in between. The opacity alpha is the one of a segment of `unit_length_mm`
// (Sakamoto's Delta t), so the extinction coefficient is
//     sigma(s) = -ln(1 - alpha(s)) / unit_length   (1/mm),
// the particle density of eq. 12 is rho = sigma / (pi r^2), and eq. 11's opacity for
// another length l is 1 - exp(-sigma l). Tables of kEntries samples over 0..1 serve the
// hot loops; the range maximum of sigma gives each cell's majorant for thinning.
#include <array>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "tissue/volume.h"

namespace sonotrace::imaging::pbvr {

struct ColourPoint {
    double value = 0.0;      // normalized intensity 0..1
    glm::vec3 colour{1.0f};  // linear RGB 0..1
    double opacity = 0.0;    // per unit length, 0..1 (1 is clamped to 1 - 1e-6)
};

class ColourTransferFunction {
  public:
    static constexpr int kEntries = 1024;

    ColourTransferFunction() = default;
    // Throws base::InputError(source, field) on bad points (unsorted, out of range,
    // fewer than two) or parameters.
    ColourTransferFunction(std::string name, std::string source, std::vector<ColourPoint> points,
                           double unit_length_mm, double low_quantile, double high_quantile);

    // Sets the intensity window from the volume (quantiles). Required before normalize().
    void bind(const tissue::Volume& volume);
    // Sets it to [low, high] (a volume of indices, whose window the caller knows).
    void set_window(float low, float high) {
        window_low_ = low;
        inverse_window_ = high > low ? 1.0f / (high - low) : 1.0f;
    }
    float normalize(float raw) const {
        return glm::clamp((raw - window_low_) * inverse_window_, 0.0f, 1.0f);
    }

    // Table lookups at s in 0..1 (linear between entries).
    float extinction(float s) const { return lerp(sigma_, s); }  // 1/mm
    glm::vec3 colour(float s) const;
    // Maximum of extinction() over [s0, s1] (exact for the piecewise-linear table).
    float max_extinction(float s0, float s1) const;
    // True if sigma is zero everywhere (nothing would be drawn).
    bool transparent() const { return sigma_max_ == 0.0f; }

    // A copy with every opacity replaced by 1 - (1 - alpha)^factor: the same colours, the
    // extinction scaled by `factor` (an opacity edit, for eq. 13).
    ColourTransferFunction with_extinction_scaled(double factor) const;

    const std::string& name() const { return name_; }
    double unit_length_mm() const { return unit_length_mm_; }
    const std::vector<ColourPoint>& points() const { return points_; }
    nlohmann::json describe() const;

  private:
    static float lerp(const std::array<float, kEntries>& table, float s) {
        const float x = glm::clamp(s, 0.0f, 1.0f) * float(kEntries - 1);
        const int i = std::min(int(x), kEntries - 2);
        const float f = x - float(i);
        return table[std::size_t(i)] + f * (table[std::size_t(i) + 1] - table[std::size_t(i)]);
    }
    void build_tables();

    std::string name_, source_;
    std::vector<ColourPoint> points_;
    double unit_length_mm_ = 1.0, low_quantile_ = 0.0, high_quantile_ = 1.0;
    float window_low_ = 0.0f, inverse_window_ = 1.0f;
    std::array<float, kEntries> sigma_{}, red_{}, green_{}, blue_{};
    // Sparse table for range maxima of sigma_: level l holds max over 2^l entries.
    std::vector<std::array<float, kEntries>> range_max_;
    float sigma_max_ = 0.0f;
};

// Presets compiled in: "head" (Colin27-tuned T1 MRI: scalp, skull band, brain), "ramp"
// (grey, opacity rising linearly; for tests and unknown volumes) and "bmode" (a frame's
// grey values, for its sector mesh).
std::vector<std::string> colour_tf_presets();
// A preset name or a JSON file; throws InputError naming the file and field.
ColourTransferFunction load_colour_tf(const std::string& spec);
ColourTransferFunction parse_colour_tf(const nlohmann::json& j, const std::string& source);

}  // namespace sonotrace::imaging::pbvr
