// Phased array: a flat array of elements at (s, 0) whose delays steer every line from
// the face's centre, L lines evenly over the field of view (FanLines with radius 0). Each
// line uses the whole array; seen from line l, whose direction is (sin u, cos u), an
// element is the flat array turned by -u.
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/base/error.h"

namespace sonotrace::probe::arrays {
namespace {

class PhasedArray final : public ArrayGeometry {
  public:
    explicit PhasedArray(const Transducer& t)
        : fan_{0.0, t.fov_deg * std::numbers::pi / 180.0, t.lines} {}

    glm::dvec2 point(double l, double depth) const override { return fan_.point(l, depth); }
    ScanLine line(int l) const override { return fan_.line(l); }
    glm::dvec2 line_and_depth(const glm::dvec2& p) const override { return fan_.line_and_depth(p); }
    double line_spacing_mm(double depth) const override { return fan_.line_spacing_mm(depth); }

    ArrayPoint face(double s) const override { return {{s, 0.0}, {0.0, 1.0}}; }
    std::optional<double> aperture_centre(const ScanLine&) const override {
        return std::nullopt;  // every line steers the whole array
    }
    ArrayPoint seen_from_line(double s, double, const ScanLine& line) const override {
        const glm::dvec2 across(line.direction.y, -line.direction.x);
        const glm::dvec2 world(s, 0.0), up(0.0, 1.0);
        return {
            {glm::dot(world - line.origin, across), glm::dot(world - line.origin, line.direction)},
            {glm::dot(up, across), glm::dot(up, line.direction)}};
    }

  private:
    FanLines fan_;
};

}  // namespace

std::unique_ptr<const ArrayGeometry> make_phased(const Transducer& t) {
    return std::make_unique<PhasedArray>(t);
}

double max_fov_phased(const Transducer&) {
    return 180.0;  // exclusive: steering reaches +-90 degrees only in the limit
}

void validate_phased(const Transducer& t, const std::string& source) {
    if (!(std::isfinite(t.fov_deg) && t.fov_deg > 0.0 && t.fov_deg < 180.0)) {
        throw base::InputError(
            source, "fov",
            "a phased array steers within (0, 180) degrees, got " + base::number_text(t.fov_deg));
    }
}

}  // namespace sonotrace::probe::arrays
