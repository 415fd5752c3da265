// Large allocations: checked against the machine's memory first, so an
// absurd request (a corrupt image header, a resolution of 10^6) fails with a
// ResourceError that names it instead of attempting a terabyte allocation;
// and backed by large pages where the system gives them, so that touching
// them the first time costs few page faults.
#pragma once

#include <cstddef>
#include <cstdint>
#include <new>
#include <string>
#include <vector>

namespace lmrefine {

// Bytes of physical memory (16 GiB if the system does not say).
uint64_t physical_memory();

// "1.50 GiB".
std::string gib(uint64_t bytes);

// Throws ResourceError ("<what> needs about X GiB of memory, more than half
// of this machine's Y GiB; <advice>") when `bytes` exceed half of physical
// memory.
void require_memory(const std::string& what, uint64_t bytes, const std::string& advice);

// Asks the system to back the whole 2 MiB pages inside [data, data + bytes)
// with large pages (Linux transparent huge pages, which many kernels,
// Debian's among them, give on request only): memory touched for the first
// time costs a page fault per 4 KiB, and one per 2 MiB in large pages
// (docs/refiner.md, "Large pages for the large arrays"). Only untouched
// memory gains; a no-op where the system has no such request, never an
// error.
void advise_large_pages(const void* data, size_t bytes);

// n copies of value in a plain vector whose storage is advised as above
// before it is filled (for vectors whose type other code shares; the C
// library's header touches the first large page, so LargeVector below
// gains more).
template <class T>
std::vector<T> large_vector(size_t n, const T& value = T()) {
    std::vector<T> v;
    v.reserve(n);
    advise_large_pages(v.data(), v.capacity() * sizeof(T));
    v.assign(n, value);
    return v;
}

// An allocator whose blocks of 2 MiB and more start on a 2 MiB boundary and
// are advised as above before anything touches them. With a plain
// allocation the C library writes its header just before the block, which
// touches the block's first large page in small pages: about 2 MiB of
// every array would fault page by page.
template <class T>
struct LargePageAllocator {
    using value_type = T;
    static constexpr size_t kLargePage = size_t(1) << 21;

    LargePageAllocator() = default;
    template <class U>
    LargePageAllocator(const LargePageAllocator<U>&) noexcept {}

    T* allocate(size_t n) {
        const size_t bytes = n * sizeof(T);
        if (bytes < kLargePage) return static_cast<T*>(::operator new(bytes));
        if (bytes > SIZE_MAX - kLargePage) throw std::bad_alloc();
        const size_t rounded = (bytes + kLargePage - 1) / kLargePage * kLargePage;
        void* p = ::operator new(rounded, std::align_val_t(kLargePage));
        advise_large_pages(p, rounded);
        return static_cast<T*>(p);
    }
    void deallocate(T* p, size_t n) noexcept {
        if (n * sizeof(T) < kLargePage) {
            ::operator delete(p);
        } else {
            ::operator delete(p, std::align_val_t(kLargePage));
        }
    }
    template <class U>
    bool operator==(const LargePageAllocator<U>&) const noexcept { return true; }
    template <class U>
    bool operator!=(const LargePageAllocator<U>&) const noexcept { return false; }
};

template <class T>
using LargeVector = std::vector<T, LargePageAllocator<T>>;

// a * b * ... saturating at UINT64_MAX, for sizes computed from user input.
uint64_t saturating_product(std::initializer_list<uint64_t> factors);

}  // namespace lmrefine
