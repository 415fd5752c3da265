#include "lmrefine/layout/gutter.h"

#include <algorithm>

#include "lmrefine/layout/chart.h"
#include "lmrefine/core/error.h"
#include "lmrefine/layout/layout_raster.h"
#include "lmrefine/core/parallel.h"

namespace lmrefine {

std::vector<uint8_t> gutter_texels(const UvLayout& layout, int width, int height) {
    LMREFINE_REQUIRE(width > 0 && height > 0, "resolution must be positive");
    validate_layout(layout);
    const Charts charts = find_charts(layout);
    return gutter_texels(texel_owners(LayoutRaster(layout, width, height), charts.triangle_chart), width, height);
}

std::vector<uint8_t> gutter_texels(const std::vector<int32_t>& owner, int width, int height) {
    std::vector<uint8_t> gutter(size_t(width) * height, 0);
    parallel_for(height, 16, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            // Neighbours outside the image are clamped onto the border: a
            // texel compared with itself or with a neighbour it already has
            // changes nothing, and the loop needs no bounds tests.
            const int32_t* up = owner.data() + size_t(std::max(0, i - 1)) * width;
            const int32_t* mid = owner.data() + size_t(i) * width;
            const int32_t* down = owner.data() + size_t(std::min(height - 1, i + 1)) * width;
            uint8_t* out = gutter.data() + size_t(i) * width;
            // A neighbour of another chart or of two makes a texel gutter; an
            // uncovered one does not (a chart's edge facing the gutter: the
            // automaton's edge_shrink).
            auto edge = [&](int j, int left, int right) {
                const int32_t o = mid[j];
                auto other = [o](int32_t n) { return (n != o) & (n != kUncovered); };
                return uint8_t((o < 0) | other(mid[left]) | other(mid[right]) | other(up[left]) | other(up[j]) |
                               other(up[right]) | other(down[left]) | other(down[j]) | other(down[right]));
            };
            out[0] = edge(0, 0, std::min(1, width - 1));
            for (int j = 1; j < width - 1; ++j) out[j] = edge(j, j - 1, j + 1);
            if (width > 1) out[width - 1] = edge(width - 1, width - 2, width - 1);
        }
    });
    return gutter;
}

}  // namespace lmrefine
