#include "probe/array_geometry.h"

#include <cmath>
#include <stdexcept>

#include "tissue/base/error.h"

namespace sonotrace::probe {

const std::vector<ArrayType>& array_types() {
    // The registration of every array type: its name (CLI, sidecars, GUI), what the CLI's
    // --type help says of it, whether --fov sets its lines' angle, whether it takes unfocused
    // transmits.
    static const std::vector<ArrayType> types = {
        {TransducerType::linear, "linear", "parallel lines", false, true, arrays::no_fov,
         arrays::whole_array, arrays::make_linear, arrays::validate_linear},
        {TransducerType::convex, "convex", "a fan of lines from a curved array", true, true,
         arrays::max_fov_convex, arrays::whole_array, arrays::make_convex, arrays::validate_convex},
        {TransducerType::phased, "phased", "a fan of lines steered from a flat array", true, true,
         arrays::max_fov_phased, arrays::whole_array, arrays::make_phased, arrays::validate_phased},
        {TransducerType::radial, "radial", "lines all around a ring of elements", false, false,
         arrays::max_fov_radial, arrays::half_ring, arrays::make_radial, arrays::validate_radial},
    };
    return types;
}

const ArrayType& array_type(TransducerType type) {
    for (const ArrayType& a : array_types())
        if (a.type == type) return a;
    throw std::logic_error("array type " + std::to_string(int(type)) + " not registered");
}

TransducerType parse_transducer_type(const std::string& name, const std::string& source,
                                     const std::string& field) {
    std::string names;
    for (const ArrayType& a : array_types()) {
        if (name == a.name) return a.type;
        names += (names.empty() ? "" : ", ") + std::string(a.name);
    }
    throw base::InputError(source, field,
                           "unknown transducer type '" + name + "' (types: " + names + ")");
}

std::string to_string(TransducerType type) {
    return array_type(type).name;
}

double arrays::whole_array(const Transducer& t) {
    return t.array_length_mm();
}

std::unique_ptr<const ArrayGeometry> array_geometry(const Transducer& t) {
    return array_type(t.type).make(t);
}

// A fan from the arc's centre (0, -R): the point at depth d on the line at angle u lies
// R + d from the centre, at (r sin u, r cos u - R).
glm::dvec2 FanLines::point(double l, double depth) const {
    const double u = angle(l);
    const double r = radius + depth;
    return {r * std::sin(u), r * std::cos(u) - radius};
}

ScanLine FanLines::line(int l) const {
    const glm::dvec2 origin = point(l, 0.0);
    const double u = angle(l);
    return {origin, {std::sin(u), std::cos(u)}};
}

glm::dvec2 FanLines::line_and_depth(const glm::dvec2& p) const {
    const glm::dvec2 v(p.x, p.y + radius);
    const double u = std::atan2(v.x, v.y);
    return {(u + 0.5 * span) * lines / span - 0.5, glm::length(v) - radius};
}

std::optional<double> ArrayGeometry::face_crossing(const glm::dvec2& p, const glm::dvec2& u) const {
    if (!(u.y > 0.0)) return std::nullopt;
    return p.x - p.y * u.x / u.y;
}

double ArcArray::arc_length(const glm::dvec2& on_face) const {
    return radius_ * std::atan2(on_face.x, on_face.y + radius_);
}

// p - t u on the circle: t^2 - 2 b t + c = 0 with b = u . (p - centre), c = |p - centre|^2
// - R^2; the smaller root that is not negative.
std::optional<double> ArcArray::face_crossing(const glm::dvec2& p, const glm::dvec2& u) const {
    const glm::dvec2 from_centre = p - glm::dvec2(0.0, -radius_);
    const double b = glm::dot(u, from_centre);
    const double c = glm::dot(from_centre, from_centre) - radius_ * radius_;
    const double discriminant = b * b - c;
    if (!(discriminant >= 0.0)) return std::nullopt;
    const double root = std::sqrt(discriminant);
    const double t = b - root >= 0.0 ? b - root : b + root;
    if (!(t >= 0.0)) return std::nullopt;
    return arc_length(p - t * u);
}

bool ArcArray::in_front(const glm::dvec2& p) const {
    return glm::length(p - glm::dvec2(0.0, -radius_)) > radius_;
}

ArrayPoint ArcArray::face(double s) const {
    const double phi = s / radius_;
    return {{radius_ * std::sin(phi), radius_ * (std::cos(phi) - 1.0)},
            {std::sin(phi), std::cos(phi)}};
}

std::optional<double> ArcArray::aperture_centre(const ScanLine& line) const {
    return std::atan2(line.direction.x, line.direction.y) * radius_;
}

}  // namespace sonotrace::probe
