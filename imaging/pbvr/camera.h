#pragma once
// A perspective orbit camera (GLM): it looks at `target` from `distance` mm, turned by
// azimuth about the world up axis (+z) and raised by elevation. Image rows run
// downwards. Shared by the particle renderer, the reference ray caster and overlays.
#include <optional>
#include <string>

#include <glm/glm.hpp>

namespace sonotrace::imaging::pbvr {

struct OrbitCamera {
    glm::dvec3 target{0.0};      // mm, world
    double distance_mm = 500.0;  // eye to target
    double azimuth_deg = 0.0;    // about +z; 0 looks along +y (from -y)
    double elevation_deg = 0.0;  // above the xy plane
    double fov_deg = 30.0;       // vertical field of view
    int width = 512, height = 512;

    // Throws base::InputError("camera", field) on a zero or inverted field of view, a
    // non-positive distance or image size.
    void validate() const;
    glm::dvec3 eye() const;
    glm::dvec3 forward() const;  // unit, eye -> target
    glm::dvec3 right() const;    // unit, image +x
    glm::dvec3 up() const;       // unit, image -y (rows run down)
    // Focal length in pixels (vertical).
    double focal_px() const;
};

// Where the ray origin + t dir (t >= 0) crosses the box [low, high] (slab method): the
// entry and exit parameters and the axis of the entry face; nullopt if it misses.
struct BoxCrossing {
    double t_entry = 0.0, t_exit = 0.0;
    int entry_axis = -1;  // -1: the origin is inside
};
std::optional<BoxCrossing> cross_box(const glm::dvec3& origin, const glm::dvec3& dir,
                                     const glm::dvec3& low, const glm::dvec3& high);

// A camera transform in single precision for the hot loops: world -> camera space
// (x right, y down, z along the view) and the pixel projection.
struct Projection {
    glm::mat3 rotation{1.0f};  // rows: right, down, forward
    glm::vec3 eye{0.0f};
    float focal = 1.0f;  // pixels of the (sub-)pixel grid
    float centre_x = 0.0f, centre_y = 0.0f;

    // `scale` sub-pixels per pixel.
    static Projection of(const OrbitCamera& camera, int scale);
    glm::vec3 to_camera(const glm::vec3& world) const { return rotation * (world - eye); }
};

}  // namespace sonotrace::imaging::pbvr
