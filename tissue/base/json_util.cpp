#include "tissue/base/json_util.h"

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <set>
#include <sstream>

#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_read.h"

namespace sonotrace::base::jsonio {

namespace {
std::string describe(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}
}  // namespace

std::string join(const std::string& where, const std::string& key) {
    return where.empty() ? key : where + "." + key;
}

json read_file(const std::string& path) {
    return parse(read_regular_file(path, kMaxJsonBytes), path);
}

json parse(const std::string& text, const std::string& source) {
    if (text.size() > kMaxJsonBytes)
        throw InputError(
            source, "",
            "is larger than the JSON size limit of " + std::to_string(kMaxJsonBytes) + " bytes");
    // A key given twice in one object is two definitions of one thing: JSON parsers
    // silently keep one of them, so it is refused here (the path names the key).
    std::vector<std::set<std::string>> keys;  // per open object
    std::string duplicate;
    int depth = 0;
    struct TooDeep {};
    const json::parser_callback_t check = [&](int, json::parse_event_t event, json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start:
                keys.emplace_back();
                [[fallthrough]];
            case json::parse_event_t::array_start:
                // Thrown out of the parser before the value exists.
                if (++depth > kMaxJsonDepth) throw TooDeep{};
                break;
            case json::parse_event_t::object_end:
                if (!keys.empty()) keys.pop_back();
                [[fallthrough]];
            case json::parse_event_t::array_end:
                --depth;
                break;
            case json::parse_event_t::key: {
                const std::string key = parsed.get<std::string>();
                if (!keys.empty() && !keys.back().insert(key).second && duplicate.empty())
                    duplicate = key;
                break;
            }
            default:
                break;
        }
        return true;
    };
    try {
        json result = json::parse(text, check);
        if (!duplicate.empty())
            throw InputError(source, duplicate,
                             "is given twice in one object (which one is meant?)");
        return result;
    } catch (const TooDeep&) {
        throw InputError(
            source, "",
            "nests arrays or objects more than " + std::to_string(kMaxJsonDepth) + " levels deep");
    } catch (const json::parse_error& e) {
        // Turn the byte offset into line:column for the message.
        std::size_t line = 1, column = 1;
        for (std::size_t n = 0; n + 1 < e.byte && n < text.size(); ++n) {
            if (text[n] == '\n') {
                ++line;
                column = 1;
            } else {
                ++column;
            }
        }
        throw InputError(source, "",
                         "invalid JSON at line " + std::to_string(line) + ", column " +
                             std::to_string(column) + " (" + e.what() + ")");
    } catch (const json::exception& e) {
        // out_of_range.406: a number such as 1e400 that no double holds.
        throw InputError(source, "", std::string("invalid JSON (") + e.what() + ")");
    }
}

void require_object(const json& value, const std::string& source, const std::string& where) {
    if (!value.is_object()) {
        throw InputError(source, where.empty() ? "(top level)" : where, "must be a JSON object");
    }
}

void require_known_keys(const json& object, std::initializer_list<std::string_view> known,
                        const std::string& source, const std::string& where) {
    require_known_keys(object, std::span<const std::string_view>(known.begin(), known.size()),
                       source, where);
}

void require_known_keys(const json& object, std::span<const std::string_view> known,
                        const std::string& source, const std::string& where) {
    require_object(object, source, where);
    for (const auto& item : object.items()) {
        bool found = false;
        for (std::string_view k : known) found = found || item.key() == k;
        if (!found) {
            std::string list;
            for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
            throw InputError(source, join(where, item.key()),
                             "unknown key (known keys here: " + list + ")");
        }
    }
}

std::optional<double> get_optional_number(const json& object, const std::string& key,
                                          const std::string& source, const std::string& where,
                                          double min, double max) {
    if (!object.contains(key)) return std::nullopt;
    const json& value = object.at(key);
    if (!value.is_number()) throw InputError(source, join(where, key), "must be a number");
    const double v = value.get<double>();
    if (!std::isfinite(v) || v < min || v > max) {
        throw InputError(
            source, join(where, key),
            "value " + describe(v) + " is outside [" + describe(min) + ", " + describe(max) + "]");
    }
    return v;
}

double get_number(const json& object, const std::string& key, const std::string& source,
                  const std::string& where, double min, double max) {
    auto v = get_optional_number(object, key, source, where, min, max);
    if (!v) throw InputError(source, join(where, key), "is required");
    return *v;
}

std::string get_string(const json& object, const std::string& key, const std::string& source,
                       const std::string& where) {
    if (!object.contains(key)) throw InputError(source, join(where, key), "is required");
    if (!object.at(key).is_string()) throw InputError(source, join(where, key), "must be a string");
    return object.at(key).get<std::string>();
}

glm::dvec3 get_vec3(const json& object, const std::string& key, const std::string& source,
                    const std::string& where) {
    const std::string field = join(where, key);
    if (!object.contains(key)) throw InputError(source, field, "is required");
    const json& value = object.at(key);
    if (!value.is_array() || value.size() != 3) {
        throw InputError(source, field, "must be an array of 3 numbers");
    }
    glm::dvec3 v;
    for (int a = 0; a < 3; ++a) {
        if (!value[a].is_number()) throw InputError(source, field, "must be an array of 3 numbers");
        v[a] = value[a].get<double>();
        if (!std::isfinite(v[a])) throw InputError(source, field, "is not finite");
    }
    return v;
}

void write_json(const json& record, const std::string& path) {
    if (path == "-") {
        std::cout << record.dump(2) << std::endl;
        return;
    }
    const std::string text = record.dump(2) + "\n";
    write_file(path, text.data(), text.size());
}

}  // namespace sonotrace::base::jsonio
