// Per-texel sample sequences (private to the baker). Each texel (or point)
// gets a key from the seed and its index alone, so results do not depend on
// which thread ran it. Each 2-D dimension is the R2 low-discrepancy sequence
// (Roberts 2018) shifted by a per-key, per-dimension random rotation
// (Cranley-Patterson), so every sample count is well stratified; and each
// dimension visits the samples in its own random order (permute), so dimensions are not correlated with each other (the same
// sequence in every dimension would make, e.g., the bounce direction a
// function of the light sample).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

namespace lmrefine {

inline uint64_t mix64(uint64_t x) {  // splitmix64 finalizer
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

inline uint64_t hash_combine(uint64_t a, uint64_t b) { return mix64(a ^ mix64(b)); }

// A random bijection of [0, count) picked by `seed`: invertible steps on the
// smallest power-of-two domain (xor, odd multiply, xorshift), walked until
// the value falls inside [0, count) (the construction of Kensler 2013,
// "Correlated Multi-Jittered Sampling", with fewer rounds: it only has to
// decorrelate dimensions, and it runs once per sample and dimension).
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
        i ^= (i & w) >> 4;
        i ^= seed >> 16;
        i *= 0x0929eb3f;
        i &= w;
        i ^= i >> 3;
    } while (i >= count);
    return i;
}

// The `count` samples of one texel or point: per-dimension rotations and
// permutation seeds, hashed once (not once per sample).
class SampleSequence {
public:
    void reset(uint64_t key, uint32_t count, uint32_t dimensions) {
        count_ = count;
        states_.resize(dimensions);
        for (uint32_t d = 0; d < dimensions; ++d) {
            const uint64_t h = hash_combine(key, d);
            states_[d] = {uint32_t(h), uint32_t(h >> 32), uint32_t(h >> 16) ^ uint32_t(h >> 48)};
        }
    }

    // A point in [0, 1)^2 for `sample` in `dimension` (< dimensions).
    glm::vec2 get(uint32_t sample, uint32_t dimension) const {
        // R2 in 0.32 fixed point: exact wrap-around, no floating-point fraction.
        constexpr uint32_t a1 = 3242174889u, a2 = 2447445414u;  // 2^32 / g, 2^32 / g^2 (plastic number g)
        const State& s = states_[dimension];
        // Dimension 0 (the position in the texel) keeps the sequence's order.
        const uint32_t index = dimension == 0 ? sample : permute(sample, count_, s.permutation);
        const uint32_t x = s.r1 + a1 * index, y = s.r2 + a2 * index;
        return {float(x >> 8) * 0x1p-24f, float(y >> 8) * 0x1p-24f};  // 24 bits: exact floats < 1
    }

private:
    struct State {
        uint32_t r1, r2, permutation;
    };
    std::vector<State> states_;
    uint32_t count_ = 1;
};

// One sample of a sequence.
class Sampler {
public:
    Sampler(const SampleSequence& sequence, uint32_t sample) : sequence_(sequence), sample_(sample) {}
    glm::vec2 get(uint32_t dimension) const { return sequence_.get(sample_, dimension); }

private:
    const SampleSequence& sequence_;
    uint32_t sample_;
};

}  // namespace lmrefine
