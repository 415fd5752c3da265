// Charts: the connected pieces of a UV layout. Layouts arrive as per-corner
// UVs, so a vertex shared inside a chart appears once per corner with the
// same UV value; triangles are joined where corners share a UV index or hold
// bit-identical UVs.
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine {

struct Charts {
    std::vector<int32_t> triangle_chart;  // chart id per triangle, 0..count-1, in order of first appearance
    int32_t count = 0;
};

// The layout must be valid (validate_layout).
Charts find_charts(const UvLayout& layout);

}  // namespace lmrefine
