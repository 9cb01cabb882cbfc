// Convex (curvilinear) array: the elements lie on an arc of radius R (centre of curvature
// (0, -R)), and L lines leave it along its normals, evenly over the field of view:
// line l at angle u_l = -fov/2 + (l + 1/2) fov / L from the axis (FanLines). An element
// at arc length s from the apex sits at angle phi = s / R: (R sin phi, R (cos phi - 1)),
// facing (sin phi, cos phi). A line's active aperture is centred on its foot, u_l R
// along the arc (clipped by the array's ends at the edge lines).
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/error.h"

namespace sonotrace::probe::arrays {
namespace {

class ConvexArray final : public ArrayGeometry {
  public:
    explicit ConvexArray(const Transducer& t)
        : radius_(t.radius_mm), fan_{t.radius_mm, t.fov_deg * std::numbers::pi / 180.0, t.lines} {}

    glm::dvec2 point(double l, double depth) const override { return fan_.point(l, depth); }
    ScanLine line(int l) const override { return fan_.line(l); }
    glm::dvec2 line_and_depth(const glm::dvec2& p) const override { return fan_.line_and_depth(p); }
    double line_spacing_mm(double depth) const override { return fan_.line_spacing_mm(depth); }

    ArrayPoint face(double s) const override {
        const double phi = s / radius_;
        return {{radius_ * std::sin(phi), radius_ * (std::cos(phi) - 1.0)},
                {std::sin(phi), std::cos(phi)}};
    }
    std::optional<double> aperture_centre(const ScanLine& line) const override {
        return std::atan2(line.direction.x, line.direction.y) * radius_;
    }
    // In the line's frame the array is the same arc, turned so that the line's foot is
    // its apex: the element `along` mm of arc from the foot.
    ArrayPoint seen_from_line(double, double along, const ScanLine&) const override {
        return face(along);
    }
    double face_radius_mm() const override { return radius_; }

  private:
    double radius_;
    FanLines fan_;
};

}  // namespace

std::unique_ptr<const ArrayGeometry> make_convex(const Transducer& t) {
    return std::make_unique<ConvexArray>(t);
}

// The arc the elements cover (degrees): the lines cannot fan wider.
double max_fov_convex(const Transducer& t) {
    return t.radius_mm > 0.0 ? t.array_length_mm() / t.radius_mm * 180.0 / std::numbers::pi : 180.0;
}

void validate_convex(const Transducer& t, const std::string& source) {
    tissue::require_in_range(source, "radius", t.radius_mm, 1.0, 1000.0, "mm");
    const double arc_deg = t.array_length_mm() / t.radius_mm * 180.0 / std::numbers::pi;
    tissue::require_in_range(source, "fov", t.fov_deg, 1e-3, 180.0, "degrees");
    if (t.fov_deg > arc_deg + 1e-9) {
        throw tissue::InputError(source, "fov",
                                 "the field of view (" + tissue::number_text(t.fov_deg) +
                                     " degrees) is wider than the array's arc (" +
                                     tissue::number_text(arc_deg) + " degrees = elements * " +
                                     "pitch / radius)");
    }
}

}  // namespace sonotrace::probe::arrays
