// The packer's corner snap: corners of one chart closer than a tolerance
// become one corner (Blender's layouts are not bit-exact), so the packed
// charts are bit-exact in the output and check_layout sees the charts that
// were packed. A snap never flips or flattens a triangle.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

#include "lmrefine/layout/coverage.h"

namespace lmrefine::pack {

// Per UV index its (snapped) UV in double. chart_of_uv: the chart of each
// UV index (-1 if unused); corners snap only within their chart. Triangles
// the snap would flip or make degenerate (check_layout's rule) keep their
// corners' own UVs.
std::vector<glm::dvec2> snapped_uvs(const UvLayout& layout, const std::vector<int32_t>& chart_of_uv, double tolerance);

}  // namespace lmrefine::pack
