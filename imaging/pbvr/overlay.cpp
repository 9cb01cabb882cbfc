#include "imaging/pbvr/overlay.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <optional>

#include "imaging/pbvr/pbvr.h"
#include "probe/array_geometry.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"
#include "tissue/image_io.h"

namespace sonotrace::imaging::pbvr {

using base::InputError;
namespace jsonio = base::jsonio;

namespace {

glm::dvec3 unit_vector(const nlohmann::json& object, const std::string& key,
                       const std::string& source, const std::string& where) {
    const glm::dvec3 v = jsonio::get_vec3(object, key, source, where);
    if (!(glm::length(v) > 1e-9))
        throw InputError(source, jsonio::join(where, key), "must be a non-zero vector");
    return glm::normalize(v);
}

// The frame's grey levels, through the image reader volumes use (its formats told by
// their first bytes, sizes checked before decoding).
cv::Mat read_grey_png(const std::string& path) {
    const tissue::Volume image = tissue::read_image(path, glm::dvec3(1.0));
    const glm::ivec3 n = image.geometry().dims;
    cv::Mat grey(n.y, n.x, CV_8UC1);
    for (int y = 0; y < n.y; ++y)
        for (int x = 0; x < n.x; ++x)
            grey.at<unsigned char>(y, x) =
                uint8_t(std::clamp(std::lround(image.at(x, y, 0)), 0L, 255L));
    return grey;
}

}  // namespace

FrameOverlay load_frame_overlay(const std::string& sidecar_path) {
    const nlohmann::json j = jsonio::read_file(sidecar_path);
    const std::string& src = sidecar_path;
    FrameOverlay o;
    for (const char* key : {"pose", "image", "probe"}) {
        if (!j.contains(key))
            throw InputError(src, key, "is required (a sonotrace simulate sidecar)");
        jsonio::require_object(j[key], src, key);
    }
    const auto& pose = j["pose"];
    o.position = jsonio::get_vec3(pose, "position_mm", src, "pose");
    o.axial = unit_vector(pose, "axial", src, "pose");
    o.lateral = unit_vector(pose, "lateral", src, "pose");
    o.elevation = unit_vector(pose, "elevation", src, "pose");
    const auto& image = j["image"];
    auto pair_mm = [&](const char* key) {
        const std::string field = jsonio::join("image", key);
        if (!image.contains(key)) throw InputError(src, field, "is required");
        const auto& v = image[key];
        if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number())
            throw InputError(src, field, "needs 2 numbers [x, y] in mm");
        const glm::dvec2 out(v[0].get<double>(), v[1].get<double>());
        if (!(std::isfinite(out.x) && std::isfinite(out.y)))
            throw InputError(src, field, "must be finite");
        return out;
    };
    o.origin_mm = pair_mm("origin_mm");
    o.pixel_mm = pair_mm("pixel_spacing_mm");
    if (!(o.pixel_mm.x > 0.0 && o.pixel_mm.y > 0.0))
        throw InputError(src, "image.pixel_spacing_mm", "must be positive");
    const auto& probe_json = j["probe"];
    o.transducer =
        probe::find_transducer(jsonio::get_string(probe_json, "name", src, "probe"), src);
    // The run's own geometry overrides the preset's; the transducer's own check then says
    // what each array type allows (a linear array has no field of view: 0).
    o.transducer.fov_deg = jsonio::get_number(probe_json, "fov_deg", src, "probe", 0.0, 360.0);
    o.transducer.depth_mm = jsonio::get_number(probe_json, "depth_mm", src, "probe", 1.0, 1000.0);
    o.transducer.lines = int(jsonio::get_number(probe_json, "lines", src, "probe", 1, 100000));
    o.transducer.radius_mm = jsonio::get_number(probe_json, "radius_mm", src, "probe", 0.0, 1e4);
    o.transducer.elements =
        int(jsonio::get_number(probe_json, "elements", src, "probe", 1, 100000));
    o.transducer.pitch_mm = jsonio::get_number(probe_json, "pitch_mm", src, "probe", 1e-3, 100.0);
    o.transducer.validate(src);
    std::filesystem::path png(sidecar_path);
    png.replace_extension(".png");
    if (!std::filesystem::exists(png))
        throw InputError(src, "", "the frame " + png.string() + " next to it is missing");
    o.frame = read_grey_png(png.string());
    return o;
}

namespace {

// Where a ray first meets a surface from outside, and the surface's unit normal there.
struct SurfaceHit {
    double t;
    glm::dvec3 normal;
};

// A closed cylinder of `radius` about the z axis between z0 and z1 (a radial probe's tip
// in its own frame), met from outside by origin + t dir, t > 0.
std::optional<SurfaceHit> cross_tip(const glm::dvec3& origin, const glm::dvec3& dir, double radius,
                                    double z0, double z1) {
    std::optional<SurfaceHit> first;
    auto keep = [&](double t, const glm::dvec3& normal) {
        if (t > 0.0 && (!first || t < first->t)) first = SurfaceHit{t, normal};
    };
    // The mantle: |(o + t d)_xy| = radius, entering (the smaller root).
    const double a = dir.x * dir.x + dir.y * dir.y;
    const double b = origin.x * dir.x + origin.y * dir.y;
    const double c = origin.x * origin.x + origin.y * origin.y - radius * radius;
    if (a > 0.0 && b * b - a * c >= 0.0) {
        const double t = (-b - std::sqrt(b * b - a * c)) / a;
        const glm::dvec3 p = origin + t * dir;
        if (p.z >= z0 && p.z <= z1) keep(t, glm::dvec3(p.x, p.y, 0.0) / radius);
    }
    // The two end discs.
    if (dir.z != 0.0) {
        for (const double z : {z0, z1}) {
            const double t = (z - origin.z) / dir.z;
            const glm::dvec3 p = origin + t * dir;
            if (p.x * p.x + p.y * p.y <= radius * radius) keep(t, glm::dvec3(0.0, 0.0, 1.0));
        }
    }
    return first;
}

}  // namespace

std::vector<uint64_t> overlay_layer(const FrameOverlay& overlay, const OrbitCamera& camera,
                                    int subpixel_level) {
    const int L = subpixel_level, width = camera.width * L, height = camera.height * L;
    std::vector<uint64_t> layer(std::size_t(width) * std::size_t(height), kEmptyEntry);
    const probe::ScanGeometry scan(overlay.transducer);
    const glm::dvec3 eye = camera.eye(), forward = camera.forward(), right = camera.right(),
                     down = -camera.up();
    const double focal = camera.focal_px() * L;
    // The probe body: the array's length and a 16 mm grip, 25 mm behind the face; a
    // closed (radial) array is a catheter or scope tip, a cylinder about the elevation axis.
    const double half_length = 0.5 * overlay.transducer.array_length_mm() + 2.0;
    const glm::dvec3 box_low(-half_length, -25.0, -8.0), box_high(half_length, 0.0, 8.0);
    const bool tip = scan.closed();
    const double tip_radius = scan.array().face_radius_mm();
    // The ring's centre: behind the face point of the central line, by the face's radius.
    const probe::ArrayPoint face_centre = scan.array().face(0.0);
    const glm::dvec3 tip_axis(face_centre.position - tip_radius * face_centre.normal, 0.0);
    const glm::dmat3 to_probe =
        glm::transpose(glm::dmat3(overlay.lateral, overlay.axial, overlay.elevation));
    const glm::vec3 frame_colour_scale(1.0f / 255.0f);
    tbb::parallel_for(0, height, [&](int y) {
        for (int x = 0; x < width; ++x) {
            const glm::dvec3 dir =
                glm::normalize(forward + (x + 0.5 - 0.5 * width) / focal * right +
                               (y + 0.5 - 0.5 * height) / focal * down);
            uint64_t best = kEmptyEntry;
            // -- the probe model (shaded by the face it is seen through)
            const glm::dvec3 o = to_probe * (eye - overlay.position), d = to_probe * dir;
            std::optional<SurfaceHit> body;
            if (tip) {
                body = cross_tip(o - tip_axis, d, tip_radius, -25.0, 8.0);
            } else if (const auto hit = cross_box(o, d, box_low, box_high);
                       hit && hit->entry_axis >= 0) {
                glm::dvec3 normal(0.0);
                normal[hit->entry_axis] = 1.0;
                body = SurfaceHit{hit->t_entry, normal};
            }
            if (body) {
                const float light = float(0.45 + 0.55 * std::abs(glm::dot(d, body->normal)));
                best = std::min(best, zbuffer_entry(float(body->t * glm::dot(dir, forward)),
                                                    glm::vec3(0.30f, 0.42f, 0.62f) * light, 0));
            }
            // -- the scan plane: the frame inside the sector, its outline in yellow
            const double facing = glm::dot(dir, overlay.elevation);
            if (std::abs(facing) > 1e-9) {
                const double tp = glm::dot(overlay.position - eye, overlay.elevation) / facing;
                if (tp > 0.0) {
                    const glm::dvec3 p = eye + tp * dir - overlay.position;
                    const glm::dvec2 in_plane(glm::dot(p, overlay.lateral),
                                              glm::dot(p, overlay.axial));
                    const glm::dvec2 ld = scan.line_and_depth(in_plane);
                    const int lines = scan.lines();
                    const bool inside = ld.x >= -0.5 && ld.x <= lines - 0.5 && ld.y >= 0.0 &&
                                        ld.y <= scan.depth_mm();
                    // A closed array's sector has no side edges: its last line meets
                    // its first.
                    const double side_mm =
                        tip ? std::numeric_limits<double>::infinity()
                            : std::min((ld.x + 0.5) * scan.line_spacing_mm(ld.y),
                                       (lines - 0.5 - ld.x) * scan.line_spacing_mm(ld.y));
                    const double edge_mm = std::min({side_mm, scan.depth_mm() - ld.y, ld.y});
                    if (inside && (edge_mm <= 0.8 || overlay.draw_frame)) {
                        glm::vec3 colour(1.0f, 0.85f, 0.1f);  // outline
                        if (edge_mm > 0.8) {
                            const double c =
                                (in_plane.x - overlay.origin_mm.x) / overlay.pixel_mm.x;
                            const double r =
                                (in_plane.y - overlay.origin_mm.y) / overlay.pixel_mm.y;
                            const int ci =
                                std::clamp(int(std::lround(c)), 0, overlay.frame.cols - 1);
                            const int ri =
                                std::clamp(int(std::lround(r)), 0, overlay.frame.rows - 1);
                            colour =
                                overlay.frame.empty()
                                    ? glm::vec3(0.2f)
                                    : glm::vec3(float(overlay.frame.at<unsigned char>(ri, ci))) *
                                          frame_colour_scale;
                        }
                        best = std::min(
                            best, zbuffer_entry(float(tp * glm::dot(dir, forward)), colour, 0));
                    }
                }
            }
            layer[std::size_t(y) * std::size_t(width) + std::size_t(x)] = best;
        }
    });
    return layer;
}

TetMesh sector_mesh(const FrameOverlay& overlay, int line_step, double depth_step_mm) {
    const probe::ScanGeometry scan(overlay.transducer);
    std::vector<double> line_positions, depths;
    for (double l = -0.5; l < scan.lines() - 0.5; l += line_step) line_positions.push_back(l);
    line_positions.push_back(scan.lines() - 0.5);
    for (double d = 0.0; d < scan.depth_mm(); d += depth_step_mm) depths.push_back(d);
    depths.push_back(scan.depth_mm());
    const double half_thickness = 0.5 * overlay.transducer.slice_thickness_mm;
    const std::size_t nl = line_positions.size(), nd = depths.size();
    TetMesh mesh;
    for (int e = 0; e < 2; ++e)
        for (std::size_t d = 0; d < nd; ++d)
            for (std::size_t l = 0; l < nl; ++l) {
                const glm::dvec2 p = scan.point(line_positions[l], depths[d]);
                mesh.points.push_back(
                    overlay.position + p.x * overlay.lateral + p.y * overlay.axial +
                    (e == 0 ? -half_thickness : half_thickness) * overlay.elevation);
                float value = 0.0f;
                if (!overlay.frame.empty()) {
                    const int c = std::clamp(
                        int(std::lround((p.x - overlay.origin_mm.x) / overlay.pixel_mm.x)), 0,
                        overlay.frame.cols - 1);
                    const int r = std::clamp(
                        int(std::lround((p.y - overlay.origin_mm.y) / overlay.pixel_mm.y)), 0,
                        overlay.frame.rows - 1);
                    value = float(overlay.frame.at<unsigned char>(r, c));
                }
                mesh.values.push_back(value);
            }
    auto index = [&](std::size_t l, std::size_t d, int e) {
        return uint32_t((std::size_t(e) * nd + d) * nl + l);
    };
    for (std::size_t d = 0; d + 1 < nd; ++d)
        for (std::size_t l = 0; l + 1 < nl; ++l) {
            std::array<uint32_t, 8> corner{};
            for (int c = 0; c < 8; ++c)
                corner[std::size_t(c)] = index(l + (c & 1), d + (c >> 1 & 1), c >> 2);
            for (const auto& t : kCellTetrahedra)
                mesh.tets.push_back({corner[std::size_t(t[0])], corner[std::size_t(t[1])],
                                     corner[std::size_t(t[2])], corner[std::size_t(t[3])]});
        }
    return mesh;
}

glm::vec4 camera_side_of_plane(const FrameOverlay& overlay, const tissue::VolumeGeometry& volume,
                               const OrbitCamera& camera) {
    // world: n . (p - position) > 0 on the camera's side; p = origin + D q in the local frame
    glm::dvec3 n = overlay.elevation;
    if (glm::dot(n, camera.eye() - overlay.position) < 0.0) n = -n;
    const glm::dvec3 local_normal = glm::transpose(volume.linear()) * n;
    const double offset = glm::dot(n, volume.origin - overlay.position);
    return glm::vec4(glm::vec3(local_normal), float(offset));
}

}  // namespace sonotrace::imaging::pbvr
