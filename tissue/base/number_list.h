#pragma once
// Numbers in option values: one ("0.5", "18446744073709551615") or comma-separated
// ("0.5,0.5", "1,1,2").
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace sonotrace::base {

// `text` as a number if all of it is one and it is finite (strtod's reading: a value too
// small for a double is its nearest, 0 or a denormal, not an error).
std::optional<double> finite_number(const std::string& text);
// Why `text` is not a finite number (all of it, NaN and infinities refused), or nothing
// if it is one: the message every option and keyword gives.
std::optional<std::string> not_a_finite_number(const std::string& text);
// The same for a whole number that a uint64_t holds (-1, 2^64 and 1e23 are not).
std::optional<std::string> not_a_whole_number(const std::string& text);

// The shortest text that reads back (strtod, from_chars) as exactly `v`: how a number a
// program computed is handed on as an option's text without changing a bit.
std::string exact_number_text(double v);

// Comma-separated finite numbers; the error text if one is not.
std::optional<std::string> parse_number_list(const std::string& text, std::vector<double>* out);
// Exactly `count` of them for `option`; throws base::InputError naming the option.
std::vector<double> parse_numbers(const std::string& text, const std::string& option,
                                  std::size_t count);
// Two or three positive spacings in mm (the third defaults to 1) for options like --spacing.
std::optional<std::string> parse_spacing(const std::string& text, double out[3]);

}  // namespace sonotrace::base
