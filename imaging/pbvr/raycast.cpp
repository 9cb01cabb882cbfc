// The reference ray caster PBVR converges to (pbvr.h: raycast_fused, raycast_meshes): the
// same volume, transfer function and shading, integrated along each sub-pixel's ray.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "imaging/pbvr/pbvr.h"
#include "imaging/pbvr/preintegration.h"
#include "tissue/base/error.h"

namespace sonotrace::imaging::pbvr {

// ---- reference ray caster ----------------------------------------------------------

RgbImage raycast_fused(
    const RenderVolume* volume, const ColourTransferFunction* volume_tf,
    const std::vector<std::pair<const TetMesh*, const ColourTransferFunction*>>& meshes,
    const OrbitCamera& camera, const RenderSettings& settings, double step_mm) {
    camera.validate();
    settings.validate();
    base::require_in_range("raycast", "step", step_mm, 1e-4, 100.0, "mm");
    if ((volume == nullptr) != (volume_tf == nullptr))
        throw std::invalid_argument("raycast_fused: a volume needs its transfer function");
    const int L = settings.subpixel_level;
    const int width = camera.width * L, height = camera.height * L;
    const glm::dvec3 eye = camera.eye(), forward = camera.forward(), right = camera.right(),
                     down = -camera.up();
    const double focal = camera.focal_px() * L;

    // -- the regular volume's frame: p_local(t) = eye_local + t dir_local
    glm::dmat3 to_local(1.0);
    glm::dvec3 eye_local(0.0), extent(0.0);
    glm::vec3 to_eye(0.0f, 0.0f, 1.0f);
    if (volume) {
        const tissue::VolumeGeometry& g = volume->geometry();
        to_local = glm::inverse(g.direction);
        eye_local = to_local * (eye - g.origin);
        extent = glm::dvec3(volume->extent());
        to_eye = glm::normalize(glm::vec3(to_local * -forward));
    }

    // -- tetrahedra binned by the image tiles (16 x 16 sub-pixels) their projection covers
    constexpr int kTile = 16;
    const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> tiles(std::size_t(tiles_x) *
                                                                  std::size_t(tiles_y));
    const Projection projection = Projection::of(camera, L);
    for (std::size_t m = 0; m < meshes.size(); ++m) {
        const TetMesh& mesh = *meshes[m].first;
        for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
            glm::dvec2 low(1e300), high(-1e300);
            bool visible = true;
            for (const uint32_t v : mesh.tets[t]) {
                const glm::vec3 e = projection.to_camera(glm::vec3(mesh.points[v]));
                if (e.z <= 1e-3f) visible = false;
                const glm::dvec2 q(projection.centre_x + projection.focal * e.x / e.z,
                                   projection.centre_y + projection.focal * e.y / e.z);
                low = glm::min(low, q), high = glm::max(high, q);
            }
            if (!visible) continue;  // as the renderer: not drawn
            const int x0 = std::max(0, int(std::floor(low.x / kTile))),
                      x1 = std::min(tiles_x - 1, int(std::floor(high.x / kTile)));
            const int y0 = std::max(0, int(std::floor(low.y / kTile))),
                      y1 = std::min(tiles_y - 1, int(std::floor(high.y / kTile)));
            for (int ty = y0; ty <= y1; ++ty)
                for (int tx = x0; tx <= x1; ++tx)
                    tiles[std::size_t(ty) * std::size_t(tiles_x) + std::size_t(tx)].push_back(
                        {uint32_t(m), uint32_t(t)});
        }
    }

    struct Segment {
        double t0, t1, s0, s1;
        const ColourTransferFunction* tf;
    };
    RgbImage out{camera.width, camera.height, {}};
    out.pixels.assign(std::size_t(camera.width) * std::size_t(camera.height), glm::vec3(0.0f));
    tbb::parallel_for(0, camera.height, [&](int y) {
        std::vector<Segment> segments;
        for (int x = 0; x < camera.width; ++x) {
            glm::dvec3 pixel(0.0);
            for (int sy = 0; sy < L; ++sy) {
                for (int sx = 0; sx < L; ++sx) {
                    const int px = x * L + sx, py = y * L + sy;
                    const glm::dvec3 dir =
                        glm::normalize(forward + (px + 0.5 - 0.5 * width) / focal * right +
                                       (py + 0.5 - 0.5 * height) / focal * down);
                    double first = 1e300, last = -1e300;
                    // -- the regular volume's box along the ray
                    double box0 = 0.0, box1 = -1.0;
                    glm::dvec3 dir_local(0.0);
                    if (volume) {
                        dir_local = to_local * dir;
                        if (const auto c = cross_box(eye_local, dir_local, glm::dvec3(0.0), extent))
                            box0 = c->t_entry, box1 = c->t_exit;
                        if (box1 > box0) first = box0, last = box1;
                    }
                    // -- the tetrahedra the ray crosses, with their values at both ends
                    segments.clear();
                    for (const auto& [m, t] : tiles[std::size_t(py / kTile) * std::size_t(tiles_x) +
                                                    std::size_t(px / kTile)]) {
                        const TetMesh& mesh = *meshes[m].first;
                        const ColourTransferFunction* tf = meshes[m].second;
                        std::array<glm::dvec3, 4> c;
                        glm::dvec4 s;
                        for (int v = 0; v < 4; ++v) {
                            c[std::size_t(v)] = mesh.points[mesh.tets[t][std::size_t(v)]];
                            s[v] = tf->normalize(mesh.values[mesh.tets[t][std::size_t(v)]]);
                        }
                        const auto crossing = cross_tetrahedron(c, eye, dir);
                        if (!crossing) continue;
                        segments.push_back({crossing->t_entry, crossing->t_exit,
                                            glm::dot(crossing->entry_weights, s),
                                            glm::dot(crossing->exit_weights, s), tf});
                        first = std::min(first, crossing->t_entry);
                        last = std::max(last, crossing->t_exit);
                    }
                    glm::dvec3 colour(0.0);
                    double transmittance = 1.0;
                    // -- front to back: extinctions add, colours mix by extinction
                    for (double t = first; t < last && transmittance > 1e-5; t += step_mm) {
                        const double length = std::min(step_mm, last - t), mid = t + 0.5 * length;
                        double sigma = 0.0;
                        glm::dvec3 emitted(0.0);
                        if (volume && mid >= box0 && mid <= box1) {
                            const glm::vec3 q(eye_local + mid * dir_local);
                            if (!settings.removed(q)) {
                                const VoxelSample v = volume->sample(q);
                                const double e = volume_tf->extinction(v.value);
                                sigma += e;
                                emitted +=
                                    e * glm::dvec3(shade(volume_tf->colour(v.value), v.gradient,
                                                         to_eye, settings.shading));
                            }
                        }
                        for (const Segment& g : segments) {
                            if (mid < g.t0 || mid > g.t1) continue;
                            const double v = g.s0 + (g.s1 - g.s0) * (mid - g.t0) / (g.t1 - g.t0);
                            const double e = g.tf->extinction(float(v));
                            sigma += e;
                            emitted += e * glm::dvec3(g.tf->colour(float(v)));
                        }
                        if (sigma <= 0.0) continue;
                        const double alpha = 1.0 - std::exp(-sigma * length);
                        colour += transmittance * alpha * emitted / sigma;
                        transmittance *= 1.0 - alpha;
                    }
                    pixel += colour + transmittance * glm::dvec3(settings.background);
                }
            }
            out.at(x, y) = glm::vec3(pixel / double(L * L));
        }
    });
    return out;
}

RgbImage raycast_meshes(
    const std::vector<std::pair<const TetMesh*, const ColourTransferFunction*>>& meshes,
    const OrbitCamera& camera, const RenderSettings& settings, double step_mm) {
    return raycast_fused(nullptr, nullptr, meshes, camera, settings, step_mm);
}

RgbImage raycast(const RenderVolume& volume, const ColourTransferFunction& tf,
                 const OrbitCamera& camera, const RenderSettings& settings, double step_mm) {
    return raycast_fused(&volume, &tf, {}, camera, settings, step_mm);
}

}  // namespace sonotrace::imaging::pbvr
