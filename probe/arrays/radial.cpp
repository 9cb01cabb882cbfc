// Radial array: the elements ring a catheter or endoscope tip, a circle of radius R whose
// circumference is the array (elements x pitch = 2 pi R), and L lines leave it along its
// normals all around: line l at angle u_l = -pi + (l + 1/2) 2 pi / L from the axis
// (ArcArray over 2 pi; the centre of the circle at (0, -R), the face's apex at the
// origin). A line's active aperture is the arc centred on its foot, at most the half of
// the ring that faces the line; the ring has no ends, so the aperture wraps past
// s = +-pi R, and the last line neighbours the first (scan conversion closes the
// circle). As in intravascular (IVUS) and endobronchial or endoscopic (EBUS, EUS)
// electronic radial probes.
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/base/error.h"

namespace sonotrace::probe::arrays {
namespace {

// The arc is the whole ring, closed on itself.
class RadialArray final : public ArcArray {
  public:
    explicit RadialArray(const Transducer& t)
        : ArcArray(t.radius_mm, 2.0 * std::numbers::pi, t.lines) {}
    bool closed() const override { return true; }
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
    base::require_in_range(source, "radius", t.radius_mm, 0.1, 100.0, "mm");
    const double ring = 2.0 * std::numbers::pi * t.radius_mm;
    // Within 1e-4 (4 um on a 12 mm ring): the seam where the numbering wraps is that far off.
    if (std::abs(t.array_length_mm() - ring) > 1e-4 * ring) {
        throw base::InputError(
            source, "radius",
            "a radial array closes on itself: elements * pitch (" +
                base::number_text(t.array_length_mm()) + " mm) must equal 2 pi * radius (" +
                base::number_text(ring) + " mm); set the radius to " +
                base::number_text(t.array_length_mm() / (2.0 * std::numbers::pi)) + " mm");
    }
    if (t.fov_deg != 360.0)
        throw base::InputError(source, "fov",
                               "a radial array images all around: the field of view is 360 "
                               "degrees, got " +
                                   base::number_text(t.fov_deg));
}

}  // namespace sonotrace::probe::arrays
