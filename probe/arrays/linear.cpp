// Linear array: L parallel scan lines, evenly over the array's length A = elements x
// pitch, each perpendicular to the flat face: line l runs from (x_l, 0) along +y with
// x_l = -A/2 + (l + 1/2) A / L. Its active aperture is centred on x_l (clipped by the
// array's ends at the edge lines).
#include <cmath>

#include "probe/array_geometry.h"

namespace sonotrace::probe::arrays {
namespace {

class LinearArray final : public ArrayGeometry {
  public:
    explicit LinearArray(const Transducer& t) : span_(t.array_length_mm()), lines_(t.lines) {}

    glm::dvec2 point(double l, double depth) const override {
        return {-0.5 * span_ + (l + 0.5) * span_ / lines_, depth};
    }
    ScanLine line(int l) const override { return {point(l, 0.0), {0.0, 1.0}}; }
    glm::dvec2 line_and_depth(const glm::dvec2& p) const override {
        return {(p.x + 0.5 * span_) * lines_ / span_ - 0.5, p.y};
    }
    double line_spacing_mm(double) const override { return span_ / lines_; }

    ArrayPoint face(double s) const override { return {{s, 0.0}, {0.0, 1.0}}; }
    std::optional<double> aperture_centre(const ScanLine& line) const override {
        return line.origin.x;
    }
    ArrayPoint seen_from_line(double, double along, const ScanLine&) const override {
        return {{along, 0.0}, {0.0, 1.0}};
    }

  private:
    double span_;  // the array's length (mm)
    int lines_;
};

}  // namespace

std::unique_ptr<const ArrayGeometry> make_linear(const Transducer& t) {
    return std::make_unique<LinearArray>(t);
}
void validate_linear(const Transducer&, const std::string&) {}
double no_fov(const Transducer&) {
    return 0.0;
}

}  // namespace sonotrace::probe::arrays
