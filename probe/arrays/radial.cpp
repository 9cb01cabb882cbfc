// Radial array: the elements ring a catheter or endoscope tip, a circle of radius R whose
// circumference is the array (elements x pitch = 2 pi R), and L lines leave it along its
// normals all around: line l at angle u_l = -pi + (l + 1/2) 2 pi / L from the axis
// (FanLines over 2 pi; the centre of the circle at (0, -R), the face's apex at the
// origin). An element at arc length s sits at angle phi = s / R, as on a convex arc. A
// line's active aperture is the arc centred on its foot, at most the half of the ring
// that faces the line; the ring has no ends, so the aperture wraps past s = +-pi R, and
// the last line neighbours the
// first (scan conversion closes the circle). As in intravascular (IVUS) and endobronchial
// or endoscopic (EBUS, EUS) electronic radial probes.
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/error.h"

namespace sonotrace::probe::arrays {
namespace {

class RadialArray final : public ArrayGeometry {
  public:
    explicit RadialArray(const Transducer& t)
        : radius_(t.radius_mm), fan_{t.radius_mm, 2.0 * std::numbers::pi, t.lines} {}

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
    ArrayPoint seen_from_line(double, double along, const ScanLine&) const override {
        return face(along);  // the ring turned so that the line's foot is its apex
    }
    bool closed() const override { return true; }
    double face_radius_mm() const override { return radius_; }

  private:
    double radius_;
    FanLines fan_;
};

}  // namespace

std::unique_ptr<const ArrayGeometry> make_radial(const Transducer& t) {
    return std::make_unique<RadialArray>(t);
}

double max_fov_radial(const Transducer&) {
    return 360.0;
}

// The elements within +-90 degrees of a line face it; those beyond face away.
double half_ring(const Transducer& t) {
    return 0.5 * t.array_length_mm();
}

void validate_radial(const Transducer& t, const std::string& source) {
    tissue::require_in_range(source, "radius", t.radius_mm, 0.1, 100.0, "mm");
    const double ring = 2.0 * std::numbers::pi * t.radius_mm;
    // Within 1e-4 (4 um on a 12 mm ring): the seam where the numbering wraps is that far off.
    if (std::abs(t.array_length_mm() - ring) > 1e-4 * ring) {
        throw tissue::InputError(
            source, "radius",
            "a radial array closes on itself: elements * pitch (" +
                tissue::number_text(t.array_length_mm()) + " mm) must equal 2 pi * radius (" +
                tissue::number_text(ring) + " mm); set the radius to " +
                tissue::number_text(t.array_length_mm() / (2.0 * std::numbers::pi)) + " mm");
    }
    if (t.fov_deg != 360.0)
        throw tissue::InputError(source, "fov",
                                 "a radial array images all around: the field of view is 360 "
                                 "degrees, got " +
                                     tissue::number_text(t.fov_deg));
}

}  // namespace sonotrace::probe::arrays
