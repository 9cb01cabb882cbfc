#include "ui/dataset/spec.h"

#include "sonotrace_version.h"

#include <cmath>
#include <filesystem>
#include <variant>

#include "probe/transmit.h"
#include "tissue/base/error.h"
#include "tissue/base/file_read.h"
#include "tissue/base/file_status.h"
#include "tissue/base/hash.h"
#include "tissue/base/json_util.h"
#include "tissue/base/number_list.h"
#include "tissue/image_io.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::dataset {

namespace {

using base::InputError;
using nlohmann::json;
namespace jsonio = base::jsonio;

// A number, or [low, high] with low <= high, within [min, max]: `parent`.`key`.
Range read_range(const json& j, const std::string& key, const std::string& source,
                 const std::string& parent, double min, double max) {
    Range r;
    if (!j.contains(key)) return r;
    const json& v = j[key];
    const std::string field = jsonio::join(parent, key);
    r.set = true;
    if (v.is_number()) {
        r.low = r.high = jsonio::get_number(j, key, source, parent, min, max);
        return r;
    }
    if (!v.is_array() || v.size() != 2)
        throw InputError(source, field, "must be a number or [low, high]");
    const json pair = {{"low", v[0]}, {"high", v[1]}};
    r.low = jsonio::get_number(pair, "low", source, field, min, max);
    r.high = jsonio::get_number(pair, "high", source, field, min, max);
    if (r.low > r.high) throw InputError(source, field, "low must not exceed high");
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

// "transducer": {KEY: number or [low, high]} over the numeric transducer parameters;
// their ranges are Transducer::validate's (FrameMaker checks the corners).
void read_transducer_ranges(const json& j, const std::string& source, Spec& spec) {
    if (!j.contains("transducer")) return;
    const json& t = j["transducer"];
    jsonio::require_object(t, source, "transducer");
    const probe::Transducer any;
    std::string numeric;
    for (const auto& doc : probe::transducer_parameter_docs())
        if (!std::holds_alternative<std::string>(doc.get(any)))
            numeric += (numeric.empty() ? "" : ", ") + std::string(doc.key);
    for (const auto& [key, value] : t.items()) {
        const probe::TransducerParameterDoc* row = nullptr;
        for (const auto& doc : probe::transducer_parameter_docs())
            if (key == doc.key) row = &doc;
        if (!row || std::holds_alternative<std::string>(row->get(any)))
            throw InputError(source, jsonio::join("transducer", key),
                             "not a numeric transducer parameter (known: " + numeric + ")");
        TransducerRange r;
        r.key = key;
        r.whole = std::holds_alternative<int>(row->get(any));
        r.range = read_range(t, key, source, "transducer", -1e9, 1e9);
        if (r.whole) {
            r.range.low = std::ceil(r.range.low), r.range.high = std::floor(r.range.high);
            if (r.range.low > r.range.high)
                throw InputError(source, jsonio::join("transducer", key), "holds no whole number");
        }
        spec.transducer.push_back(r);
    }
}

// "tgc": {"slope": number or [low, high], "sliders": n, "slider_db": dB}.
void read_tgc_range(const json& j, const std::string& source, Spec& spec) {
    if (!j.contains("tgc")) return;
    const json& t = j["tgc"];
    jsonio::require_object(t, source, "tgc");
    jsonio::require_known_keys(t, {"slope", "sliders", "slider_db"}, source, "tgc");
    spec.tgc.set = true;
    spec.tgc.slope = read_range(t, "slope", source, "tgc", 0.0, 5.0);
    if (t.contains("sliders") != t.contains("slider_db"))
        throw InputError(source, "tgc", "sliders and slider_db go together");
    if (t.contains("sliders")) {
        const double n = jsonio::get_number(t, "sliders", source, "tgc", 2, 32);
        if (n != std::floor(n)) throw InputError(source, "tgc.sliders", "must be a whole number");
        spec.tgc.sliders = int(n);
        spec.tgc.slider_db = jsonio::get_number(t, "slider_db", source, "tgc", 0.0, 40.0);
    }
}

// "tissues": {TISSUE: {PROPERTY: number, [low, high] or {"spread": s}}}.
void read_tissue_ranges(const json& j, const std::string& source, Spec& spec) {
    if (!j.contains("tissues")) return;
    const json& tissues = j["tissues"];
    jsonio::require_object(tissues, source, "tissues");
    std::string properties;
    for (const auto& info : tissue::kPropertyInfo)
        properties += (properties.empty() ? "" : ", ") + std::string(info.key);
    for (const auto& [name, entry] : tissues.items()) {
        const std::string where = jsonio::join("tissues", name);
        const tissue::TissueEntry& table = tissue::find_tissue(name, source, where);
        jsonio::require_object(entry, source, where);
        for (const auto& [key, value] : entry.items()) {
            const std::string field = jsonio::join(where, key);
            std::size_t p = 0;
            while (p < tissue::kPropertyCount && tissue::kPropertyInfo[p].key != key) ++p;
            if (p == tissue::kPropertyCount)
                throw InputError(source, field, "unknown property (known: " + properties + ")");
            const tissue::PropertyInfo& info = tissue::kPropertyInfo[p];
            TissueRange r;
            r.tissue = name;
            r.label = tissue::tissue_label_of(name);
            r.property = tissue::Property(p);
            r.table_value = table.properties.values[p];
            if (value.is_object()) {
                jsonio::require_known_keys(value, {"spread"}, source, field);
                if (!value.contains("spread")) throw InputError(source, field, "needs spread");
                r.spread = jsonio::get_number(value, "spread", source, field, 0.0, 0.95);
            } else {
                r.values = read_range(entry, key, source, where, info.min, info.max);
                if (!(r.table_value > 0.0))
                    throw InputError(source, field,
                                     "is 0 for " + name +
                                         ": a value has nothing to scale; "
                                         "give the tissue's shapes explicit properties instead");
            }
            spec.tissues.push_back(r);
        }
    }
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
    // The keys of earlier versions, pointed to their new place.
    for (const auto& [old, now] : {std::pair{"frequency_mhz", "frequency"},
                                   std::pair{"depth_mm", "depth"}, std::pair{"focus_mm", "focus"}})
        if (j.contains(old))
            throw InputError(source, old,
                             std::string("is now \"transducer\": {\"") + now + "\": ...}");
    jsonio::require_known_keys(
        j,
        {"comment", "frames", "frames_per_shard", "seed", "image", "sources", "probes",
         "transducer", "gain_db", "dynamic_range_db", "tgc", "noise_snr_db", "tissues", "pose",
         "disable", "quality", "trace", "transmit", "write"},
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
    read_transducer_ranges(j, source, spec);
    spec.gain_db =
        read_range(j, "gain_db", source, "", imaging::kGainRange.low, imaging::kGainRange.high);
    spec.dynamic_range_db =
        read_range(j, "dynamic_range_db", source, "", imaging::kDynamicRangeRange.low,
                   imaging::kDynamicRangeRange.high);
    read_tgc_range(j, source, spec);
    spec.noise_snr_db = read_range(j, "noise_snr_db", source, "", imaging::kNoiseSnrRange.low,
                                   imaging::kNoiseSnrRange.high);
    read_tissue_ranges(j, source, spec);
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
    if (j.contains("transmit")) {
        spec.transmit = jsonio::get_string(j, "transmit", source, "");
        if (spec.transmit != "focused")
            probe::parse_transmit_scheme(spec.transmit, source, "transmit");
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
            bool* flag = name == "bmode"          ? &spec.write_bmode
                         : name == "labels"       ? &spec.write_labels
                         : name == "labels_echo"  ? &spec.write_echo_labels
                         : name == "depth"        ? &spec.write_depth
                         : name == "echogenicity" ? &spec.write_echogenicity
                         : name == "instances"    ? &spec.write_instances
                         : name == "envelope"     ? &spec.write_envelope
                         : name == "rf"           ? &spec.write_rf
                         : name == "energy"       ? &spec.write_energy
                         : name == "channels"     ? &spec.write_channels
                                                  : nullptr;
            if (!flag)
                throw InputError(source, "write[" + std::to_string(n) + "]",
                                 "must be bmode, labels, labels_echo, depth, echogenicity, "
                                 "instances, envelope, rf, energy or channels");
            *flag = true;
        }
        if (spec.write_channels && spec.transmit == "focused")
            throw InputError(source, "write",
                             "\"channels\" needs unfocused transmits: give "
                             "\"transmit\": \"plane:...\" or \"diverging:...\"");
    }
    return spec;
}

Spec read_spec(const std::string& path) {
    return parse_spec(base::jsonio::read_file(path), path);
}

namespace {

// The draw number of a named quantity: its name hashed, the top bit set so that it never
// meets the fixed numbers of draw_frame's enum.
uint64_t named_draw(const std::string& name) {
    uint64_t h = 0x6e616d65ull;
    for (const char c : name) h = base::mix64(h ^ uint8_t(c));
    return h | (uint64_t(1) << 63);
}

std::string transducer_column(const TransducerRange& r) {
    return "transducer." + r.key;
}
std::string tissue_column(const TissueRange& r) {
    return "tissues." + r.tissue + "." + std::string(tissue::info(r.property).key);
}
std::string slider_column(int k) {
    return "tgc.slider" + std::to_string(k);
}

}  // namespace

FrameDraw draw_frame(const Spec& spec, uint64_t index) {
    // Draw numbers are fixed per quantity (named ones by their column's name), so adding a
    // range to a spec changes only that quantity's values, not the others'.
    enum : uint64_t {
        kSeed,
        kSource,
        kProbe,
        kGain = 6,  // 3-5 were the frequency, depth and focus, now named
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
    auto in = [&](const Range& r, uint64_t draw) {
        return r.low + (r.high - r.low) * uniform(spec.seed, index, draw);
    };
    for (const TransducerRange& r : spec.transducer) {
        const uint64_t draw = named_draw(transducer_column(r));
        d.transducer.push_back(
            r.whole ? std::min(r.range.high,
                               r.range.low + std::floor(uniform(spec.seed, index, draw) *
                                                        (r.range.high - r.range.low + 1.0)))
                    : in(r.range, draw));
    }
    if (spec.gain_db.set) d.gain_db = in(spec.gain_db, kGain);
    d.dynamic_range_db = draw_in(spec.dynamic_range_db, 60.0, spec.seed, index, kRange);
    auto symmetric = [&](double half, uint64_t draw) {
        return half * (2.0 * uniform(spec.seed, index, draw) - 1.0);
    };
    d.lateral_mm = symmetric(spec.lateral_mm, kLateral);
    d.elevation_mm = symmetric(spec.elevation_mm, kElevation);
    d.rotation_deg = symmetric(spec.rotation_deg, kRotation);
    d.tilt_deg = symmetric(spec.tilt_deg, kTilt);
    if (spec.tgc.set) {
        d.tgc_slope = spec.tgc.slope.set ? in(spec.tgc.slope, named_draw("tgc.slope")) : 0.6;
        for (int k = 0; k < spec.tgc.sliders; ++k)
            d.tgc_sliders_db.push_back(symmetric(spec.tgc.slider_db, named_draw(slider_column(k))));
    }
    if (spec.noise_snr_db.set) d.noise_snr_db = in(spec.noise_snr_db, named_draw("noise_snr_db"));
    for (const TissueRange& r : spec.tissues) {
        const uint64_t draw = named_draw(tissue_column(r));
        tissue::LabelScale scale{r.label, r.property, 1.0};
        double value = 0.0;
        if (r.values.set) {
            value = in(r.values, draw);
            scale.factor = value / r.table_value;
        } else {
            scale.factor = 1.0 + symmetric(r.spread, draw);
            value = r.table_value * scale.factor;
        }
        d.tissue_scales.push_back(scale);
        d.tissue_values.push_back(value);
    }
    return d;
}

std::vector<DrawnValue> drawn_values(const Spec& spec, const FrameDraw& draw) {
    std::vector<DrawnValue> out;
    for (std::size_t n = 0; n < spec.transducer.size(); ++n)
        out.push_back({transducer_column(spec.transducer[n]), draw.transducer[n]});
    if (spec.tgc.set) {
        out.push_back({"tgc.slope", *draw.tgc_slope});
        for (int k = 0; k < spec.tgc.sliders; ++k)
            out.push_back({slider_column(k), draw.tgc_sliders_db[std::size_t(k)]});
    }
    if (spec.noise_snr_db.set) out.push_back({"noise_snr_db", *draw.noise_snr_db});
    for (std::size_t n = 0; n < spec.tissues.size(); ++n)
        out.push_back({tissue_column(spec.tissues[n]), draw.tissue_values[n]});
    return out;
}

std::string tgc_curve(const FrameDraw& draw, const probe::Transducer& t) {
    if (!draw.tgc_slope) return "auto";
    // Two points carry the slope alone; sliders add their offsets at evenly spaced depths.
    const int points = std::max(2, int(draw.tgc_sliders_db.size()));
    std::string text;
    for (int k = 0; k < points; ++k) {
        const double depth = t.depth_mm * k / (points - 1);
        double gain = 2.0 * *draw.tgc_slope * t.frequency_mhz * depth / 10.0;
        if (!draw.tgc_sliders_db.empty()) gain += draw.tgc_sliders_db[std::size_t(k)];
        if (k) text += ',';
        text += base::exact_number_text(depth);
        text += ':';
        text += base::exact_number_text(gain);
    }
    return text;
}

}  // namespace sonotrace::dataset
