#pragma once
// Strict reading of JSON inputs: unknown keys, wrong types and out-of-range values are
// errors that name the file and the JSON path of the field ("points[2].density").
#include <cstddef>
#include <initializer_list>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

namespace sonotrace::base::jsonio {

using nlohmann::json;

// Limits of every JSON input: descriptions (phantoms, scenes, transfer functions,
// sidecars) are kilobytes and a few levels deep. The size cap keeps an endless or huge
// file (/dev/zero, a disk image) from being read whole; the depth cap keeps a value
// nested 100,000 deep from overflowing the stack of the recursive code that later walks
// or prints it.
inline constexpr std::size_t kMaxJsonBytes = std::size_t(64) << 20;
inline constexpr int kMaxJsonDepth = 64;

// Parses a regular file of at most kMaxJsonBytes; throws InputError naming the file
// with the line and column of a syntax error, or what else is wrong (not a regular
// file, too large, too deep, a number out of range).
json read_file(const std::string& path);
// Parses text from `source` (a file name used in messages), with the same checks.
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

// Writes `record` (two-space indented, a final newline) to `path` whole or not at all
// (callers stage it through base::OutputTransaction), or to stdout when path is "-".
void write_json(const json& record, const std::string& path);

// "where.key" or "key" when `where` is empty.
std::string join(const std::string& where, const std::string& key);

}  // namespace sonotrace::base::jsonio
