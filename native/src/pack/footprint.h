// A chart's texel footprint at one scale and rotation: the texels its
// triangles (grown by kInset) cover, with the chart kInset inside its
// bounding box's corner on a texel corner; and the footprint dilated by the
// padding: where another chart's footprint may not go.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <glm/vec2.hpp>

#include "lmrefine/layout/coverage.h"

namespace lmrefine::pack {

// The chart is grown by this (texels) before it is rasterized, so footprints
// `padding` apart keep the charts padding + 2 kInset apart: the output's
// rounding to float32 (2e-3 grid units at 16384^2 subdivided twice) cannot bring them closer than
// the padding.
constexpr double kInset = 4e-3;

using Span = std::pair<int32_t, int32_t>;  // columns [first, second)

// Row spans of a small bitmap: row r's spans are spans[offsets[r] .. offsets[r + 1]).
struct SpanRows {
    int width = 0, height = 0;
    std::vector<int32_t> offsets;
    std::vector<Span> spans;
};

struct Footprint {
    SpanRows covered;    // the chart's texels, origin at the footprint's corner
    SpanRows dilated;    // texels another chart may not cover, origin at (-reach, -reach)
    int reach = 0;       // how far the dilation reaches past the footprint
    int64_t texels = 0;  // covered texels
    std::vector<int32_t> longest;  // per covered row, its longest span
    int tightest = 0;              // the covered row with the longest span
};

// Work vectors a footprint is built in, reused from chart to chart: a trial
// builds every chart's footprints, and allocating these each time cost more
// than using them.
struct FootprintScratch {
    struct Run {
        int32_t column, first, end;  // a column's vertical run of covered rows [first, end)
    };
    std::vector<Span> row, merged;
    std::vector<Run> runs;
    std::vector<int32_t> start, count;
};

// One chart as the packer sees it: its triangles and used UV indices.
struct ChartPiece {
    std::vector<int64_t> triangles;
    std::vector<int64_t> corners;  // distinct UV indices, ascending
};

// The chart's corners in footprint pixel coordinates (x right, y down, the
// bounding box's corner at (kInset, kInset)) for a linear scale, indexed
// like piece.corners. `uvs` are the (welded) input UVs.
std::vector<glm::dvec2> local_pixels(const ChartPiece& piece, const std::vector<glm::dvec2>& uvs, double scale,
                                     int width, int height);

// The footprint's size (columns, rows) for those local pixels.
glm::ivec2 footprint_size(const std::vector<glm::dvec2>& local);

// The footprint of the chart at those local pixels; `padding` in texels.
// `bits` and `scratch` are scratch the caller may reuse (the covered texels
// are rasterized into `bits`, row-major, 1 = covered).
Footprint make_footprint(const ChartPiece& piece, const UvLayout& layout, const std::vector<glm::dvec2>& local,
                         double padding, std::vector<uint8_t>& bits, FootprintScratch& scratch);

// A quarter turn counter-clockwise (on the image, so in UV too), in texel
// space: the footprint's texels turned, and a local point of a footprint
// `width` columns wide moved with them. Exact on the texel lattice, so the
// turned chart lies in the turned footprint as the chart in the footprint.
Footprint turned_footprint(const Footprint& fp, FootprintScratch& scratch);
glm::dvec2 turn_local(const glm::dvec2& p, double width);

// The footprint of a bitmap ((height * width) bytes, 1 = covered, 0 = not).
Footprint footprint_of_bits(const std::vector<uint8_t>& bits, int width, int height, double padding);

}  // namespace lmrefine::pack
