// Gutter texels: the texels whose cells the automaton may shift but not
// compress, so the gutter between charts keeps its width (issue 3, docs/method.md §7).
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine {

// (height * width) bytes, 1 for texels no chart covers or two charts cover,
// and for texels next to (8-neighbourhood) a texel of another chart or of
// two. Every straight path between two charts crosses only such texels and
// chart edges facing the gutter (covered, next to an uncovered texel: the
// automaton lets them shrink only to edge_shrink), so chart pairs keep
// nearly their distance; the layout check judges the rest. Charts as
// find_charts.
std::vector<uint8_t> gutter_texels(const UvLayout& layout, int width, int height);

// The same from the layout's texel_owners (every triangle counted), for a
// caller that already rasterized it.
std::vector<uint8_t> gutter_texels(const std::vector<int32_t>& owners, int width, int height);

}  // namespace lmrefine
