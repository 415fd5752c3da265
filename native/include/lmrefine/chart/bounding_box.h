// The turn that gives a chart its smallest bounding box: the packer turns
// charts only by quarter turns, so a square chart unwrapped along its
// diagonal (or a chart stretched along one) would take up to twice its area
// in the atlas.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

#include "lmrefine/layout/coverage.h"

namespace lmrefine::chart {

// Unit direction (cos, sin) of the angle to turn `points` by (about the
// origin) so their axis-aligned box is smallest. A minimal-area rectangle
// has a side along an edge of the convex hull, so only those are tried.
// The points must be finite.
glm::dvec2 smallest_box_turn(const std::vector<glm::dvec2>& points);

// smallest_box_turn of each chart's corners: `triangle_chart` (one id in
// [0, chart_count) per triangle of the valid `layout`). A chart without
// triangles gets (1, 0).
std::vector<glm::dvec2> smallest_box_turns(const UvLayout& layout, const std::vector<int32_t>& triangle_chart,
                                           int32_t chart_count);

}  // namespace lmrefine::chart
