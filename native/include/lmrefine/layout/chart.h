// Charts: the connected pieces of a UV layout. Layouts arrive as per-corner
// UVs, so a vertex shared inside a chart appears once per corner with the
// same UV value; triangles are joined where corners share a UV index or hold
// UVs closer than a tolerance (bit-identical with tolerance 0). Blender's
// layouts are not bit-exact, so callers that want its islands weld within a
// small tolerance.
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine {

struct Charts {
    std::vector<int32_t> triangle_chart;  // chart id per triangle, 0..count-1, in order of first appearance
    int32_t count = 0;
};

// The layout must be valid (validate_layout); tolerance >= 0 is a UV-space
// distance: corners closer than it (or bit-identical) are joined.
Charts find_charts(const UvLayout& layout, double tolerance = 0.0);

// Welded corners: per UV index, the smallest UV index of the triangles'
// corners it is joined to by the tolerance (corners closer than it, chained),
// itself when none; UV indices no triangle uses map to themselves. With
// tolerance 0, bit-identical UVs are joined.
std::vector<int64_t> weld_corners(const UvLayout& layout, double tolerance);

}  // namespace lmrefine
