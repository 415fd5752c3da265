// Per-texel sample sequences (private to the baker). Each texel (or point)
// gets a key from the seed and its index alone, so results do not depend on
// which thread ran it. Each 2-D dimension is the R2 low-discrepancy sequence
// (Roberts 2018) shifted by a per-key, per-dimension random rotation
// (Cranley-Patterson), so every sample count is well stratified.
#pragma once

#include <cstdint>

#include <glm/vec2.hpp>

namespace lmrefine {

inline uint64_t mix64(uint64_t x) {  // splitmix64 finalizer
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

inline uint64_t hash_combine(uint64_t a, uint64_t b) { return mix64(a ^ mix64(b)); }

class Sampler {
public:
    Sampler(uint64_t key, uint32_t sample) : key_(key), sample_(sample) {}

    // A point in [0, 1)^2 for this sample in the given dimension.
    glm::vec2 get(uint32_t dimension) const {
        constexpr double a1 = 0.75487766624669276, a2 = 0.56984029099805327;  // 1/g, 1/g^2 (plastic number g)
        const uint64_t h = hash_combine(key_, dimension);
        const double r1 = double(h >> 40) * 0x1p-24, r2 = double(h & 0xFFFFFF) * 0x1p-24;
        double x = r1 + a1 * sample_, y = r2 + a2 * sample_;
        x -= double(int64_t(x));
        y -= double(int64_t(y));
        // float(x) may round up to 1.0; keep samples in [0, 1).
        return {float(x < 0.99999994 ? x : 0.99999994), float(y < 0.99999994 ? y : 0.99999994)};
    }

private:
    uint64_t key_;
    uint32_t sample_;
};

}  // namespace lmrefine
