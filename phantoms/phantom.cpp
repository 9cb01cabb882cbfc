#include "phantoms/phantom.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "tissue/base/error.h"
#include "tissue/base/json_util.h"
#include "tissue/base/memory.h"
#include "tissue/transfer_function.h"

namespace sonotrace::phantoms {

namespace {

using nlohmann::json;
namespace jsonio = base::jsonio;

struct ShapeKeys {
    const char* name;
    ShapeType type;
    std::vector<std::string_view> geometry;  // keys besides the property keys
};

const std::vector<ShapeKeys>& shape_keys() {
    static const std::vector<ShapeKeys> keys = {
        {"sphere", ShapeType::sphere, {"centre", "radius"}},
        {"ellipsoid", ShapeType::ellipsoid, {"centre", "radii"}},
        {"box", ShapeType::box, {"min", "max"}},
        {"cylinder", ShapeType::cylinder, {"from", "to", "radius"}},
        {"wire", ShapeType::wire, {"at", "radius"}},
        {"half_space", ShapeType::half_space, {"point", "normal"}},
        {"layer", ShapeType::layer, {"point", "normal", "thickness"}},
        {"tube", ShapeType::tube, {"path", "radius"}},
        {"mesh", ShapeType::mesh, {"file", "scale", "rotate", "translate"}},
    };
    return keys;
}

// The keys of a shape (`geometry`, its type) or of the background: plus the properties.
void require_keys(const json& object, std::vector<std::string_view> keys, const std::string& source,
                  const std::string& where, bool paper) {
    if (paper) {
        keys.push_back("paper_density");
    } else {
        for (const auto& p : tissue::kPropertyInfo) keys.push_back(p.key);
        keys.push_back("tissue");
    }
    keys.push_back("comment");
    jsonio::require_known_keys(object, keys, source, where);
}

glm::dvec3 unit(const json& object, const std::string& key, const std::string& source,
                const std::string& where) {
    const glm::dvec3 v = jsonio::get_vec3(object, key, source, where);
    if (!(glm::length(v) > 0.0))
        throw base::InputError(source, jsonio::join(where, key), "must not be zero");
    return glm::normalize(v);
}

Shape parse_shape(const json& j, const std::string& source, const std::string& where, bool paper) {
    jsonio::require_object(j, source, where);
    const std::string type = jsonio::get_string(j, "type", source, where);
    const auto& all = shape_keys();
    const auto found =
        std::find_if(all.begin(), all.end(), [&](const ShapeKeys& k) { return type == k.name; });
    if (found == all.end()) {
        std::string list;
        for (const auto& k : all) list += (list.empty() ? "" : ", ") + std::string(k.name);
        throw base::InputError(source, jsonio::join(where, "type"),
                               "unknown shape '" + type + "' (known: " + list + ")");
    }
    std::vector<std::string_view> keys = found->geometry;
    keys.insert(keys.end(), {"type", "profile"});
    if (paper) keys.push_back("texture");
    require_keys(j, keys, source, where, paper);
    Shape s;
    s.type = found->type;
    auto vec = [&](const char* key) { return jsonio::get_vec3(j, key, source, where); };
    auto length = [&](const char* key) {
        return jsonio::get_number(j, key, source, where, 1e-3, 1e4);
    };
    switch (s.type) {
        case ShapeType::sphere:
            s.a = vec("centre"), s.radius = length("radius");
            break;
        case ShapeType::ellipsoid:
            s.a = vec("centre"), s.b = vec("radii");
            if (!(glm::min(s.b.x, glm::min(s.b.y, s.b.z)) > 0.0))
                throw base::InputError(source, jsonio::join(where, "radii"), "must be > 0");
            break;
        case ShapeType::box:
            s.a = vec("min"), s.b = vec("max");
            if (!(s.b.x > s.a.x && s.b.y > s.a.y && s.b.z > s.a.z))
                throw base::InputError(source, jsonio::join(where, "max"),
                                       "must exceed min on every axis");
            break;
        case ShapeType::cylinder:
            s.a = vec("from"), s.b = vec("to"), s.radius = length("radius");
            if (!(glm::length(s.b - s.a) > 0.0))
                throw base::InputError(source, jsonio::join(where, "to"), "equals from");
            break;
        case ShapeType::wire: {
            if (!j.contains("at"))
                throw base::InputError(source, jsonio::join(where, "at"), "is required");
            const json& at = j.at("at");
            if (!at.is_array() || at.size() != 2 || !at[0].is_number() || !at[1].is_number())
                throw base::InputError(source, jsonio::join(where, "at"), "must be [x, y] (mm)");
            s.a = {at[0].get<double>(), at[1].get<double>(), 0.0};
            s.radius = length("radius");
            break;
        }
        case ShapeType::half_space:
            s.a = vec("point"), s.b = unit(j, "normal", source, where);
            break;
        case ShapeType::layer:
            s.a = vec("point"), s.b = unit(j, "normal", source, where);
            s.radius = length("thickness");
            break;
        case ShapeType::tube: {
            const json* path = j.contains("path") ? &j.at("path") : nullptr;
            if (!path || !path->is_array() || path->size() < 2)
                throw base::InputError(source, jsonio::join(where, "path"),
                                       "must be an array of at least two [x, y, z] points (mm)");
            for (std::size_t i = 0; i < path->size(); ++i) {
                const json& q = (*path)[i];
                if (!q.is_array() || q.size() != 3 ||
                    !std::all_of(q.begin(), q.end(), [](const json& v) { return v.is_number(); }))
                    throw base::InputError(source,
                                           jsonio::join(where, "path[" + std::to_string(i) + "]"),
                                           "must be [x, y, z] (mm)");
                s.path.push_back({q[0].get<double>(), q[1].get<double>(), q[2].get<double>()});
            }
            s.radius = length("radius");
            break;
        }
        case ShapeType::mesh: {
            const std::string file = jsonio::get_string(j, "file", source, where);
            std::filesystem::path path(file);
            if (path.is_relative()) path = std::filesystem::path(source).parent_path() / path;
            MeshTransform place;
            if (j.contains("scale")) {
                const std::string at = jsonio::join(where, "scale");
                place.scale =
                    j.at("scale").is_number()
                        ? glm::dvec3(jsonio::get_number(j, "scale", source, where, 1e-6, 1e6))
                        : vec("scale");
                if (!(glm::min(place.scale.x, glm::min(place.scale.y, place.scale.z)) > 0.0))
                    throw base::InputError(source, at, "must be > 0");
            }
            if (j.contains("rotate")) place.rotate_deg = vec("rotate");
            if (j.contains("translate")) place.translate_mm = vec("translate");
            TriangleMesh mesh = read_mesh_file(path.string());
            for (glm::dvec3& v : mesh.vertices) v = place.apply(v);
            s.mesh = std::make_shared<const MeshShape>(std::move(mesh), path.string());
            s.a = 0.5 * (s.mesh->lower() + s.mesh->upper());
            break;
        }
    }
    if (j.contains("profile")) {
        const std::string profile = jsonio::get_string(j, "profile", source, where);
        const bool radial = s.type == ShapeType::sphere || s.type == ShapeType::cylinder ||
                            s.type == ShapeType::wire || s.type == ShapeType::tube;
        if (profile == "parabolic" && radial)
            s.parabolic = true;
        else if (profile != "smooth")
            throw base::InputError(source, jsonio::join(where, "profile"),
                                   "must be 'smooth' or (sphere, cylinder, wire, tube) "
                                   "'parabolic', got '" +
                                       profile + "'");
    }
    if (paper) {
        s.paper_density = jsonio::get_number(j, "paper_density", source, where, 0.01, 100.0);
        if (j.contains("texture")) {
            const json& t = j.at("texture");
            const std::string at = jsonio::join(where, "texture");
            jsonio::require_object(t, source, at);
            jsonio::require_known_keys(t, {"amplitude", "cell"}, source, at);
            s.texture_amplitude = jsonio::get_number(t, "amplitude", source, at, 0.0, 100.0);
            s.texture_cell_mm = jsonio::get_number(t, "cell", source, at, 1e-3, 1e4);
        }
        return s;
    }
    std::string tissue_name;
    s.properties = tissue::read_properties(j, source, where, &tissue_name);
    s.label = tissue::tissue_label_of(tissue_name);
    return s;
}

// Whether a shape reaches into the box [0, size]: its anchor points clamped into the box
// (exact for spheres and half-spaces), then a 17^3 lattice of the box.
bool touches_box(const Shape& s, const glm::dvec3& size) {
    std::vector<glm::dvec3> anchors = {s.a};
    if (s.type == ShapeType::box || s.type == ShapeType::cylinder) anchors.push_back(s.b);
    if (s.type == ShapeType::box) anchors.push_back(0.5 * (s.a + s.b));
    anchors.insert(anchors.end(), s.path.begin(), s.path.end());
    for (const glm::dvec3& p : anchors) {
        glm::dvec3 q = glm::clamp(p, glm::dvec3(0.0), size);
        if (s.type == ShapeType::wire) q.z = 0.5 * size.z;
        if (s.signed_distance(q) <= 0.0) return true;
    }
    constexpr int kSteps = 16;
    for (int k = 0; k <= kSteps; ++k)
        for (int j = 0; j <= kSteps; ++j)
            for (int i = 0; i <= kSteps; ++i)
                if (s.signed_distance(glm::dvec3(i, j, k) / double(kSteps) * size) <= 0.0)
                    return true;
    return false;
}

tissue::PointTarget parse_target(const json& j, const glm::dvec3& size, const std::string& source,
                                 const std::string& where) {
    jsonio::require_object(j, source, where);
    jsonio::require_known_keys(j, {"type", "at", "axis", "diameter", "reflectivity", "comment"},
                               source, where);
    tissue::PointTarget t;
    const std::string type = jsonio::get_string(j, "type", source, where);
    if (type != "point" && type != "wire")
        throw base::InputError(source, jsonio::join(where, "type"),
                               "unknown target '" + type + "' (known: point, wire)");
    t.type = type == "wire" ? tissue::PointTarget::Type::wire : tissue::PointTarget::Type::point;
    const json* at = j.contains("at") ? &j.at("at") : nullptr;
    const std::size_t n = t.type == tissue::PointTarget::Type::wire ? 2 : 3;
    if (!at || !at->is_array() || at->size() != n ||
        !std::all_of(at->begin(), at->end(), [](const json& v) { return v.is_number(); }))
        throw base::InputError(
            source, jsonio::join(where, "at"),
            n == 2 ? "must be [x, y] (mm; a wire runs along z)" : "must be [x, y, z] (mm)");
    t.at = {(*at)[0].get<double>(), (*at)[1].get<double>(),
            n == 3 ? (*at)[2].get<double>() : 0.5 * size.z};
    for (std::size_t a = 0; a < n; ++a)
        if (!(t.at[int(a)] >= 0.0 && t.at[int(a)] <= size[int(a)]))
            throw base::InputError(source, jsonio::join(where, "at"),
                                   "lies outside the phantom (size " + base::number_text(size.x) +
                                       " x " + base::number_text(size.y) + " x " +
                                       base::number_text(size.z) + " mm from the origin)");
    if (j.contains("axis")) {
        if (t.type != tissue::PointTarget::Type::wire)
            throw base::InputError(source, jsonio::join(where, "axis"), "only a wire has an axis");
        const json& axis = j.at("axis");
        if (!axis.is_array() || axis.size() != 3 ||
            !std::all_of(axis.begin(), axis.end(), [](const json& v) { return v.is_number(); }))
            throw base::InputError(source, jsonio::join(where, "axis"),
                                   "must be a direction [x, y, z]");
        const glm::dvec3 v((axis)[0].get<double>(), axis[1].get<double>(), axis[2].get<double>());
        const double length = glm::length(v);
        if (!(std::isfinite(length) && length > 1e-9))
            throw base::InputError(source, jsonio::join(where, "axis"),
                                   "must be a non-zero, finite direction");
        t.axis = v / length;
    }
    if (auto d = jsonio::get_optional_number(j, "diameter", source, where, 1e-3, 2.0))
        t.diameter_mm = *d;
    if (auto r = jsonio::get_optional_number(j, "reflectivity", source, where, 1e-6, 1.0))
        t.reflectivity = *r;
    return t;
}

// The shape a target paints: the local tissue's speed (no refraction), the impedance that
// reflects `reflectivity` (Z_t = Z (1 + r) / (1 - r), through the density), no scatterers.
Shape target_core(const tissue::PointTarget& t, const Phantom& ph) {
    Shape s;
    s.type = t.type == tissue::PointTarget::Type::wire ? ShapeType::wire : ShapeType::sphere;
    s.a = t.at;
    if (s.type == ShapeType::wire && std::abs(t.axis.z) < 1.0 - 1e-12) {
        // A wire off the z axis: a cylinder through the whole phantom.
        const double through = glm::length(ph.size);
        s.type = ShapeType::cylinder;
        s.a = t.at - t.axis * through;
        s.b = t.at + t.axis * through;
    }
    s.radius = 0.5 * t.diameter_mm;
    s.properties = ph.at(t.at);
    const double r = std::min(t.reflectivity, 0.99);
    float& density = s.properties[tissue::Property::density];
    density = float(std::min(double(density) * (1.0 + r) / (1.0 - r),
                             tissue::info(tissue::Property::density).max));
    s.properties[tissue::Property::backscatter] = 0.0f;
    s.properties[tissue::Property::scatterer_density] = 0.0f;
    return s;
}

}  // namespace

double Shape::signed_distance(const glm::dvec3& p) const {
    switch (type) {
        case ShapeType::sphere:
            return glm::length(p - a) - radius;
        case ShapeType::ellipsoid: {
            const double smallest = glm::min(b.x, glm::min(b.y, b.z));
            return (glm::length((p - a) / b) - 1.0) * smallest;
        }
        case ShapeType::box: {
            const glm::dvec3 centre = 0.5 * (a + b), half = 0.5 * (b - a);
            const glm::dvec3 q = glm::abs(p - centre) - half;
            return glm::length(glm::max(q, 0.0)) + glm::min(glm::max(q.x, glm::max(q.y, q.z)), 0.0);
        }
        case ShapeType::cylinder: {
            const glm::dvec3 axis = b - a;
            const double len = glm::length(axis);
            const glm::dvec3 u = axis / len;
            const double along = glm::dot(p - a, u);
            const double across = glm::length(p - a - along * u);
            const glm::dvec2 d(across - radius, std::abs(along - 0.5 * len) - 0.5 * len);
            return glm::length(glm::max(d, 0.0)) + glm::min(glm::max(d.x, d.y), 0.0);
        }
        case ShapeType::wire:
            return glm::length(glm::dvec2(p.x - a.x, p.y - a.y)) - radius;
        case ShapeType::half_space:
            return -glm::dot(p - a, b);
        case ShapeType::layer:
            return std::abs(glm::dot(p - a, b) - 0.5 * radius) - 0.5 * radius;
        case ShapeType::mesh:
            return mesh->signed_distance(p);
        case ShapeType::tube: {
            double nearest = 1e30;
            for (std::size_t i = 0; i + 1 < path.size(); ++i) {
                const glm::dvec3 seg = path[i + 1] - path[i];
                const double t = std::clamp(
                    glm::dot(p - path[i], seg) / std::max(glm::dot(seg, seg), 1e-30), 0.0, 1.0);
                nearest = std::min(nearest, glm::length(p - path[i] - t * seg));
            }
            return nearest - radius;
        }
    }
    return 1e30;
}

double Shape::weight(const glm::dvec3& p, double smoothing_mm, double* steady_mm) const {
    if (steady_mm) *steady_mm = 0.0;
    // Beyond the ramp's reach of a mesh's bounding box: no surface search.
    if (type == ShapeType::mesh) {
        const double to_bounds = mesh->distance_to_bounds(p);
        if (to_bounds > 0.5 * smoothing_mm) {
            if (steady_mm) *steady_mm = to_bounds - 0.5 * smoothing_mm;
            return 0.0;
        }
    }
    const double d = signed_distance(p);
    // Past the ramp the weight is 0 or 1 until the distance reaches it again.
    if (steady_mm && type == ShapeType::mesh && !parabolic)
        *steady_mm = std::max(0.0, std::abs(d) - 0.5 * smoothing_mm);
    if (parabolic) {  // distance from the axis = d + radius
        const double rho = (d + radius) / radius;
        return std::max(0.0, 1.0 - rho * rho);
    }
    // Linear ramp across the boundary: inside fully at -w/2, outside at +w/2.
    return smoothing_mm > 0.0 ? std::clamp(0.5 - d / smoothing_mm, 0.0, 1.0)
                              : (d <= 0.0 ? 1.0 : 0.0);
}

double value_noise(double x, double y, double cell) {
    auto hash = [](int i, int j) {
        uint32_t h = uint32_t(i) * 0x8da6b343u ^ uint32_t(j) * 0xd8163841u;
        h ^= h >> 13, h *= 0x5bd1e995u, h ^= h >> 15;
        return double(h & 0xffffff) / double(0xffffff) * 2.0 - 1.0;
    };
    const double fx = x / cell, fy = y / cell;
    const int i = int(std::floor(fx)), j = int(std::floor(fy));
    auto smooth = [](double t) { return t * t * (3 - 2 * t); };
    const double tx = smooth(fx - i), ty = smooth(fy - j);
    const double a = hash(i, j) * (1 - tx) + hash(i + 1, j) * tx;
    const double b = hash(i, j + 1) * (1 - tx) + hash(i + 1, j + 1) * tx;
    return a * (1 - ty) + b * ty;
}

double Phantom::paper_density_at(const glm::dvec3& p) const {
    double d = background_paper_density;
    for (const Shape& s : shapes) {
        const double inside = s.weight(p, smoothing_mm);
        if (inside <= 0.0) continue;
        double target = s.paper_density;
        if (s.texture_amplitude > 0.0)
            target += s.texture_amplitude * value_noise(p.x, p.y, s.texture_cell_mm);
        d += inside * (target - d);
    }
    return d;
}

tissue::AcousticProperties Phantom::at(const glm::dvec3& p, int* label, int* instance) const {
    std::vector<double> weights(shapes.size());
    for (std::size_t k = 0; k < shapes.size(); ++k) weights[k] = shapes[k].weight(p, smoothing_mm);
    return blend(weights.data(), label, instance);
}

tissue::AcousticProperties Phantom::blend(const double* weights, int* label, int* instance) const {
    tissue::AcousticProperties value = background;
    int l = background_label, which = 0;
    for (std::size_t k = 0; k < shapes.size(); ++k) {
        const Shape& s = shapes[k];
        const double inside = weights[k];
        if (inside <= 0.0) continue;
        for (std::size_t n = 0; n < tissue::kPropertyCount; ++n)
            value.values[n] =
                float(value.values[n] + inside * (s.properties.values[n] - value.values[n]));
        if (inside >= 0.5) l = s.label, which = int(k) + 1;
    }
    if (label) *label = l;
    if (instance) *instance = which;
    return value;
}

Phantom parse_phantom(const json& j, const std::string& source) {
    jsonio::require_known_keys(
        j,
        {"name", "description", "size", "resolution", "smoothing", "background", "shapes", "probe",
         "comment", "mode", "source", "trace", "targets"},
        source, "");
    Phantom ph;
    ph.source = source;
    ph.name = jsonio::get_string(j, "name", source, "");
    if (j.contains("description"))
        ph.description = jsonio::get_string(j, "description", source, "");
    ph.size = jsonio::get_vec3(j, "size", source, "");
    for (int a = 0; a < 3; ++a)
        if (!(ph.size[a] > 0.0 && ph.size[a] <= 1e4))
            throw base::InputError(source, "size", "every extent must be in (0, 10000] mm");
    if (auto r = jsonio::get_optional_number(j, "resolution", source, "", 1e-3, 100.0))
        ph.resolution_mm = *r;
    if (auto w = jsonio::get_optional_number(j, "smoothing", source, "", 0.0, 100.0))
        ph.smoothing_mm = *w;
    // The whole phantom rasterised at its resolution (property maps, 4 bytes a field)
    // must fit: an absurd resolution fails here, not in an allocation.
    const glm::dvec3 texels = glm::floor(ph.size / ph.resolution_mm) + 1.0;
    base::check_allocation(texels.x * texels.y * texels.z * 4.0 * double(tissue::kPropertyCount),
                           source, "resolution");
    if (j.contains("mode")) {
        const std::string mode = jsonio::get_string(j, "mode", source, "");
        if (mode != "acoustic" && mode != "paper")
            throw base::InputError(source, "mode",
                                   "must be 'acoustic' or 'paper', got '" + mode + "'");
        ph.paper_mode = mode == "paper";
    }
    if (!j.contains("background")) throw base::InputError(source, "background", "is required");
    {
        const json& b = j.at("background");
        jsonio::require_object(b, source, "background");
        require_keys(b, {}, source, "background", ph.paper_mode);
        if (ph.paper_mode) {
            ph.background_paper_density =
                jsonio::get_number(b, "paper_density", source, "background", 0.01, 100.0);
        } else {
            std::string tissue_name;
            ph.background = tissue::read_properties(b, source, "background", &tissue_name);
            ph.background_label = tissue::tissue_label_of(tissue_name);
        }
    }
    if (j.contains("shapes")) {
        const json& shapes = j.at("shapes");
        if (!shapes.is_array()) throw base::InputError(source, "shapes", "must be an array");
        for (std::size_t i = 0; i < shapes.size(); ++i) {
            const std::string where = "shapes[" + std::to_string(i) + "]";
            ph.shapes.push_back(parse_shape(shapes[i], source, where, ph.paper_mode));
            if (!touches_box(ph.shapes.back(), ph.size))
                throw base::InputError(source, where,
                                       "lies entirely outside the phantom (size " +
                                           base::number_text(ph.size.x) + " x " +
                                           base::number_text(ph.size.y) + " x " +
                                           base::number_text(ph.size.z) + " mm from the origin)");
        }
    }
    if (j.contains("targets")) {
        const json& targets = j.at("targets");
        if (!targets.is_array()) throw base::InputError(source, "targets", "must be an array");
        if (ph.paper_mode)
            throw base::InputError(source, "targets", "are not imaged in paper mode");
        for (std::size_t i = 0; i < targets.size(); ++i) {
            const std::string where = "targets[" + std::to_string(i) + "]";
            ph.targets.push_back(parse_target(targets[i], ph.size, source, where));
            ph.shapes.push_back(target_core(ph.targets.back(), ph));
        }
    }
    if (j.contains("source")) {
        const json& src = j.at("source");
        jsonio::require_object(src, source, "source");
        jsonio::require_known_keys(
            src, {"type", "at", "direction", "half_angle", "width", "particles", "comment"}, source,
            "source");
        ParticleSource ps;
        const std::string type = jsonio::get_string(src, "type", source, "source");
        if (type != "fan" && type != "parallel")
            throw base::InputError(source, "source.type",
                                   "must be 'fan' or 'parallel', got '" + type + "'");
        ps.type = type == "fan" ? ParticleSource::Type::fan : ParticleSource::Type::parallel;
        auto vec2 = [&](const char* key) {
            const json* v = src.contains(key) ? &src.at(key) : nullptr;
            if (!v || !v->is_array() || v->size() != 2 || !(*v)[0].is_number() ||
                !(*v)[1].is_number())
                throw base::InputError(source, std::string("source.") + key, "must be [x, y]");
            return glm::dvec2((*v)[0].get<double>(), (*v)[1].get<double>());
        };
        ps.at = vec2("at");
        ps.direction = vec2("direction");
        if (!(glm::length(ps.direction) > 0.0))
            throw base::InputError(source, "source.direction", "must not be zero");
        ps.direction = glm::normalize(ps.direction);
        if (ps.type == ParticleSource::Type::fan)
            ps.half_angle_deg = jsonio::get_number(src, "half_angle", source, "source", 0.0, 89.0);
        else
            ps.width_mm = jsonio::get_number(src, "width", source, "source", 1e-3, 1e4);
        ps.particles = int(jsonio::get_number(src, "particles", source, "source", 1.0, 1e7));
        ph.injection = ps;
    }
    if (j.contains("trace")) {
        jsonio::require_object(j.at("trace"), source, "trace");
        ph.trace = j.at("trace");
    }
    glm::dvec3 at(0.5 * ph.size.x, 0.0, 0.5 * ph.size.z), beam(0, 1, 0), lateral(1, 0, 0);
    if (j.contains("probe")) {
        const json& p = j.at("probe");
        jsonio::require_known_keys(p, {"preset", "at", "beam", "lateral", "comment"}, source,
                                   "probe");
        if (p.contains("preset"))
            ph.probe_preset = jsonio::get_string(p, "preset", source, "probe");
        if (p.contains("at")) at = jsonio::get_vec3(p, "at", source, "probe");
        if (p.contains("beam")) beam = unit(p, "beam", source, "probe");
        if (p.contains("lateral")) lateral = unit(p, "lateral", source, "probe");
    }
    try {
        ph.pose = probe::Pose::looking(at, beam, lateral);
    } catch (const std::invalid_argument&) {
        throw base::InputError(source, "probe.lateral", "is parallel to the beam");
    }
    return ph;
}

Phantom load_phantom(const std::string& path) {
    return parse_phantom(jsonio::read_file(path), path);
}

tissue::Volume rasterise_paper_density(const Phantom& phantom, const tissue::VolumeGeometry& grid) {
    tissue::Volume d(grid);
    const glm::ivec3 n = grid.dims;
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        for (int i = 0; i < n.x; ++i)
            d.at(i, j, k) = float(
                phantom.paper_density_at(grid.index_to_world({double(i), double(j), double(k)})));
    });
    return d;
}

tissue::VolumeGeometry plane_grid_2d(const Phantom& phantom) {
    tissue::VolumeGeometry g;
    const double h = phantom.resolution_mm;
    g.dims = {int(std::floor(phantom.size.x / h)) + 1, int(std::floor(phantom.size.y / h)) + 1, 1};
    g.spacing = {h, h, h};
    g.origin = {0.0, 0.0, 0.5 * phantom.size.z};
    return g;
}

tissue::PropertyMaps rasterise(const Phantom& phantom, const tissue::VolumeGeometry& grid,
                               tissue::Volume* labels, tissue::Volume* instances) {
    tissue::PropertyMaps maps;
    for (auto& f : maps.fields) f = tissue::Volume(grid);
    if (labels) *labels = tissue::Volume(grid);
    if (instances) *instances = tissue::Volume(grid);
    const glm::ivec3 n = grid.dims;
    const std::size_t count = phantom.shapes.size();
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        // Along the row each shape's weight is kept while the row has not gone as far as
        // the distance it is steady over (Shape::weight): a mesh's surface is searched
        // near it only. The same weights as Phantom::at's, so the same maps.
        std::vector<double> weight(count), steady(count, 0.0), gone(count, 0.0);
        glm::dvec3 previous(0.0);
        for (int i = 0; i < n.x; ++i) {
            const glm::dvec3 at = grid.index_to_world({double(i), double(j), double(k)});
            const double step = i > 0 ? glm::length(at - previous) : 0.0;
            previous = at;
            for (std::size_t m = 0; m < count; ++m) {
                gone[m] += step;
                // A margin of 1e-9 of the distance for its rounding.
                if (i > 0 && gone[m] < steady[m] * (1.0 - 1e-9) - 1e-9) continue;
                weight[m] = phantom.shapes[m].weight(at, phantom.smoothing_mm, &steady[m]);
                gone[m] = 0.0;
            }
            int label = 0, instance = 0;
            const tissue::AcousticProperties p = phantom.blend(weight.data(), &label, &instance);
            for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                maps.fields[f].at(i, j, k) = p.values[f];
            if (labels) labels->at(i, j, k) = float(label);
            if (instances) instances->at(i, j, k) = float(instance);
        }
    });
    return maps;
}

}  // namespace sonotrace::phantoms
