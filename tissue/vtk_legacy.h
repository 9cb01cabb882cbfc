#pragma once
// VTK legacy files (ASCII or BINARY), read token by token: the header (version line,
// title, format), then sections whose counts are checked against what is left of the file
// before anything is allocated, and numbers in the section's type (big-endian in BINARY
// files). Its readers: imaging/pbvr/tetra.cpp (UNSTRUCTURED_GRID) and phantoms/mesh.cpp
// (POLYDATA). Errors are base::InputError naming the file and the section.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include <glm/glm.hpp>

#include "tissue/base/error.h"

namespace sonotrace::tissue {

class VtkLegacyStream {
  public:
    // Opens the file and reads its header: "# vtk DataFile ...", the title, ASCII or BINARY.
    explicit VtkLegacyStream(const std::string& path);
    // The next word, or nothing at the end of the file (read between sections).
    std::optional<std::string> next_keyword();
    // A section's item count: a non-negative integer that the rest of the file can hold,
    // each item taking at least `ascii_bytes` (digits and a space per number) or
    // `binary_bytes`. A header declaring more is corrupt: refused before allocating.
    std::size_t count(const std::string& section, double ascii_bytes, double binary_bytes);
    std::string word(const std::string& section);
    // A number stored as `type` (float, double, int, vtkIdType, long, vtktypeint64,
    // unsigned_char, short, unsigned_short), converted to T (integers range-checked).
    template <typename T>
    T number(const std::string& section, const std::string& type);
    // The POINTS section after its keyword: the count, the type, three numbers a point.
    std::vector<glm::dvec3> points();
    // A section's data ends: the next BINARY section starts after its own header line.
    void section_done() { skipped_newline_ = false; }
    const std::string& path() const { return path_; }

  private:
    std::string line();

    std::string path_;
    std::ifstream in_;
    double file_bytes_ = 0.0;
    bool binary_ = false, skipped_newline_ = false;
};

template <typename T>
T VtkLegacyStream::number(const std::string& section, const std::string& type) {
    if (!binary_) {
        double v;
        if (!(in_ >> v)) throw base::InputError(path_, section, "expected a number");
        if constexpr (std::is_integral_v<T>) {  // converting beyond T's range is undefined
            const double low = double(std::numeric_limits<T>::min());
            const double past_high = 2.0 * (double(std::numeric_limits<T>::max() / 2) + 1.0);
            if (!(v >= low && v < past_high))
                throw base::InputError(path_, section,
                                       "integer " + base::number_text(v) + " is out of range");
        }
        return T(v);
    }
    if (!skipped_newline_) {  // binary data starts after the header line's newline
        in_.ignore(std::numeric_limits<std::streamsize>::max(), '\n');
        skipped_newline_ = true;
    }
    auto read = [&](auto value) {
        unsigned char bytes[sizeof value];
        if (!in_.read(reinterpret_cast<char*>(bytes), sizeof value))
            throw base::InputError(path_, section, "binary data ends early");
        if constexpr (std::endian::native == std::endian::little)
            std::reverse(bytes, bytes + sizeof value);
        std::memcpy(&value, bytes, sizeof value);
        return T(value);
    };
    if (type == "float") return read(float{});
    if (type == "double") return read(double{});
    if (type == "int" || type == "vtkIdType") return read(int32_t{});
    if (type == "long" || type == "vtktypeint64") return read(int64_t{});
    if (type == "unsigned_char") return read(uint8_t{});
    if (type == "short") return read(int16_t{});
    if (type == "unsigned_short") return read(uint16_t{});
    throw base::InputError(path_, section, "unsupported binary type '" + type + "'");
}

}  // namespace sonotrace::tissue
