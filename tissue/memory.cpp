#include "tissue/memory.h"

#include <unistd.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "tissue/error.h"

namespace sonotrace::tissue {

double available_memory_bytes() {
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    double kib = 0.0;
    std::string unit;
    while (meminfo >> key >> kib >> unit) {
        if (key == "MemAvailable:") return kib * 1024.0;
    }
    return double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
}

void check_allocation(double bytes, const std::string& source, const std::string& field) {
    const double available = available_memory_bytes();
    if (!std::isfinite(bytes) || bytes > available) {
        std::ostringstream s;
        s.precision(3);
        s << "would need " << bytes / (1024.0 * 1024.0 * 1024.0) << " GiB of memory but only "
          << available / (1024.0 * 1024.0 * 1024.0) << " GiB are available";
        throw InputError(source, field, s.str());
    }
}

}  // namespace sonotrace::tissue
