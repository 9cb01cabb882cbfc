#include "phantoms/phantom.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "tissue/error.h"
#include "tissue/json_util.h"
#include "tissue/transfer_function.h"

namespace sonotrace::phantoms {

namespace {

using nlohmann::json;
namespace jsonio = tissue::jsonio;

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
    };
    return keys;
}

// The keys of a shape (`geometry`, its type) or of the background: plus the properties.
void require_keys(const json& object, std::vector<std::string_view> keys, const std::string& source,
                  const std::string& where) {
    for (const auto& p : tissue::kPropertyInfo) keys.push_back(p.key);
    keys.insert(keys.end(), {"tissue", "comment"});
    jsonio::require_known_keys(object, keys, source, where);
}

glm::dvec3 unit(const json& object, const std::string& key, const std::string& source,
                const std::string& where) {
    const glm::dvec3 v = jsonio::get_vec3(object, key, source, where);
    if (!(glm::length(v) > 0.0))
        throw tissue::InputError(source, jsonio::join(where, key), "must not be zero");
    return glm::normalize(v);
}

Shape parse_shape(const json& j, const std::string& source, const std::string& where) {
    jsonio::require_object(j, source, where);
    const std::string type = jsonio::get_string(j, "type", source, where);
    const auto& all = shape_keys();
    const auto found =
        std::find_if(all.begin(), all.end(), [&](const ShapeKeys& k) { return type == k.name; });
    if (found == all.end()) {
        std::string list;
        for (const auto& k : all) list += (list.empty() ? "" : ", ") + std::string(k.name);
        throw tissue::InputError(source, jsonio::join(where, "type"),
                                 "unknown shape '" + type + "' (known: " + list + ")");
    }
    std::vector<std::string_view> keys = found->geometry;
    keys.push_back("type");
    require_keys(j, keys, source, where);
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
                throw tissue::InputError(source, jsonio::join(where, "radii"), "must be > 0");
            break;
        case ShapeType::box:
            s.a = vec("min"), s.b = vec("max");
            if (!(s.b.x > s.a.x && s.b.y > s.a.y && s.b.z > s.a.z))
                throw tissue::InputError(source, jsonio::join(where, "max"),
                                         "must exceed min on every axis");
            break;
        case ShapeType::cylinder:
            s.a = vec("from"), s.b = vec("to"), s.radius = length("radius");
            if (!(glm::length(s.b - s.a) > 0.0))
                throw tissue::InputError(source, jsonio::join(where, "to"), "equals from");
            break;
        case ShapeType::wire: {
            if (!j.contains("at"))
                throw tissue::InputError(source, jsonio::join(where, "at"), "is required");
            const json& at = j.at("at");
            if (!at.is_array() || at.size() != 2 || !at[0].is_number() || !at[1].is_number())
                throw tissue::InputError(source, jsonio::join(where, "at"), "must be [x, y] (mm)");
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
    }
    std::string tissue_name;
    s.properties = tissue::read_properties(j, source, where, &tissue_name);
    s.label = tissue::tissue_label_of(tissue_name);
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
    }
    return 1e30;
}

tissue::AcousticProperties Phantom::at(const glm::dvec3& p, int* label) const {
    tissue::AcousticProperties value = background;
    int l = background_label;
    for (const Shape& s : shapes) {
        const double d = s.signed_distance(p);
        // Linear ramp across the boundary: inside fully at -w/2, outside at +w/2.
        const double inside = smoothing_mm > 0.0 ? std::clamp(0.5 - d / smoothing_mm, 0.0, 1.0)
                                                 : (d <= 0.0 ? 1.0 : 0.0);
        if (inside <= 0.0) continue;
        for (std::size_t n = 0; n < tissue::kPropertyCount; ++n)
            value.values[n] =
                float(value.values[n] + inside * (s.properties.values[n] - value.values[n]));
        if (inside >= 0.5) l = s.label;
    }
    if (label) *label = l;
    return value;
}

Phantom parse_phantom(const json& j, const std::string& source) {
    jsonio::require_known_keys(j,
                               {"name", "description", "size", "resolution", "smoothing",
                                "background", "shapes", "probe", "comment"},
                               source, "");
    Phantom ph;
    ph.source = source;
    ph.name = jsonio::get_string(j, "name", source, "");
    if (j.contains("description"))
        ph.description = jsonio::get_string(j, "description", source, "");
    ph.size = jsonio::get_vec3(j, "size", source, "");
    for (int a = 0; a < 3; ++a)
        if (!(ph.size[a] > 0.0 && ph.size[a] <= 1e4))
            throw tissue::InputError(source, "size", "every extent must be in (0, 10000] mm");
    if (auto r = jsonio::get_optional_number(j, "resolution", source, "", 1e-3, 100.0))
        ph.resolution_mm = *r;
    if (auto w = jsonio::get_optional_number(j, "smoothing", source, "", 0.0, 100.0))
        ph.smoothing_mm = *w;
    if (!j.contains("background")) throw tissue::InputError(source, "background", "is required");
    {
        const json& b = j.at("background");
        require_keys(b, {}, source, "background");
        std::string tissue_name;
        ph.background = tissue::read_properties(b, source, "background", &tissue_name);
        ph.background_label = tissue::tissue_label_of(tissue_name);
    }
    if (j.contains("shapes")) {
        const json& shapes = j.at("shapes");
        if (!shapes.is_array()) throw tissue::InputError(source, "shapes", "must be an array");
        for (std::size_t i = 0; i < shapes.size(); ++i)
            ph.shapes.push_back(
                parse_shape(shapes[i], source, "shapes[" + std::to_string(i) + "]"));
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
        throw tissue::InputError(source, "probe.lateral", "is parallel to the beam");
    }
    return ph;
}

Phantom load_phantom(const std::string& path) {
    return parse_phantom(jsonio::read_file(path), path);
}

tissue::PropertyMaps rasterise(const Phantom& phantom, const tissue::VolumeGeometry& grid,
                               tissue::Volume* labels) {
    tissue::PropertyMaps maps;
    for (auto& f : maps.fields) f = tissue::Volume(grid);
    if (labels) *labels = tissue::Volume(grid);
    const glm::ivec3 n = grid.dims;
    tbb::parallel_for(0, n.y * n.z, [&](int row) {
        const int j = row % n.y, k = row / n.y;
        for (int i = 0; i < n.x; ++i) {
            int label = 0;
            const tissue::AcousticProperties p =
                phantom.at(grid.index_to_world({double(i), double(j), double(k)}), &label);
            for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                maps.fields[f].at(i, j, k) = p.values[f];
            if (labels) labels->at(i, j, k) = float(label);
        }
    });
    return maps;
}

}  // namespace sonotrace::phantoms
