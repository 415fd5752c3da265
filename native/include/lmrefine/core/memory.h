// Memory checked before a large allocation, so an absurd request (a corrupt
// image header, a resolution of 10^6) fails with a ResourceError that names
// it instead of attempting a terabyte allocation.
#pragma once

#include <cstdint>
#include <string>

namespace lmrefine {

// Bytes of physical memory (16 GiB if the system does not say).
uint64_t physical_memory();

// "1.50 GiB".
std::string gib(uint64_t bytes);

// Throws ResourceError ("<what> needs about X GiB of memory, more than half
// of this machine's Y GiB; <advice>") when `bytes` exceed half of physical
// memory.
void require_memory(const std::string& what, uint64_t bytes, const std::string& advice);

// a * b * ... saturating at UINT64_MAX, for sizes computed from user input.
uint64_t saturating_product(std::initializer_list<uint64_t> factors);

}  // namespace lmrefine
