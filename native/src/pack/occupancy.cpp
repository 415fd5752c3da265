#include "occupancy.h"

#include <algorithm>

namespace lmrefine::pack {
namespace {

// Keeps the parts of `candidates` (sorted, disjoint column ranges of the
// footprint's corner) where span [lo, hi) lies in one of `runs`.
void keep_inside(const std::vector<Span>& candidates, const std::vector<Span>& runs, int lo, int hi,
                 std::vector<Span>& out) {
    out.clear();
    if (candidates.empty()) return;
    size_t k = 0;
    // Only the runs that can hold the span at a candidate corner: from the
    // first ending past the first candidate's span to the first starting past
    // the last candidate's (a row of a filled atlas has hundreds of runs).
    const int from = candidates.front().first + hi - 1, to = candidates.back().second + lo;
    auto run = std::upper_bound(runs.begin(), runs.end(), from, [](int c, const Span& r) { return c < r.second; });
    for (; run != runs.end() && run->first < to; ++run) {
        if (run->second - run->first < hi - lo) continue;
        // Corners x with [x + lo, x + hi) inside the run.
        const int first = run->first - lo, last = run->second - hi + 1;
        while (k < candidates.size() && candidates[k].second <= first) ++k;
        for (size_t m = k; m < candidates.size() && candidates[m].first < last; ++m) {
            const int a = std::max(first, candidates[m].first), b = std::min(last, candidates[m].second);
            if (a < b) out.emplace_back(a, b);
        }
    }
}

}  // namespace

Occupancy::Occupancy(int width, int height)
    : width_(width), height_(height), runs_(size_t(height), std::vector<Span>{{0, width}}), longest_(size_t(height), width) {}

void Occupancy::block(int row, int lo, int hi) {
    // Blocking only takes cells out of free runs: the runs it meets are cut
    // to the parts left of lo and right of hi, which stay maximal.
    std::vector<Span>& runs = runs_[size_t(row)];
    const auto first = std::upper_bound(runs.begin(), runs.end(), lo, [](int c, const Span& run) { return c < run.second; });
    auto last = first;
    bool longest_cut = false;
    for (; last != runs.end() && last->first < hi; ++last) longest_cut |= last->second - last->first == longest_[size_t(row)];
    if (first == last) return;
    Span pieces[2];
    int count = 0;
    if (first->first < lo) pieces[count++] = {first->first, lo};
    if ((last - 1)->second > hi) pieces[count++] = {hi, (last - 1)->second};
    const auto at = runs.erase(first, last);
    runs.insert(at, pieces, pieces + count);
    if (longest_cut) {
        int longest = 0;
        for (const Span& run : runs) longest = std::max(longest, run.second - run.first);
        longest_[size_t(row)] = longest;
    }
}

bool Occupancy::first_fit(const Footprint& fp, int& out_x, int& out_y, int last_row, int first_row) const {
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
    // The footprint's rows in the order the corners are narrowed: the
    // tightest first (it leaves the fewest), then spread over the footprint
    // (bit-reversed order: top, middle, quarters, ...), because neighbouring
    // rows of a chart rule out nearly the same corners, and far rows of a
    // tall or sheared chart rule out different ones: a failing row comes
    // sooner. Intersections do not depend on the order, so neither does the
    // position found. Made only when a corner row gets that far (a call may
    // end before).
    const auto order_rows = [&] {
        row_order_.assign(1, fp.tightest);
        int bits = 0;
        while ((1 << bits) < fh) ++bits;
        for (int k = 0; k < (1 << bits); ++k) {
            int reversed = 0;
            for (int b = 0; b < bits; ++b) reversed |= (k >> b & 1) << (bits - 1 - b);
            if (reversed < fh && reversed != fp.tightest) row_order_.push_back(reversed);
        }
    };
    bool ordered = false;
    // Atlas rows from the corner row y to clear_to each have a free run as
    // long as the footprint's longest span: a corner row whose rows all lie
    // there passes the row test below without walking the footprint's rows
    // (y only moves down, so each atlas row is looked at about once).
    const int widest = fp.longest[size_t(fp.tightest)];
    int clear_to = 0;
    for (int y = std::max(first_row, 0); y + fh <= height_ && y <= last_row;) {
        // A row whose longest free run is too short rules the row out at once.
        if (longest_[size_t(y + fp.tightest)] < widest) {
            y = next_row(y + fp.tightest, fp.tightest);
            continue;
        }
        clear_to = std::max(clear_to, y);
        while (clear_to < y + fh && longest_[size_t(clear_to)] >= widest) ++clear_to;
        // Footprint rows from the top whose atlas row has a long enough run.
        int long_enough = clear_to >= y + fh ? fh : 0;
        while (long_enough < fh && longest_[size_t(y + long_enough)] >= fp.longest[size_t(long_enough)]) ++long_enough;
        if (long_enough < fh) {
            y = next_row(y + long_enough, long_enough);
            continue;
        }
        // The corners where every span lies in a free run, narrowed row by row.
        if (!ordered) order_rows();
        ordered = true;
        candidates_.assign(1, {0, width_ - fw + 1});
        for (int n = 0; n < fh && !candidates_.empty(); ++n) {
            const int r = row_order_[size_t(n)];
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
        for (int k = d.offsets[size_t(r)]; k < d.offsets[size_t(r) + 1]; ++k) {
            const int lo = std::max(0, x - fp.reach + d.spans[size_t(k)].first);
            const int hi = std::min(width_, x - fp.reach + d.spans[size_t(k)].second);
            if (lo < hi) block(row, lo, hi);
        }
    }
}

}  // namespace lmrefine::pack
