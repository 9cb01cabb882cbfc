#pragma once
// Guards against allocations the machine cannot satisfy, so that a corrupt header
// or an absurd parameter gives a message instead of std::bad_alloc or the OOM killer.
#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <string>
#include <utility>

namespace sonotrace::base {

// Bytes of memory currently available (MemAvailable from /proc/meminfo, or physical
// memory if that is unreadable).
double available_memory_bytes();

// Throws InputError(source, field, ...) when `bytes` exceeds the available memory.
void check_allocation(double bytes, const std::string& source, const std::string& field);

// Asks glibc's malloc to keep freed memory for reuse: blocks up to 32 MiB come from the
// heap, which is trimmed only above 64 MiB free. By default a block above malloc's
// adaptive threshold is a fresh mapping each time, and each trace allocates tens of MB of
// transient buffers (echo lists, per-line outputs, result maps); the kernel zeroes fresh
// pages at their first touch, and in a virtual machine the host may fault on them too.
// Called at the start of main() by our programs.
void keep_freed_memory();

// Memory on 2 MiB pages where the kernel offers them (transparent huge pages: asked for
// with madvise, which is all Debian's default "madvise" mode grants). For arrays read at
// random by the particle tracer: one TLB entry then covers 512 pages' worth, and in a
// virtual machine each TLB miss costs a two-level page walk. Blocks under 2 MiB come
// from operator new as usual.
void* allocate_huge(std::size_t bytes);
void free_huge(void* p, std::size_t bytes);

// An allocator's construct() whose value-initialization writes nothing (default-
// initialization); other constructors as usual.
struct DefaultInitConstruct {
    template <class U>
    void construct(U* p) noexcept {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

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

// The same, but value-initialization writes nothing: for arrays that are filled in
// parallel right after allocation, so that their pages fault in on every thread (page
// faults are slow in a virtual machine).
template <class T>
struct UninitializedHugePageAllocator : HugePageAllocator<T>, DefaultInitConstruct {
    using value_type = T;
    UninitializedHugePageAllocator() = default;
    template <class U>
    UninitializedHugePageAllocator(const UninitializedHugePageAllocator<U>&) {}
};

// For arrays whose elements start at zero, such as volumes: memory from calloc, which
// clears only what needs it (a fresh mapping is zero already, and its pages cost nothing
// until written, then they fault in whichever thread writes them), and value-
// initialization that writes nothing more (std::vector zero-filling a 3D trace's result
// maps on one core was a quarter of the trace).
// Caveat: a vector shrunk and then grown in place keeps the old values; Volume never
// resizes its storage.
template <class T>
struct ZeroedAllocator : DefaultInitConstruct {
    using value_type = T;
    ZeroedAllocator() = default;
    template <class U>
    ZeroedAllocator(const ZeroedAllocator<U>&) {}
    T* allocate(std::size_t n) {
        static_assert(alignof(T) <= alignof(std::max_align_t));
        if (n > std::size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
        void* p = std::calloc(std::max<std::size_t>(n, 1), sizeof(T));
        if (p == nullptr) throw std::bad_alloc();
        return static_cast<T*>(p);
    }
    void deallocate(T* p, std::size_t) { std::free(p); }
    // construct(): value-initialization writes nothing, the bytes are zero already.
    template <class U>
    bool operator==(const ZeroedAllocator<U>&) const {
        return true;
    }
};

}  // namespace sonotrace::base
