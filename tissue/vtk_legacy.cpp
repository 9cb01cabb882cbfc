#include "tissue/vtk_legacy.h"

#include <exception>
#include <filesystem>

namespace sonotrace::tissue {

using base::InputError;

VtkLegacyStream::VtkLegacyStream(const std::string& path) : path_(path) {
    // Checked before opening: a FIFO would block the open for ever.
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error))
        throw InputError(path, "", "does not exist or is not a file");
    in_.open(path, std::ios::binary);
    if (!in_) throw InputError(path, "", "cannot open the file");
    file_bytes_ = double(std::filesystem::file_size(path, error));
    if (error) throw InputError(path, "", "cannot read the file's size: " + error.message());
    if (line().rfind("# vtk DataFile", 0) != 0)
        throw InputError(path, "header", "not a VTK legacy file ('# vtk DataFile ...')");
    line();  // title
    const std::string format = line();
    if (format.rfind("BINARY", 0) == 0)
        binary_ = true;
    else if (format.rfind("ASCII", 0) != 0)
        throw InputError(path, "format", "must be ASCII or BINARY");
}

std::optional<std::string> VtkLegacyStream::next_keyword() {
    std::string w;
    if (!(in_ >> w)) return std::nullopt;
    return w;
}

std::size_t VtkLegacyStream::count(const std::string& section, double ascii_bytes,
                                   double binary_bytes) {
    const std::string w = word(section);
    std::size_t used = 0;
    long long n = -1;
    try {
        n = std::stoll(w, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (used != w.size() || n < 0)
        throw InputError(path_, section, "count '" + w + "' is not a non-negative integer");
    const double remaining = file_bytes_ - double(in_.tellg());
    if (double(n) * (binary_ ? binary_bytes : ascii_bytes) > remaining) {
        throw InputError(path_, section,
                         "declares " + std::to_string(n) + " items, more than the " +
                             base::number_text(std::max(0.0, remaining)) +
                             " bytes left in the file hold: truncated or corrupt");
    }
    return std::size_t(n);
}

std::vector<glm::dvec3> VtkLegacyStream::points() {
    const std::size_t n = count("POINTS", 6.0, 12.0);  // 3 numbers a point
    const std::string type = word("POINTS");
    std::vector<glm::dvec3> out(n);
    for (auto& p : out)
        for (int a = 0; a < 3; ++a) p[a] = number<double>("POINTS", type);
    section_done();
    return out;
}

std::string VtkLegacyStream::line() {
    std::string l;
    if (!std::getline(in_, l)) throw InputError(path_, "", "ends early");
    if (!l.empty() && l.back() == '\r') l.pop_back();
    return l;
}

std::string VtkLegacyStream::word(const std::string& section) {
    std::string w;
    if (!(in_ >> w)) throw InputError(path_, section, "ends early");
    return w;
}

}  // namespace sonotrace::tissue
