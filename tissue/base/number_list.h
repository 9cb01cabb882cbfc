#pragma once
// Comma-separated numbers in option values ("0.5,0.5", "1,1,2").
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace sonotrace::base {

// Comma-separated finite numbers; the error text if one is not.
std::optional<std::string> parse_number_list(const std::string& text, std::vector<double>* out);
// Exactly `count` of them for `option`; throws base::InputError naming the option.
std::vector<double> parse_numbers(const std::string& text, const std::string& option,
                                  std::size_t count);
// Two or three positive spacings in mm (the third defaults to 1) for options like --spacing.
std::optional<std::string> parse_spacing(const std::string& text, double out[3]);

}  // namespace sonotrace::base
