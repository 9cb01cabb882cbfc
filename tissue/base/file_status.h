#pragma once
// The status of a file named by the user, without std::filesystem's exceptions: a name
// the system refuses (too long, a component that is a file, no permission) becomes an
// InputError naming the file and the field it came from; a missing file is just absent.
#include <filesystem>
#include <string>

#include "tissue/base/error.h"

namespace sonotrace::base {

inline std::filesystem::file_status file_status(const std::filesystem::path& path,
                                                const std::string& source,
                                                const std::string& field) {
    std::error_code error;
    const std::filesystem::file_status status = std::filesystem::status(path, error);
    if (error && status.type() != std::filesystem::file_type::not_found) {
        throw InputError(source, field,
                         "'" + path.string().substr(0, 200) + "': " + error.message());
    }
    return status;
}

}  // namespace sonotrace::base
