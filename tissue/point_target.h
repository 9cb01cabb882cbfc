#pragma once
// Sub-resolution targets (QA wires, point reflectors) as the image sees them: not traced
// and not resolved by the map, but imaged through each scan line's two-way field at their
// exact position (imaging/bmode.h).
//
// Strength: a wire of radius a whose surface reflects the amplitude fraction r back has,
// in the scan plane, the geometric-optics backscatter width sigma = pi a r^2 (mm; the 2D
// echo width of a large cylinder, pi a, times r^2). It holds for ka >~ 1 (a 0.1 mm wire at
// 7.6 MHz: ka = 1.6) and overstates thinner wires, whose Rayleigh echo falls as (ka)^3.
// A point (a small sphere of the same diameter) is a piece of that wire as long as its
// diameter, weighted by the two-way elevation profile of the lens at its offset from the
// scan plane and its depth (probe/elevation.h; unit integral over the elevation: a wire
// straight across the slice sums its points to the wire's echo). A wire crossing the
// plane obliquely is its pieces: it shows wherever the slice reaches.
#include <cmath>
#include <numbers>

#include <glm/glm.hpp>

namespace sonotrace::tissue {

// Nylon (2.9 MRayl) in water or tissue-mimicking gel (1.5 MRayl): (2.9-1.5)/(2.9+1.5).
inline constexpr double kDefaultTargetReflectivity = 0.3;

struct PointTarget {
    enum class Type { point, wire } type = Type::point;
    glm::dvec3 at{0.0};              // mm: the centre (point), a point on the axis (wire)
    glm::dvec3 axis{0.0, 0.0, 1.0};  // unit direction of a wire
    double diameter_mm = 0.1;
    double reflectivity =
        kDefaultTargetReflectivity;  // amplitude reflection coefficient of its surface, (0, 1]

    // The wire's 2D backscatter width (mm), see above.
    double backscatter_width_mm() const {
        return std::numbers::pi * 0.5 * diameter_mm * reflectivity * reflectivity;
    }
};

}  // namespace sonotrace::tissue
