#include "tissue/base/memory.h"

#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>

#include <algorithm>

#include <cmath>
#include <fstream>
#include <sstream>

#include "tissue/base/error.h"

namespace sonotrace::base {

namespace {
constexpr std::size_t kHugePage = std::size_t(2) << 20;
}

void* allocate_huge(std::size_t bytes) {
    if (bytes < kHugePage) return ::operator new(bytes);
    const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
    void* p = std::aligned_alloc(kHugePage, rounded);
    if (p == nullptr) throw std::bad_alloc();
    madvise(p, rounded, MADV_HUGEPAGE);  // a hint: without it the pages are 4 KiB
    return p;
}

void free_huge(void* p, std::size_t bytes) {
    if (bytes < kHugePage)
        ::operator delete(p);
    else
        std::free(p);
}

void keep_freed_memory() {
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 64 << 20);
}

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

}  // namespace sonotrace::base
