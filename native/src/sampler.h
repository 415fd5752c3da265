// Per-texel sample sequences (private to the baker). Each texel (or point)
// gets a key from the seed and its index alone, so results do not depend on
// which thread ran it. Each 2-D dimension is the R2 low-discrepancy sequence
// (Roberts 2018) shifted by a per-key, per-dimension random rotation
// (Cranley-Patterson), so every sample count is well stratified; and each
// dimension visits the samples in its own random order (Kensler's
// permutation), so dimensions are not correlated with each other (the same
// sequence in every dimension would make, e.g., the bounce direction a
// function of the light sample).
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

// A random bijection of [0, count) picked by `seed` (Kensler 2013,
// "Correlated Multi-Jittered Sampling").
inline uint32_t permute(uint32_t i, uint32_t count, uint32_t seed) {
    uint32_t w = count - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    do {
        i ^= seed;
        i *= 0xe170893d;
        i ^= seed >> 16;
        i ^= (i & w) >> 4;
        i ^= seed >> 8;
        i *= 0x0929eb3f;
        i ^= seed >> 23;
        i ^= (i & w) >> 1;
        i *= 1 | seed >> 27;
        i *= 0x6935fa69;
        i ^= (i & w) >> 11;
        i *= 0x74dcb303;
        i ^= (i & w) >> 2;
        i *= 0x9e501cc3;
        i ^= (i & w) >> 2;
        i *= 0xc860a3df;
        i &= w;
        i ^= i >> 5;
    } while (i >= count);
    return (i + seed) % count;
}

class Sampler {
public:
    // Sample `sample` of `count` for the texel or point identified by `key`.
    Sampler(uint64_t key, uint32_t sample, uint32_t count) : key_(key), sample_(sample), count_(count) {}

    // A point in [0, 1)^2 for this sample in the given dimension.
    glm::vec2 get(uint32_t dimension) const {
        constexpr double a1 = 0.75487766624669276, a2 = 0.56984029099805327;  // 1/g, 1/g^2 (plastic number g)
        const uint64_t h = hash_combine(key_, dimension);
        const double r1 = double(h >> 40) * 0x1p-24, r2 = double(h & 0xFFFFFF) * 0x1p-24;
        const uint32_t index = dimension == 0 ? sample_ : permute(sample_, count_, uint32_t(h >> 24));
        double x = r1 + a1 * index, y = r2 + a2 * index;
        x -= double(int64_t(x));
        y -= double(int64_t(y));
        // float(x) may round up to 1.0; keep samples in [0, 1).
        return {float(x < 0.99999994 ? x : 0.99999994), float(y < 0.99999994 ? y : 0.99999994)};
    }

private:
    uint64_t key_;
    uint32_t sample_, count_;
};

}  // namespace lmrefine
