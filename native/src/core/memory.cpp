#include "lmrefine/core/memory.h"

// Physical memory has no standard C++ query: one branch per platform.
#if defined(_WIN32)
#define NOMINMAX
#include <windows.h>
#elif defined(__APPLE__)
#include <sys/sysctl.h>
#include <sys/types.h>
#else
#include <unistd.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>
#endif

#include <cstdio>
#include <limits>

#include "lmrefine/core/error.h"

namespace lmrefine {

uint64_t physical_memory() {
    const uint64_t unknown = uint64_t(1) << 34;
#if defined(_WIN32)
    MEMORYSTATUSEX status;
    status.dwLength = sizeof status;
    return GlobalMemoryStatusEx(&status) ? uint64_t(status.ullTotalPhys) : unknown;
#elif defined(__APPLE__)
    uint64_t bytes = 0;
    size_t size = sizeof bytes;
    return sysctlbyname("hw.memsize", &bytes, &size, nullptr, 0) == 0 && bytes > 0 ? bytes : unknown;
#else
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    return pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : unknown;
#endif
}

void advise_large_pages(const void* data, size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    constexpr uintptr_t kLargePage = uintptr_t(1) << 21;
    const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kLargePage - 1) & ~(kLargePage - 1);
    const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kLargePage - 1);
    // A refusal (old kernel, huge pages off) only leaves the small pages.
    if (data && end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
    (void)data;
    (void)bytes;
#endif
}

std::string gib(uint64_t bytes) {
    char text[48];
    std::snprintf(text, sizeof text, "%.2f GiB", double(bytes) / double(uint64_t(1) << 30));
    return text;
}

void require_memory(const std::string& what, uint64_t bytes, const std::string& advice) {
    const uint64_t available = physical_memory();
    if (bytes > available / 2) {
        LMREFINE_THROW(ResourceError, what + " needs about " + gib(bytes) + " of memory, more than half of this machine's " +
                                          gib(available) + "; " + advice);
    }
}

uint64_t saturating_product(std::initializer_list<uint64_t> factors) {
    uint64_t product = 1;
    for (uint64_t f : factors) {
        if (f != 0 && product > std::numeric_limits<uint64_t>::max() / f) return std::numeric_limits<uint64_t>::max();
        product *= f;
    }
    return product;
}

}  // namespace lmrefine
