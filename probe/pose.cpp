#include "probe/pose.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "tissue/base/error.h"

namespace sonotrace::probe {

namespace {

glm::dvec3 parse_vec3(const std::string& text, const std::string& source, const std::string& key) {
    glm::dvec3 v;
    std::istringstream in(text);
    char comma = 0;
    if (!(in >> v.x >> comma >> v.y) || comma != ',' || !(in >> comma >> v.z) || comma != ',' ||
        !(in >> std::ws).eof()) {
        throw base::InputError(source, key,
                               "expected three comma-separated numbers, got '" + text + "'");
    }
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) {
        throw base::InputError(source, key, "values must be finite");
    }
    return v;
}

double parse_degrees(const std::string& text, const std::string& source, const std::string& key) {
    std::size_t used = 0;
    double v = 0.0;
    try {
        v = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (used != text.size() || !std::isfinite(v) || std::abs(v) > 360.0) {
        throw base::InputError(source, key,
                               "expected an angle in degrees in [-360, 360], got '" + text + "'");
    }
    return v;
}

// Six significant digits; rounding residue of the rotations (2e-16) shown as 0.
std::string format_vec(const glm::dvec3& v) {
    auto clean = [](double c) { return std::abs(c) < 1e-9 ? 0.0 : c; };
    std::ostringstream s;
    s << clean(v.x) << "," << clean(v.y) << "," << clean(v.z);
    return s.str();
}

}  // namespace

Pose Pose::looking(const glm::dvec3& position, const glm::dvec3& beam,
                   const glm::dvec3& lateral_hint) {
    if (!(glm::length(beam) > 0.0)) throw std::invalid_argument("beam direction is zero");
    const glm::dvec3 axial = glm::normalize(beam);
    const glm::dvec3 lateral_raw = lateral_hint - axial * glm::dot(lateral_hint, axial);
    if (!(glm::length(lateral_raw) > 1e-6 * glm::length(lateral_hint))) {
        throw std::invalid_argument("lateral direction is parallel to the beam");
    }
    const glm::dvec3 lateral = glm::normalize(lateral_raw);
    const glm::dmat3 axes(lateral, axial, glm::cross(lateral, axial));
    return Pose{position, glm::normalize(glm::quat_cast(axes))};
}

Pose Pose::rotated(double degrees) const {
    const glm::dquat turn = glm::angleAxis(glm::radians(degrees), glm::dvec3(0, 1, 0));
    return Pose{position, glm::normalize(orientation * turn)};
}

Pose Pose::tilted(double degrees) const {
    const glm::dquat rock = glm::angleAxis(glm::radians(degrees), glm::dvec3(1, 0, 0));
    return Pose{position, glm::normalize(orientation * rock)};
}

std::string Pose::to_string() const {
    return "at=" + format_vec(position) + " beam=" + format_vec(axial()) +
           " lateral=" + format_vec(lateral());
}

Pose parse_pose(const std::string& text, const std::string& source) {
    std::istringstream in(text);
    std::string token;
    glm::dvec3 at{0.0}, beam{0.0}, lateral{0.0};
    bool has_at = false, has_beam = false, has_lateral = false;
    double rotate = 0.0, tilt = 0.0;
    while (in >> token) {
        const auto eq = token.find('=');
        if (eq == std::string::npos) {
            throw base::InputError(source, token,
                                   "expected key=value (keys: at, beam, lateral, rotate, tilt)");
        }
        const std::string key = token.substr(0, eq), value = token.substr(eq + 1);
        if (key == "at")
            at = parse_vec3(value, source, key), has_at = true;
        else if (key == "beam")
            beam = parse_vec3(value, source, key), has_beam = true;
        else if (key == "lateral")
            lateral = parse_vec3(value, source, key), has_lateral = true;
        else if (key == "rotate")
            rotate = parse_degrees(value, source, key);
        else if (key == "tilt")
            tilt = parse_degrees(value, source, key);
        else
            throw base::InputError(source, key,
                                   "unknown key (keys: at, beam, lateral, rotate, tilt)");
    }
    if (!has_at) throw base::InputError(source, "at", "is required (probe face centre in mm)");
    if (!has_beam) throw base::InputError(source, "beam", "is required (beam direction)");
    if (!(glm::length(beam) > 0.0)) throw base::InputError(source, "beam", "must not be zero");
    if (!has_lateral) {
        // The world axis most perpendicular to the beam, preferring +Y, then +X.
        const glm::dvec3 b = glm::normalize(beam);
        lateral = std::abs(b.y) < 0.9 ? glm::dvec3(0, 1, 0) : glm::dvec3(1, 0, 0);
    }
    Pose pose;
    try {
        pose = Pose::looking(at, beam, lateral);
    } catch (const std::invalid_argument& e) {
        throw base::InputError(source, "lateral", e.what());
    }
    return pose.rotated(rotate).tilted(tilt);
}

Pose colin27_temporal_pose() {
    // MNI coordinates, measured on Colin27 along y = -18, z = 2: skin at x = +87 mm, the
    // temporal squama at x = +72..+75 (3 mm thick), the midbrain around x = 0.
    return Pose::looking({87.0, -18.0, 2.0}, {-1.0, 0.0, 0.0}, {0.0, 1.0, 0.0});
}

}  // namespace sonotrace::probe
