#include "occupancy.h"

#include <algorithm>

namespace lmrefine::pack {
namespace {

int highest_bit(uint64_t word) {
    int bit = 63;
    while (!(word >> bit)) --bit;  // portable; a word rarely needs many steps after the mask
    return bit;
}

}  // namespace

Occupancy::Occupancy(int width, int height)
    : width_(width), height_(height), words_((width + 63) / 64),
      bits_(size_t(words_) * size_t(height), 0), first_free_(size_t(height), 0) {}

int Occupancy::last_occupied(int row, int begin, int end) const {
    if (begin >= end) return -1;
    const uint64_t* words = bits_.data() + size_t(row) * size_t(words_);
    const int last = end - 1;
    for (int w = last >> 6; w >= (begin >> 6); --w) {
        uint64_t word = words[w];
        if (!word) continue;
        if (w == (last >> 6) && (last & 63) != 63) word &= (uint64_t(1) << ((last & 63) + 1)) - 1;
        if (w == (begin >> 6)) word &= ~uint64_t(0) << (begin & 63);
        if (word) return w * 64 + highest_bit(word);
    }
    return -1;
}

bool Occupancy::first_fit(const Footprint& fp, int& out_x, int& out_y) const {
    const int fw = fp.covered.width, fh = fp.covered.height;
    if (fw > width_ || fh > height_) return false;
    for (int y = 0; y + fh <= height_; ++y) {
        // Columns left of a row's first free texel are occupied, so the
        // footprint's first texel in that row must start at or after it.
        int x = 0;
        for (int r = 0; r < fh && x + fw <= width_; ++r) {
            if (fp.row_first[size_t(r)] < fw) x = std::max(x, first_free_[size_t(y + r)] - fp.row_first[size_t(r)]);
        }
        while (x + fw <= width_) {
            // A span over an occupied texel c can only clear it by starting
            // after c: jump there (no fitting position is skipped).
            int jump = x;
            const int dy = y - fp.reach, dx = x - fp.reach;
            for (int r = 0; r < fp.dilated.height && jump == x; ++r) {
                const int row = dy + r;
                if (row < 0 || row >= height_) continue;
                for (int k = fp.dilated.offsets[size_t(r)]; k < fp.dilated.offsets[size_t(r) + 1]; ++k) {
                    const auto [lo, hi] = fp.dilated.spans[size_t(k)];
                    const int c = last_occupied(row, std::max(0, dx + lo), std::min(width_, dx + hi));
                    if (c >= 0) {
                        jump = std::max(jump, c - lo + fp.reach + 1);
                        break;
                    }
                }
            }
            if (jump == x) {
                out_x = x;
                out_y = y;
                return true;
            }
            x = jump;
        }
    }
    return false;
}

void Occupancy::place(const Footprint& fp, int x, int y) {
    for (int r = 0; r < fp.covered.height; ++r) {
        const int row = y + r;
        uint64_t* words = bits_.data() + size_t(row) * size_t(words_);
        for (int k = fp.covered.offsets[size_t(r)]; k < fp.covered.offsets[size_t(r) + 1]; ++k) {
            const auto [lo, hi] = fp.covered.spans[size_t(k)];
            for (int c = x + lo; c < x + hi; ++c) words[c >> 6] |= uint64_t(1) << (c & 63);
        }
        int& first = first_free_[size_t(row)];
        while (first < width_ && (words[first >> 6] >> (first & 63) & 1)) ++first;
    }
}

}  // namespace lmrefine::pack
