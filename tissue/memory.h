#pragma once
// Guards against allocations the machine cannot satisfy, so that a corrupt header
// or an absurd parameter gives a message instead of std::bad_alloc or the OOM killer.
#include <cstddef>
#include <new>
#include <string>

namespace sonotrace::tissue {

// Bytes of memory currently available (MemAvailable from /proc/meminfo, or physical
// memory if that is unreadable).
double available_memory_bytes();

// Throws InputError(source, field, ...) when `bytes` exceeds the available memory.
void check_allocation(double bytes, const std::string& source, const std::string& field);

// Memory on 2 MiB pages where the kernel offers them (transparent huge pages: asked for
// with madvise, which is all Debian's default "madvise" mode grants). For arrays read at
// random by the particle tracer: one TLB entry then covers 512 pages' worth, and in a
// virtual machine each TLB miss costs a two-level page walk (bench/README.md: +7 % 2D,
// +14 % 3D on Colin27). Blocks under 2 MiB come from operator new as usual.
void* allocate_huge(std::size_t bytes);
void free_huge(void* p, std::size_t bytes);
// Asks for 2 MiB pages on the whole huge pages inside [p, p + bytes) of memory not yet
// touched (a hint). For large arrays from other allocators, e.g. a std::vector's
// reserve(): a fresh 30 MB result map otherwise costs ~7,000 page faults at its first
// touch, which in a virtual machine took a fifth of a 3D trace.
void advise_huge_pages(void* p, std::size_t bytes);

template <class T>
struct HugePageAllocator {
    using value_type = T;
    HugePageAllocator() = default;
    template <class U>
    HugePageAllocator(const HugePageAllocator<U>&) {}
    T* allocate(std::size_t n) {
        static_assert(alignof(T) <= alignof(std::max_align_t));
        if (n > std::size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
        return static_cast<T*>(allocate_huge(n * sizeof(T)));
    }
    void deallocate(T* p, std::size_t n) { free_huge(p, n * sizeof(T)); }
    template <class U>
    bool operator==(const HugePageAllocator<U>&) const {
        return true;
    }
};

}  // namespace sonotrace::tissue
