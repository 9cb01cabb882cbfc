#include "tissue/base/number_list.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "tissue/base/error.h"

namespace sonotrace::base {

std::string exact_number_text(double v) {
    char text[32];
    const auto end = std::to_chars(text, text + sizeof text, v).ptr;
    return std::string(text, end);
}

std::optional<double> finite_number(const std::string& text) {
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v)) return std::nullopt;
    return v;
}

std::optional<std::string> not_a_finite_number(const std::string& text) {
    if (!finite_number(text)) return "value " + text + " is not a finite number";
    return std::nullopt;
}

std::optional<std::string> not_a_whole_number(const std::string& text) {
    uint64_t parsed = 0;
    const char* end = text.data() + text.size();
    const auto [stop, error] = std::from_chars(text.data(), end, parsed);
    if (text.empty() || error != std::errc() || stop != end)
        return "value " + text + " is not a whole number from 0 to " +
               std::to_string(std::numeric_limits<uint64_t>::max());
    return std::nullopt;
}

std::optional<std::string> parse_number_list(const std::string& text, std::vector<double>* out) {
    out->clear();
    std::istringstream in(text);
    for (std::string part; std::getline(in, part, ',');) {
        const std::optional<double> v = finite_number(part);
        if (!v) return "'" + part + "' is not a number";
        out->push_back(*v);
    }
    return std::nullopt;
}

std::vector<double> parse_numbers(const std::string& text, const std::string& option,
                                  std::size_t count) {
    std::vector<double> values;
    if (const auto error = parse_number_list(text, &values)) throw InputError(option, "", *error);
    if (values.size() != count)
        throw InputError(
            option, "",
            "needs " + std::to_string(count) + " comma-separated numbers, got '" + text + "'");
    return values;
}

std::optional<std::string> parse_spacing(const std::string& text, double out[3]) {
    std::vector<double> values;
    if (const auto error = parse_number_list(text, &values)) return error;
    if (values.size() > 3) return "at most three values";
    if (values.size() < 2) return "give at least two values (mm per pixel along x and y)";
    for (std::size_t i = 0; i < values.size(); ++i) {
        if (!(values[i] > 0.0)) {
            std::ostringstream message;
            message << "'" << values[i] << "' is not a positive number of mm";
            return message.str();
        }
        out[i] = values[i];
    }
    if (values.size() == 2) out[2] = 1.0;
    return std::nullopt;
}

}  // namespace sonotrace::base
