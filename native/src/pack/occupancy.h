// The atlas's blocked texels and the first-fit placement rule: a chart goes
// to the first position in scan order (rows top to bottom, then columns left
// to right) where its footprint fits inside the atlas and meets no blocked
// texel. Blocked texels are the placed charts' dilated footprints; the
// dilation is symmetric, so a footprint meeting none is as far from every
// placed footprint as the padding asks.
#pragma once

#include <cstdint>
#include <vector>

#include "footprint.h"

namespace lmrefine::pack {

class Occupancy {
public:
    Occupancy(int width, int height);

    // The first position (column, row) of the footprint's corner where it
    // fits, in rows first_row to last_row; false if none.
    bool first_fit(const Footprint& fp, int& x, int& y, int last_row = INT32_MAX, int first_row = 0) const;
    // Blocks the footprint's dilation at (x, y).
    void place(const Footprint& fp, int x, int y);

private:
    // Blocks columns [lo, hi) of a row (inside the atlas, lo < hi).
    void block(int row, int lo, int hi);

    int width_, height_;
    std::vector<std::vector<Span>> runs_;    // per row, its free runs [first, second), ascending and maximal
    std::vector<int32_t> longest_;           // per row, its longest free run
    mutable std::vector<Span> candidates_, next_;  // first_fit's scratch (one Occupancy per thread)
    mutable std::vector<int> row_order_;            // first_fit's footprint rows, in the order tried
};

}  // namespace lmrefine::pack
