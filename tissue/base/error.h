#pragma once
// Errors about user input. Every message names the file (or option) and the field
// that is wrong, so that the CLI can print it verbatim and exit non-zero.
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace sonotrace::base {

class InputError : public std::runtime_error {
  public:
    // `source` is a file path or an option name such as "--pose"; `field` is the header
    // field, JSON key or parameter inside it (may be empty).
    InputError(std::string source, std::string field, const std::string& what)
        : std::runtime_error(compose(source, field, what)),
          source_(std::move(source)),
          field_(std::move(field)),
          detail_(what) {}

    const std::string& source() const { return source_; }
    const std::string& field() const { return field_; }
    // What is wrong, without the source and field.
    const std::string& detail() const { return detail_; }

  private:
    static std::string compose(const std::string& source, const std::string& field,
                               const std::string& what) {
        std::string msg = source;
        if (!field.empty()) msg += ": field '" + field + "'";
        return msg + ": " + what;
    }
    std::string source_;
    std::string field_;
    std::string detail_;
};

// Throws InputError(source, field) unless lo <= value <= hi (and finite); `unit` is
// appended to the bounds in the message.
// A number as messages show it: six significant digits, an exponent when it is large or
// small (std::to_string prints 1e300 as 301 digits and 1e-9 as 0.000000).
inline std::string number_text(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%.6g", v);
    return text;
}

inline void require_in_range(const std::string& source, const char* field, double value, double lo,
                             double hi, const char* unit = "") {
    if (!(std::isfinite(value) && value >= lo && value <= hi)) {
        throw InputError(source, field,
                         "must be in [" + number_text(lo) + ", " + number_text(hi) + "]" +
                             (unit[0] ? std::string(" ") + unit : std::string()) + ", got " +
                             number_text(value));
    }
}

}  // namespace sonotrace::base
