// A chart's texel footprint at one scale and rotation: the texels its
// triangles cover (conservative, as coverage_mask), with its bounding box's
// corner on a texel corner, and that footprint dilated by the padding.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <glm/vec2.hpp>

#include "lmrefine/layout/coverage.h"

namespace lmrefine::pack {

using Span = std::pair<int32_t, int32_t>;  // columns [first, second)

// Row spans of a small bitmap: row r's spans are spans[offsets[r] .. offsets[r + 1]).
struct SpanRows {
    int width = 0, height = 0;
    std::vector<int32_t> offsets;
    std::vector<Span> spans;
};

struct Footprint {
    SpanRows covered;       // the chart's texels, origin at the footprint's corner
    SpanRows dilated;       // texels another chart may not cover, origin at (-reach, -reach)
    int reach = 0;          // how far the dilation reaches past the footprint
    int64_t texels = 0;     // covered texels
    std::vector<int32_t> row_first;  // per covered row, its first covered column (width if none)
};

// One chart as the packer sees it: its triangles and used UV indices.
struct ChartPiece {
    std::vector<int64_t> triangles;
    std::vector<int64_t> corners;  // distinct UV indices, ascending
};

// The chart's corners in footprint pixel coordinates (x right, y down, the
// bounding box's corner at 0) for a linear scale and quarter turns, indexed
// like piece.corners. `uvs` are the (welded) input UVs in double.
std::vector<glm::dvec2> local_pixels(const ChartPiece& piece, const std::vector<glm::dvec2>& uvs, double scale,
                                     int quarter_turns, int width, int height);

// The footprint of the chart at those local pixels; `padding` in texels.
Footprint make_footprint(const ChartPiece& piece, const UvLayout& layout, const std::vector<glm::dvec2>& local,
                         double padding);

}  // namespace lmrefine::pack
