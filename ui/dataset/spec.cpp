#include "ui/dataset/spec.h"

#include "sonotrace_version.h"

#include <cmath>
#include <filesystem>

#include "tissue/base/error.h"
#include "tissue/base/file_read.h"
#include "tissue/base/file_status.h"
#include "tissue/base/hash.h"
#include "tissue/base/json_util.h"
#include "tissue/image_io.h"

namespace sonotrace::dataset {

namespace {

using base::InputError;
using nlohmann::json;
namespace jsonio = base::jsonio;

// A number, or [low, high] with low <= high, within [min, max].
Range read_range(const json& j, const std::string& key, const std::string& source, double min,
                 double max) {
    Range r;
    if (!j.contains(key)) return r;
    const json& v = j[key];
    r.set = true;
    if (v.is_number()) {
        r.low = r.high = jsonio::get_number(j, key, source, "", min, max);
        return r;
    }
    if (!v.is_array() || v.size() != 2)
        throw InputError(source, key, "must be a number or [low, high]");
    const json pair = {{"low", v[0]}, {"high", v[1]}};
    r.low = jsonio::get_number(pair, "low", source, key, min, max);
    r.high = jsonio::get_number(pair, "high", source, key, min, max);
    if (r.low > r.high) throw InputError(source, key, "low must not exceed high");
    return r;
}

// Uniform in [0, 1) from (seed, frame, draw): 53 bits of a counter-based hash.
double uniform(uint64_t seed, uint64_t frame, uint64_t draw) {
    const uint64_t h = base::mix64(base::mix64(base::mix64(seed ^ 0x64617461ull) ^ frame) ^ draw);
    return double(h >> 11) * 0x1.0p-53;
}

double draw_in(const Range& r, double fallback, uint64_t seed, uint64_t frame, uint64_t draw) {
    if (!r.set) return fallback;
    return r.low + (r.high - r.low) * uniform(seed, frame, draw);
}

// The spec with every whole number written as an integer: "frames": 8.0 and 8 are one
// spec (JSON does not tell them apart in meaning, nlohmann's dump does in text).
json canonical_numbers(const json& j) {
    if (j.is_number_float()) {
        const double v = j.get<double>();
        if (std::isfinite(v) && v == std::floor(v) && std::abs(v) < 9007199254740992.0)
            return json(int64_t(v));
        return j;
    }
    if (!j.is_structured()) return j;
    json out = j;
    for (auto it = out.begin(); it != out.end(); ++it) *it = canonical_numbers(*it);
    return out;
}

}  // namespace

uint64_t Spec::digest() const {
    uint64_t h = 0x73706563ull;
    for (const char c : canonical) h = base::mix64(h ^ uint8_t(c));
    return base::mix64(h ^ inputs);
}

Spec parse_spec(const json& j, const std::string& source) {
    jsonio::require_object(j, source, "");
    jsonio::require_known_keys(j,
                               {"comment", "frames", "frames_per_shard", "seed", "image", "sources",
                                "probes", "frequency_mhz", "depth_mm", "focus_mm", "gain_db",
                                "dynamic_range_db", "pose", "disable", "quality", "trace", "write"},
                               source, "");
    Spec spec;
    spec.path = source;
    spec.canonical = canonical_numbers(j).dump();
    spec.frames = uint64_t(jsonio::get_number(j, "frames", source, "", 1, 1e8));
    if (j.contains("frames_per_shard"))
        spec.frames_per_shard =
            uint64_t(jsonio::get_number(j, "frames_per_shard", source, "", 1, 1e5));
    if (j.contains("seed"))
        spec.seed = uint64_t(jsonio::get_number(j, "seed", source, "", 0, 0x1p53));
    for (const auto& [key, value] :
         {std::pair{"frames", spec.frames}, std::pair{"frames_per_shard", spec.frames_per_shard},
          std::pair{"seed", spec.seed}})
        if (j.contains(key) && double(value) != j[key].get<double>())
            throw InputError(source, key, "must be a whole number");
    if (j.contains("image")) {
        const json& image = j["image"];
        jsonio::require_object(image, source, "image");
        jsonio::require_known_keys(image, {"width", "height"}, source, "image");
        if (image.contains("width"))
            spec.width = int(jsonio::get_number(image, "width", source, "image", 4, 4096));
        if (image.contains("height"))
            spec.height = int(jsonio::get_number(image, "height", source, "image", 4, 4096));
    }
    // -- sources
    if (!j.contains("sources") || !j["sources"].is_array() || j["sources"].empty())
        throw InputError(source, "sources", "needs a list of at least one source");
    const std::filesystem::path base = std::filesystem::path(source).parent_path();
    for (std::size_t n = 0; n < j["sources"].size(); ++n) {
        const json& s = j["sources"][n];
        const std::string where = "sources[" + std::to_string(n) + "]";
        jsonio::require_object(s, source, where);
        jsonio::require_known_keys(s, {"scene", "phantom", "volume", "tf", "spacing", "weight"},
                                   source, where);
        SourceSpec out;
        if (s.contains("weight"))
            out.weight = jsonio::get_number(s, "weight", source, where, 1e-9, 1e9);
        const int kinds =
            int(s.contains("scene")) + int(s.contains("phantom")) + int(s.contains("volume"));
        if (kinds != 1)
            throw InputError(source, where, "needs exactly one of scene, phantom and volume");
        // Files are relative to the spec's directory, as a shell user would expect of a
        // file that names others.
        // A volume may be an image-stack pattern (img_%03d.png); a phantom is one file.
        auto file = [&](const std::string& key) {
            const std::string name = jsonio::get_string(s, key, source, where);
            const std::filesystem::path p(name);
            const std::string resolved = p.is_absolute() ? name : (base / p).string();
            const std::string field = jsonio::join(where, key);
            if (base::file_status(resolved, source, field).type() ==
                std::filesystem::file_type::not_found) {
                if (key != "volume" || name.find('%') == std::string::npos)
                    throw InputError(source, field, "no such file: " + resolved);
                try {  // an image-stack pattern: at least its first file must exist
                    tissue::list_image_stack(resolved);
                } catch (const InputError& e) {
                    throw InputError(source, field, e.what());
                }
            }
            return resolved;
        };
        if (s.contains("scene")) {
            const std::string scene = jsonio::get_string(s, "scene", source, where);
            if (scene != "head-craniotomy" && scene != "head-temporal")
                throw InputError(source, jsonio::join(where, "scene"),
                                 "must be head-craniotomy or head-temporal, got '" + scene + "'");
            out.scene.view = scene == "head-temporal" ? "temporal" : "craniotomy";
            out.label = scene;
        } else if (s.contains("phantom")) {
            out.scene.phantom = file("phantom");
            out.label = "phantom:" + jsonio::get_string(s, "phantom", source, where);
        } else {
            out.scene.volume = file("volume");
            out.label = "volume:" + jsonio::get_string(s, "volume", source, where);
        }
        if (s.contains("tf") || s.contains("spacing")) {
            if (!s.contains("volume"))
                throw InputError(source, where, "tf and spacing belong to a volume source");
            if (s.contains("tf")) out.scene.tf = jsonio::get_string(s, "tf", source, where);
            if (s.contains("spacing"))
                out.scene.spacing = jsonio::get_string(s, "spacing", source, where);
        }
        // What the source's files hold (an image stack: each of its files).
        auto add_content = [&](const std::string& path, const std::string& key) {
            const std::string field = jsonio::join(where, key);
            if (path.find('%') != std::string::npos &&
                base::file_status(path, source, field).type() ==
                    std::filesystem::file_type::not_found) {
                for (const std::string& member : tissue::list_image_stack(path))
                    spec.inputs = base::mix64(spec.inputs ^ base::content_digest(member, field));
                return;
            }
            spec.inputs = base::mix64(spec.inputs ^ base::content_digest(path, field));
        };
        if (!out.scene.phantom.empty()) add_content(out.scene.phantom, "phantom");
        if (s.contains("volume")) add_content(out.scene.volume, "volume");
        if (!out.scene.tf.empty()) {  // a file, or a preset's name (its table is the program's)
            const std::filesystem::path p(out.scene.tf);
            const std::string resolved = p.is_absolute() ? out.scene.tf : (base / p).string();
            if (base::file_status(resolved, source, jsonio::join(where, "tf")).type() ==
                std::filesystem::file_type::regular)
                add_content(resolved, "tf");
        }
        spec.sources.push_back(std::move(out));
    }
    // The program's version: another version may make other frames of the same spec.
    for (const char c : std::string(SONOTRACE_VERSION))
        spec.inputs = base::mix64(spec.inputs ^ uint8_t(c));
    // -- probes and parameter ranges
    if (j.contains("probes")) {
        const json& p = j["probes"];
        if (!p.is_array() || p.empty())
            throw InputError(source, "probes", "needs a list of presets");
        for (std::size_t n = 0; n < p.size(); ++n) {
            if (!p[n].is_string())
                throw InputError(source, "probes[" + std::to_string(n) + "]",
                                 "must be a preset name");
            spec.probes.push_back(p[n].get<std::string>());
            std::string names;
            bool known = false;
            for (const probe::Transducer& t : probe::transducer_presets()) {
                known = known || t.name == spec.probes.back();
                names += (names.empty() ? "" : ", ") + t.name;
            }
            if (!known)
                throw InputError(
                    source, "probes[" + std::to_string(n) + "]",
                    "unknown preset '" + spec.probes.back() + "' (presets: " + names + ")");
        }
    }
    spec.frequency_mhz = read_range(j, "frequency_mhz", source, 0.1, 100.0);
    spec.depth_mm = read_range(j, "depth_mm", source, 1.0, 500.0);
    spec.focus_mm = read_range(j, "focus_mm", source, 1.0, 500.0);
    spec.gain_db = read_range(j, "gain_db", source, -100.0, 150.0);
    spec.dynamic_range_db = read_range(j, "dynamic_range_db", source, 1.0, 200.0);
    if (j.contains("pose")) {
        const json& pose = j["pose"];
        jsonio::require_object(pose, source, "pose");
        jsonio::require_known_keys(pose, {"lateral_mm", "elevation_mm", "rotation_deg", "tilt_deg"},
                                   source, "pose");
        auto half = [&](const char* key, double max) {
            return jsonio::get_optional_number(pose, key, source, "pose", 0.0, max).value_or(0.0);
        };
        spec.lateral_mm = half("lateral_mm", 100.0);
        spec.elevation_mm = half("elevation_mm", 100.0);
        spec.rotation_deg = half("rotation_deg", 180.0);
        spec.tilt_deg = half("tilt_deg", 60.0);
    }
    if (j.contains("disable")) {
        const json& d = j["disable"];
        if (!d.is_array()) throw InputError(source, "disable", "must be a list of physics names");
        for (std::size_t n = 0; n < d.size(); ++n) {
            if (!d[n].is_string())
                throw InputError(source, "disable[" + std::to_string(n) + "]", "must be a name");
            spec.disable += (spec.disable.empty() ? "" : ",") + d[n].get<std::string>();
        }
        imaging::disabled_physics(spec.disable, source, "disable");  // names checked here
    }
    if (j.contains("trace")) {
        const std::string trace = jsonio::get_string(j, "trace", source, "");
        if (trace != "2d" && trace != "3d")
            throw InputError(source, "trace", "must be 2d or 3d, got '" + trace + "'");
        spec.trace_dimensions = trace == "3d" ? 3 : 2;
    }
    if (j.contains("quality")) {
        spec.quality =
            imaging::parse_quality(jsonio::get_string(j, "quality", source, ""), source, "quality");
    }
    if (j.contains("write")) {
        const json& w = j["write"];
        if (!w.is_array() || w.empty())
            throw InputError(source, "write", "needs a list of outputs");
        spec.write_bmode = spec.write_labels = false;
        for (std::size_t n = 0; n < w.size(); ++n) {
            const std::string name = w[n].is_string() ? w[n].get<std::string>() : "";
            bool* flag = name == "bmode"         ? &spec.write_bmode
                         : name == "labels"      ? &spec.write_labels
                         : name == "labels_echo" ? &spec.write_echo_labels
                         : name == "envelope"    ? &spec.write_envelope
                         : name == "rf"          ? &spec.write_rf
                         : name == "energy"      ? &spec.write_energy
                                                 : nullptr;
            if (!flag)
                throw InputError(source, "write[" + std::to_string(n) + "]",
                                 "must be bmode, labels, labels_echo, envelope, rf or energy");
            *flag = true;
        }
    }
    return spec;
}

Spec read_spec(const std::string& path) {
    return parse_spec(base::jsonio::read_file(path), path);
}

FrameDraw draw_frame(const Spec& spec, uint64_t index) {
    // Draw numbers are fixed per quantity, so adding a range to a spec changes only that
    // quantity's values, not the others'.
    enum : uint64_t {
        kSeed,
        kSource,
        kProbe,
        kFrequency,
        kDepth,
        kFocus,
        kGain,
        kRange,
        kLateral,
        kElevation,
        kRotation,
        kTilt
    };
    FrameDraw d;
    d.index = index;
    d.seed = base::mix64(spec.seed ^ base::mix64(index + 0x9e3779b97f4a7c15ull)) >> 11;
    double total = 0.0;
    for (const SourceSpec& s : spec.sources) total += s.weight;
    double pick = uniform(spec.seed, index, kSource) * total;
    d.source = int(spec.sources.size()) - 1;
    for (std::size_t n = 0; n < spec.sources.size(); ++n) {
        pick -= spec.sources[n].weight;
        if (pick < 0.0) {
            d.source = int(n);
            break;
        }
    }
    if (!spec.probes.empty())
        d.probe = spec.probes[std::min(
            spec.probes.size() - 1,
            std::size_t(uniform(spec.seed, index, kProbe) * double(spec.probes.size())))];
    d.frequency_mhz = draw_in(spec.frequency_mhz, 0.0, spec.seed, index, kFrequency);
    d.depth_mm = draw_in(spec.depth_mm, 0.0, spec.seed, index, kDepth);
    d.focus_mm = draw_in(spec.focus_mm, 0.0, spec.seed, index, kFocus);
    d.gain_db = draw_in(spec.gain_db, 36.0, spec.seed, index, kGain);
    d.dynamic_range_db = draw_in(spec.dynamic_range_db, 60.0, spec.seed, index, kRange);
    auto symmetric = [&](double half, uint64_t draw) {
        return half * (2.0 * uniform(spec.seed, index, draw) - 1.0);
    };
    d.lateral_mm = symmetric(spec.lateral_mm, kLateral);
    d.elevation_mm = symmetric(spec.elevation_mm, kElevation);
    d.rotation_deg = symmetric(spec.rotation_deg, kRotation);
    d.tilt_deg = symmetric(spec.tilt_deg, kTilt);
    return d;
}

}  // namespace sonotrace::dataset
