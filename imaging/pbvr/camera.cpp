#include "imaging/pbvr/camera.h"

#include <cmath>
#include <limits>

#include "tissue/base/error.h"

namespace sonotrace::imaging::pbvr {

void OrbitCamera::validate() const {
    using base::require_in_range;
    for (int a = 0; a < 3; ++a) require_in_range("camera", "target", target[a], -1e6, 1e6, "mm");
    require_in_range("camera", "distance", distance_mm, 1e-3, 1e6, "mm");
    require_in_range("camera", "azimuth", azimuth_deg, -360.0, 360.0, "degrees");
    // 90 degrees would look straight along the up axis, where right() is undefined.
    require_in_range("camera", "elevation", elevation_deg, -89.0, 89.0, "degrees");
    // A zero field of view sees nothing; 180 or more turns the image inside out.
    require_in_range("camera", "fov", fov_deg, 0.1, 170.0, "degrees");
    require_in_range("camera", "width", width, 1, 16384, "pixels");
    require_in_range("camera", "height", height, 1, 16384, "pixels");
}

glm::dvec3 OrbitCamera::forward() const {
    const double a = glm::radians(azimuth_deg), e = glm::radians(elevation_deg);
    // azimuth 0: the eye on -y, looking along +y; positive azimuth turns it towards +x
    return -glm::dvec3(-std::sin(a) * std::cos(e), -std::cos(a) * std::cos(e), std::sin(e));
}

glm::dvec3 OrbitCamera::eye() const {
    return target - forward() * distance_mm;
}

glm::dvec3 OrbitCamera::right() const {
    return glm::normalize(glm::cross(forward(), glm::dvec3(0.0, 0.0, 1.0)));
}

glm::dvec3 OrbitCamera::up() const {
    return glm::cross(right(), forward());
}

double OrbitCamera::focal_px() const {
    return 0.5 * height / std::tan(0.5 * glm::radians(fov_deg));
}

std::optional<BoxCrossing> cross_box(const glm::dvec3& origin, const glm::dvec3& dir,
                                     const glm::dvec3& low, const glm::dvec3& high) {
    BoxCrossing c;
    c.t_exit = std::numeric_limits<double>::max();
    for (int a = 0; a < 3; ++a) {
        if (std::abs(dir[a]) < 1e-12) {  // parallel to the slab: inside it or never
            if (origin[a] < low[a] || origin[a] > high[a]) return std::nullopt;
            continue;
        }
        double ta = (low[a] - origin[a]) / dir[a], tb = (high[a] - origin[a]) / dir[a];
        if (ta > tb) std::swap(ta, tb);
        if (ta > c.t_entry) c.t_entry = ta, c.entry_axis = a;
        c.t_exit = std::min(c.t_exit, tb);
    }
    if (!(c.t_exit > c.t_entry)) return std::nullopt;
    return c;
}

Projection Projection::of(const OrbitCamera& camera, int scale) {
    Projection p;
    const glm::vec3 r(camera.right()), d(-camera.up()), f(camera.forward());
    // GLM matrices are column-major: rows of the rotation are the camera axes.
    p.rotation = glm::transpose(glm::mat3(r, d, f));
    p.eye = glm::vec3(camera.eye());
    p.focal = float(camera.focal_px() * scale);
    p.centre_x = 0.5f * float(camera.width * scale);
    p.centre_y = 0.5f * float(camera.height * scale);
    return p;
}

}  // namespace sonotrace::imaging::pbvr
