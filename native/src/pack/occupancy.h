// The atlas's occupied texels (the placed charts' undilated footprints) as
// bit rows, and the first-fit placement rule: a chart goes to the first
// position in scan order (rows top to bottom, then columns left to right)
// where its dilated footprint meets no occupied texel.
#pragma once

#include <cstdint>
#include <vector>

#include "footprint.h"

namespace lmrefine::pack {

class Occupancy {
public:
    Occupancy(int width, int height);

    // The first position (column, row) of the footprint's corner where it
    // fits inside the atlas and its dilation meets no occupied texel; false
    // if none.
    bool first_fit(const Footprint& fp, int& x, int& y) const;
    // Marks the footprint's covered texels at (x, y) occupied.
    void place(const Footprint& fp, int x, int y);

private:
    // The last occupied column in [begin, end) of a row, or -1.
    int last_occupied(int row, int begin, int end) const;

    int width_, height_, words_;
    std::vector<uint64_t> bits_;       // row-major, words_ per row
    std::vector<int32_t> first_free_;  // per row: every column before it is occupied
};

}  // namespace lmrefine::pack
