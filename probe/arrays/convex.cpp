// Convex (curvilinear) array: the elements lie on an arc of radius R (centre of curvature
// (0, -R)), and L lines leave it along its normals, evenly over the field of view:
// line l at angle u_l = -fov/2 + (l + 1/2) fov / L from the axis (ArcArray). A line's
// active aperture is centred on its foot, u_l R along the arc (clipped by the array's
// ends at the edge lines). The lines cannot fan wider than the arc the elements cover.
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/base/error.h"

namespace sonotrace::probe::arrays {
namespace {

// The arc spans the field of view.
class ConvexArray final : public ArcArray {
  public:
    explicit ConvexArray(const Transducer& t)
        : ArcArray(t.radius_mm, t.fov_deg * std::numbers::pi / 180.0, t.lines) {}
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
    base::require_in_range(source, "radius", t.radius_mm, 1.0, 1000.0, "mm");
    const double arc_deg = t.array_length_mm() / t.radius_mm * 180.0 / std::numbers::pi;
    base::require_in_range(source, "fov", t.fov_deg, 1e-3, 180.0, "degrees");
    if (t.fov_deg > arc_deg + 1e-9) {
        throw base::InputError(source, "fov",
                               "the field of view (" + base::number_text(t.fov_deg) +
                                   " degrees) is wider than the array's arc (" +
                                   base::number_text(arc_deg) + " degrees = elements * " +
                                   "pitch / radius)");
    }
}

}  // namespace sonotrace::probe::arrays
