// The particle renderer's occlusion culling (PbvrRenderer, pbvr.h): a map of the depth
// beyond which each tile of the image is hidden (an optical depth of 5 along rays a few
// pixels apart), and the tests of cells and bricks against it.
#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/parallel_for.h>

#include "imaging/pbvr/pbvr.h"
#include "imaging/pbvr/renderer_parts.h"

namespace sonotrace::imaging::pbvr {

namespace {

// Camera rays in the volume's local frame, through points of the sub-pixel grid.
struct LocalRays {
    glm::dvec3 eye, right, down, forward, extent;
    double focal = 1.0, centre_x = 0.0, centre_y = 0.0;

    LocalRays(const RenderVolume& volume, const OrbitCamera& camera, int scale) {
        const tissue::VolumeGeometry& g = volume.geometry();
        const glm::dmat3 to_local = glm::inverse(g.direction);  // q = D^-1 (world - origin)
        eye = to_local * (camera.eye() - g.origin);
        right = to_local * camera.right(), down = to_local * -camera.up();
        forward = to_local * camera.forward();
        extent = glm::dvec3(volume.extent());
        focal = camera.focal_px() * scale;
        centre_x = 0.5 * camera.width * scale, centre_y = 0.5 * camera.height * scale;
    }
    // Unit direction through the grid point (x, y) (sub-pixel centres at +0.5).
    glm::dvec3 direction(double x, double y) const {
        return glm::normalize(forward + (x - centre_x) / focal * right +
                              (y - centre_y) / focal * down);
    }
    // The ray's parameter range inside the volume box (t0 >= t1: misses it).
    std::pair<double, double> clip(const glm::dvec3& dir) const {
        const auto c = cross_box(eye, dir, glm::dvec3(0.0), extent);
        return c ? std::pair{c->t_entry, c->t_exit} : std::pair{0.0, -1.0};
    }
};

}  // namespace

void PbvrRenderer::build_occlusion_map() {
    const LocalRays rays(volume_, camera_, 1);
    occlusion_tiles_x_ = (camera_.width + kOcclusionTile - 1) / kOcclusionTile;
    occlusion_tiles_y_ = (camera_.height + kOcclusionTile - 1) / kOcclusionTile;
    const int grid_x = occlusion_tiles_x_ + 1, grid_y = occlusion_tiles_y_ + 1;
    const float step =
        0.5f * std::min({volume_.spacing().x, volume_.spacing().y, volume_.spacing().z});
    occluded_beyond_.assign(std::size_t(grid_x) * std::size_t(grid_y),
                            std::numeric_limits<float>::infinity());
    tbb::parallel_for(0, grid_y, [&](int gy) {
        for (int gx = 0; gx < grid_x; ++gx) {
            const glm::dvec3 dir = rays.direction(gx * kOcclusionTile, gy * kOcclusionTile);
            const auto [t0, t1] = rays.clip(dir);
            float tau = 0.0f;
            for (double t = t0; t < t1; t += step) {
                const glm::vec3 q(rays.eye + (t + 0.5 * step) * dir);
                if (settings_.removed(q)) continue;
                tau += generation_tf_.extinction(volume_.sample_value(q)) * step;
                if (tau >= kOcclusionDepth) {
                    occluded_beyond_[std::size_t(gy) * std::size_t(grid_x) + std::size_t(gx)] =
                        float((t + step) * glm::dot(dir, rays.forward));
                    break;
                }
            }
        }
    });
}

// Whether every cell from `first` to `last` (inclusive) is hidden by cell_hidden: bounds
// of what cell_hidden computes for each, over the box of their centres (a perspective
// ratio e.x / e.z over a box in front of the eye is extreme at a corner). Conservative:
// false where it cannot tell.
bool PbvrRenderer::brick_hidden(const glm::ivec3& first, const glm::ivec3& last,
                                bool occlusion) const {
    const glm::vec3 h = volume_.spacing();
    const float half_diagonal = 0.5f * glm::length(h);
    const float L = float(settings_.subpixel_level);
    // Over the corner cells' centres (camera frame): depth, distance from the eye and the
    // radius are extreme at a corner (linear or convex).
    float z_min = std::numeric_limits<float>::max(), z_max = -z_min, radius = 0.0f;
    float farthest = 0.0f;
    float u_min = z_min, u_max = -z_min, v_min = z_min, v_max = -z_min;
    glm::vec3 corners[8];  // camera frame
    for (int c = 0; c < 8; ++c) {
        const glm::vec3 q =
            glm::vec3((c & 1 ? last.x : first.x) + 0.5f, (c & 2 ? last.y : first.y) + 0.5f,
                      (c & 4 ? last.z : first.z) + 0.5f) *
            h;
        const glm::vec3 e = corners[c] = to_camera_ * q + camera_offset_;
        z_min = std::min(z_min, e.z), z_max = std::max(z_max, e.z);
        farthest = std::max(farthest, glm::length(e));
        radius = std::max(radius, cell_radius(q));
    }
    if (z_max + half_diagonal <= 0.0f) return true;  // wholly behind the eye
    const float bound = half_diagonal + radius;
    const float plane_bound = half_diagonal + radius * edge_stretch_;
    for (const glm::vec3& plane : frustum_planes_) {  // distances are linear: all corners out
        bool outside = true;
        for (const glm::vec3& e : corners) outside = outside && glm::dot(plane, e) < -plane_bound;
        if (outside) return true;
    }
    for (const glm::vec3& e : corners) {
        if (e.z - bound <= 1e-3f) return false;
        u_min = std::min(u_min, e.x / e.z), u_max = std::max(u_max, e.x / e.z);
        v_min = std::min(v_min, e.y / e.z), v_max = std::max(v_max, e.y / e.z);
    }
    const float nearest = z_min - bound;  // no cell's nearest point is nearer
    // no cell's disc is larger (cell_hidden)
    const float pr = focal_ * bound * (farthest + bound) / (nearest * nearest) / L;
    const float px0 = (centre_x_ + focal_ * u_min) / L, px1 = (centre_x_ + focal_ * u_max) / L;
    const float py0 = (centre_y_ + focal_ * v_min) / L, py1 = (centre_y_ + focal_ * v_max) / L;
    return footprint_hidden(px0 - pr, px1 + pr, py0 - pr, py1 + pr, nearest, occlusion);
}

// A cell is hidden if it lies behind the eye or off the image, or (with `occlusion`) if
// its nearest point lies beyond the occlusion depth of every grid ray around its
// projection (with a margin).
bool PbvrRenderer::cell_hidden(int i, int j, int k, bool occlusion) const {
    const glm::vec3 h = volume_.spacing();
    const float L = float(settings_.subpixel_level);
    const glm::vec3 centre = (glm::vec3(float(i), float(j), float(k)) + 0.5f) * h;
    const glm::vec3 e = to_camera_ * centre + camera_offset_;
    const float half_diagonal = 0.5f * glm::length(h), radius = cell_radius(centre);
    if (e.z + half_diagonal <= 0.0f) return true;  // wholly behind the eye
    const float bound = half_diagonal + radius;
    const float plane_bound = half_diagonal + radius * edge_stretch_;
    for (const glm::vec3& plane : frustum_planes_)
        if (glm::dot(plane, e) < -plane_bound) return true;  // off the image
    const float nearest = e.z - bound;
    if (nearest <= 1e-3f) return false;
    const float px = (centre_x_ + focal_ * e.x / e.z) / L,
                py = (centre_y_ + focal_ * e.y / e.z) / L;
    // Where the cell's particles can draw, around its centre's projection: an offset of
    // b at depth z moves a projection by at most f b |e| / z^2, and a disc's stretch
    // (add_repetition) is below |e| / z, both for |e| / z <= (|e| + b) / nearest.
    const float pr = focal_ * bound * (glm::length(e) + bound) / (nearest * nearest) / L;
    return footprint_hidden(px - pr, px + pr, py - pr, py + pr, nearest, occlusion);
}

// Whether what draws within image box [x0, x1] x [y0, y1] (pixels), nothing of it nearer
// than `nearest`, is hidden: off the image, or (with `occlusion`) beyond the occlusion
// depth of every grid ray around the box, with a margin.
bool PbvrRenderer::footprint_hidden(float x0, float x1, float y0, float y1, float nearest,
                                    bool occlusion) const {
    if (x1 < 0.0f || y1 < 0.0f || x0 > float(camera_.width) || y0 > float(camera_.height))
        return true;
    return occlusion && nearest > deepest_occlusion(x0, x1, y0, y1) + kHiddenMargin;
}

// The largest occlusion depth of the grid rays around image box [x0, x1] x [y0, y1].
float PbvrRenderer::deepest_occlusion(float x0, float x1, float y0, float y1) const {
    // The grid tile holding image coordinate v (integer floor: a call on the baseline),
    // clamped to the grid; v is clamped first so that the conversion is safe.
    const float tile = float(kOcclusionTile);
    auto tile_of = [tile](float v, int tiles) {
        return std::clamp(base::floor_to_int(std::clamp(v / tile, -1.0f, float(tiles))), 0,
                          tiles - 1);
    };
    const int tx0 = tile_of(x0, occlusion_tiles_x_), tx1 = tile_of(x1, occlusion_tiles_x_);
    const int ty0 = tile_of(y0, occlusion_tiles_y_), ty1 = tile_of(y1, occlusion_tiles_y_);
    float deepest = 0.0f;
    for (int gy = ty0; gy <= ty1 + 1; ++gy)
        for (int gx = tx0; gx <= tx1 + 1; ++gx)
            deepest = std::max(
                deepest, occluded_beyond_[std::size_t(gy) * std::size_t(occlusion_tiles_x_ + 1) +
                                          std::size_t(gx)]);
    return deepest;
}

}  // namespace sonotrace::imaging::pbvr
