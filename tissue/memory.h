#pragma once
// Guards against allocations the machine cannot satisfy, so that a corrupt header
// or an absurd parameter gives a message instead of std::bad_alloc or the OOM killer.
#include <string>

namespace sonotrace::tissue {

// Bytes of memory currently available (MemAvailable from /proc/meminfo, or physical
// memory if that is unreadable).
double available_memory_bytes();

// Throws InputError(source, field, ...) when `bytes` exceeds the available memory.
void check_allocation(double bytes, const std::string& source, const std::string& field);

}  // namespace sonotrace::tissue
