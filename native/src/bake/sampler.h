// Per-texel sample sequences (private to the baker). Each texel (or point)
// gets a key from the seed and its index alone, so results do not depend on
// which thread ran it. Dimensions come in pairs, each pair a 4-D Owen-
// scrambled Sobol' set with its own scramble per texel (below), and each
// pair but the first visits the samples in its own random order (permute),
// so pairs are not correlated with each other (the same order everywhere
// would make, e.g., the bounce direction a function of the light sample).
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

// The smallest 2^k - 1 >= count - 1 (count >= 1).
inline uint32_t power_of_two_mask(uint32_t count) {
    uint32_t mask = count - 1;
    mask |= mask >> 1;
    mask |= mask >> 2;
    mask |= mask >> 4;
    mask |= mask >> 8;
    mask |= mask >> 16;
    return mask;
}

// A random bijection of [0, count) picked by `seed`: invertible steps on the
// smallest power-of-two domain (xor, odd multiply, xorshift), walked until
// the value falls inside [0, count) (the construction of Kensler 2013,
// "Correlated Multi-Jittered Sampling", with fewer rounds: it only has to
// decorrelate dimensions, and it runs once per sample and dimension).
inline uint32_t permute(uint32_t i, uint32_t count, uint32_t seed) {
    const uint32_t w = power_of_two_mask(count);
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

// Sobol' points with hash-based Owen scrambling (Burley 2020, "Practical
// Hash-based Owen Scrambling"). Dimensions are used in pairs: dimension 2g
// takes Sobol' dimensions 0-1 and 2g + 1 dimensions 2-3, through one shuffled
// index, so each pair is a 4-D scrambled Sobol' set (the sample's place in
// the texel and its AO or sky direction are stratified jointly, not only
// each on its own); pairs get independent shuffles (padding).
namespace sobol {

constexpr int kBits = 32;

struct Directions {
    uint32_t v[4][kBits];
};

// Joe and Kuo's primitive polynomials and initial numbers for Sobol'
// dimensions 1-3 (dimension 0 is van der Corput's sequence).
constexpr Directions make_directions() {
    Directions d{};
    const uint32_t degree[4] = {0, 1, 2, 3}, poly[4] = {0, 0, 1, 1};
    const uint32_t initial[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 3, 0}, {1, 3, 1}};
    for (int i = 0; i < kBits; ++i) d.v[0][i] = 1u << (31 - i);
    for (int dim = 1; dim < 4; ++dim) {
        const uint32_t s = degree[dim], a = poly[dim];
        for (int i = 0; i < kBits; ++i) {
            if (uint32_t(i) < s) {
                d.v[dim][i] = initial[dim][i] << (31 - i);
            } else {
                uint32_t v = d.v[dim][i - int(s)] ^ (d.v[dim][i - int(s)] >> s);
                for (uint32_t k = 1; k < s; ++k) {
                    if ((a >> (s - 1 - k)) & 1u) v ^= d.v[dim][i - int(k)];
                }
                d.v[dim][i] = v;
            }
        }
    }
    return d;
}

constexpr uint32_t reverse_bits_constexpr(uint32_t x) {
    uint32_t r = 0;
    for (int i = 0; i < 32; ++i) r |= ((x >> i) & 1u) << (31 - i);
    return r;
}

// Bit-reversed: Owen scrambling works on reversed values (below), so points
// are built reversed and turned around once, after scrambling.
constexpr Directions make_reversed_directions() {
    Directions d = make_directions();
    for (auto& dim : d.v) {
        for (uint32_t& v : dim) v = reverse_bits_constexpr(v);
    }
    return d;
}

inline constexpr Directions kReversed = make_reversed_directions();

inline uint32_t reverse_bits(uint32_t x) {
    x = (x << 16) | (x >> 16);
    x = ((x & 0x00ff00ffu) << 8) | ((x & 0xff00ff00u) >> 8);
    x = ((x & 0x0f0f0f0fu) << 4) | ((x & 0xf0f0f0f0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xccccccccu) >> 2);
    return ((x & 0x55555555u) << 1) | ((x & 0xaaaaaaaau) >> 1);
}

// Burley's Laine-Karras-style hash: each bit depends only on lower bits, so
// on bit-reversed values it is a nested uniform (Owen) scramble.
inline uint32_t laine_karras(uint32_t x, uint32_t seed) {
    x ^= x * 0x3d20adeau;
    x += seed;
    x *= (seed >> 16) | 1u;
    x ^= x * 0x05526c56u;
    x ^= x * 0x53a22864u;
    return x;
}

// Sobol' point `index` in dimensions 0-3, bit-reversed.
inline void reversed_point(uint32_t index, uint32_t out[4]) {
    out[0] = out[1] = out[2] = out[3] = 0;
    for (int bit = 0; index != 0; index >>= 1, ++bit) {
        if (!(index & 1u)) continue;
        for (int dim = 0; dim < 4; ++dim) out[dim] ^= kReversed.v[dim][bit];
    }
}

// A reversed Sobol' coordinate, Owen-scrambled, as 0.32 fixed point.
inline uint32_t scramble(uint32_t reversed, uint32_t seed) { return reverse_bits(laine_karras(reversed, seed)); }

}  // namespace sobol

// The `count` samples of one texel or point: per-dimension scramble seeds,
// hashed once (not once per sample).
class SampleSequence {
public:
    void reset(uint64_t key, uint32_t count, uint32_t dimensions) {
        // Shuffled indices stay below the next power of two >= count.
        const uint32_t mask = power_of_two_mask(count);
        if (points_.empty() || mask != mask_) {  // the unscrambled points, shared by all texels
            mask_ = mask;
            points_.resize(4 * (size_t(mask) + 1));
            for (uint32_t i = 0; i <= mask; ++i) sobol::reversed_point(i, &points_[4 * size_t(i)]);
        }
        states_.resize(dimensions);
        for (uint32_t d = 0; d < dimensions; ++d) {
            const uint64_t h = hash_combine(key, d), shuffle = hash_combine(key, 0x5348554646ull + (d >> 1));
            states_[d] = {uint32_t(h), uint32_t(h >> 32), uint32_t(shuffle)};
        }
    }

    // A point in [0, 1)^2 for `sample` in `dimension` (< dimensions).
    glm::vec2 get(uint32_t sample, uint32_t dimension) const {
        const State& s = states_[dimension];
        // All of a texel's samples are used together, so the order within a
        // pair does not matter; other pairs are visited in a random order
        // (any bijection of [0, 2^k) will do) so that they are independent.
        const uint32_t index = dimension < 2 ? sample : permute(sample, mask_ + 1, s.shuffle);
        const uint32_t* point = &points_[4 * size_t(index) + 2 * (dimension & 1u)];
        const uint32_t x = sobol::scramble(point[0], s.x), y = sobol::scramble(point[1], s.y);
        return {float(x >> 8) * 0x1p-24f, float(y >> 8) * 0x1p-24f};  // 24 bits: exact floats < 1
    }

private:
    struct State {
        uint32_t x, y, shuffle;
    };
    std::vector<State> states_;
    std::vector<uint32_t> points_;  // (mask_ + 1, 4) reversed Sobol' points
    uint32_t mask_ = 0;
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
