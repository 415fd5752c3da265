#include "occupancy.h"

#include <algorithm>

namespace lmrefine::pack {
namespace {

int lowest_bit(uint64_t word) {
    int bit = 0;
    while (!(word >> bit & 1)) ++bit;  // portable (no builtins); words are short to walk
    return bit;
}

// Keeps the parts of `candidates` (sorted, disjoint column ranges of the
// footprint's corner) where span [lo, hi) lies in one of `runs`.
void keep_inside(const std::vector<Span>& candidates, const std::vector<Span>& runs, int lo, int hi,
                 std::vector<Span>& out) {
    out.clear();
    size_t k = 0;
    for (const Span& run : runs) {
        if (run.second - run.first < hi - lo) continue;
        // Corners x with [x + lo, x + hi) inside the run.
        const int first = run.first - lo, last = run.second - hi + 1;
        while (k < candidates.size() && candidates[k].second <= first) ++k;
        for (size_t m = k; m < candidates.size() && candidates[m].first < last; ++m) {
            const int a = std::max(first, candidates[m].first), b = std::min(last, candidates[m].second);
            if (a < b) out.emplace_back(a, b);
        }
    }
}

}  // namespace

Occupancy::Occupancy(int width, int height)
    : width_(width), height_(height), words_((width + 63) / 64), bits_(size_t(words_) * size_t(height), 0),
      runs_(size_t(height), std::vector<Span>{{0, width}}), longest_(size_t(height), width) {}

void Occupancy::update_runs(int row) {
    const uint64_t* words = bits_.data() + size_t(row) * size_t(words_);
    std::vector<Span>& runs = runs_[size_t(row)];
    runs.clear();
    int longest = 0;
    int c = 0;
    while (c < width_) {
        // Skip blocked texels, then take the free run.
        while (c < width_) {
            const uint64_t blocked = words[c >> 6] >> (c & 63);
            if (!(blocked & 1)) break;
            const uint64_t free = ~blocked;
            c = free ? c + lowest_bit(free) : (c | 63) + 1;
        }
        if (c >= width_) break;
        const int begin = c;
        while (c < width_) {
            const uint64_t blocked = words[c >> 6] >> (c & 63);
            if (blocked & 1) break;
            c = blocked ? c + lowest_bit(blocked) : (c | 63) + 1;
        }
        c = std::min(c, width_);
        runs.push_back({begin, c});
        longest = std::max(longest, c - begin);
    }
    longest_[size_t(row)] = longest;
}

bool Occupancy::first_fit(const Footprint& fp, int& out_x, int& out_y, int last_row) const {
    const int fw = fp.covered.width, fh = fp.covered.height;
    if (fw > width_ || fh > height_) return false;
    // Atlas row q is too short for footprint row r: no corner row up to q
    // that puts q at a footprint row with a longer span can fit either. The
    // corner row to try next is the first that puts q at a footprint row
    // whose longest span fits (past q when none does); the rows skipped
    // would each fail the tests below.
    const auto next_row = [&](int q, int r) {
        const int free = longest_[size_t(q)];
        int k = r - 1;
        while (k >= 0 && fp.longest[size_t(k)] > free) --k;
        return q - k;
    };
    for (int y = 0; y + fh <= height_ && y <= last_row;) {
        // A row whose longest free run is too short rules the row out at once.
        if (longest_[size_t(y + fp.tightest)] < fp.longest[size_t(fp.tightest)]) {
            y = next_row(y + fp.tightest, fp.tightest);
            continue;
        }
        int long_enough = 0;  // footprint rows from the top whose atlas row has a long enough run
        while (long_enough < fh && longest_[size_t(y + long_enough)] >= fp.longest[size_t(long_enough)]) ++long_enough;
        if (long_enough < fh) {
            y = next_row(y + long_enough, long_enough);
            continue;
        }
        // The corners where every span lies in a free run, narrowed row by
        // row (the tightest row first: it leaves the fewest).
        candidates_.assign(1, {0, width_ - fw + 1});
        for (int n = 0; n < fh && !candidates_.empty(); ++n) {
            const int r = n == 0 ? fp.tightest : (n <= fp.tightest ? n - 1 : n);
            for (int k = fp.covered.offsets[size_t(r)]; k < fp.covered.offsets[size_t(r) + 1] && !candidates_.empty(); ++k) {
                keep_inside(candidates_, runs_[size_t(y + r)], fp.covered.spans[size_t(k)].first,
                            fp.covered.spans[size_t(k)].second, next_);
                candidates_.swap(next_);
            }
        }
        if (!candidates_.empty()) {
            out_x = candidates_.front().first;
            out_y = y;
            return true;
        }
        ++y;
    }
    return false;
}

void Occupancy::place(const Footprint& fp, int x, int y) {
    const SpanRows& d = fp.dilated;
    for (int r = 0; r < d.height; ++r) {
        const int row = y - fp.reach + r;
        if (row < 0 || row >= height_) continue;
        uint64_t* words = bits_.data() + size_t(row) * size_t(words_);
        for (int k = d.offsets[size_t(r)]; k < d.offsets[size_t(r) + 1]; ++k) {
            const int lo = std::max(0, x - fp.reach + d.spans[size_t(k)].first);
            const int hi = std::min(width_, x - fp.reach + d.spans[size_t(k)].second);
            for (int c = lo; c < hi; ++c) words[c >> 6] |= uint64_t(1) << (c & 63);
        }
        update_runs(row);
    }
}

}  // namespace lmrefine::pack
