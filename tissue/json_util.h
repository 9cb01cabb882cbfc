#pragma once
// Strict reading of JSON inputs: unknown keys, wrong types and out-of-range values are
// errors that name the file and the JSON path of the field ("points[2].density").
#include <initializer_list>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

namespace sonotrace::tissue::jsonio {

using nlohmann::json;

// Parses a file; throws InputError with the line and column of a syntax error.
json read_file(const std::string& path);
// Parses text from `source` (a file name used in messages).
json parse(const std::string& text, const std::string& source);

// Throws if `object` (at JSON path `where`) has a key not in `known`; lists the known ones.
void require_known_keys(const json& object, std::initializer_list<std::string_view> known,
                        const std::string& source, const std::string& where);
void require_known_keys(const json& object, std::span<const std::string_view> known,
                        const std::string& source, const std::string& where);
void require_object(const json& value, const std::string& source, const std::string& where);

// Member access with type and range checks; `where` is the path of `object`.
double get_number(const json& object, const std::string& key, const std::string& source,
                  const std::string& where, double min, double max);
std::optional<double> get_optional_number(const json& object, const std::string& key,
                                          const std::string& source, const std::string& where,
                                          double min, double max);
std::string get_string(const json& object, const std::string& key, const std::string& source,
                       const std::string& where);
glm::dvec3 get_vec3(const json& object, const std::string& key, const std::string& source,
                    const std::string& where);

// "where.key" or "key" when `where` is empty.
std::string join(const std::string& where, const std::string& key);

}  // namespace sonotrace::tissue::jsonio
