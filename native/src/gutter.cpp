#include "lmrefine/gutter.h"

#include <algorithm>

#include "lmrefine/chart.h"
#include "lmrefine/error.h"
#include "lmrefine/layout_raster.h"
#include "lmrefine/parallel.h"

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
            const int y0 = std::max(0, i - 1), y1 = std::min(height - 1, i + 1);
            for (int j = 0; j < width; ++j) {
                const int32_t o = owner[size_t(i) * width + j];
                const int x0 = std::max(0, j - 1), x1 = std::min(width - 1, j + 1);
                bool edge = o < 0;
                for (int y = y0; y <= y1 && !edge; ++y) {
                    const int32_t* row = owner.data() + size_t(y) * width;
                    for (int x = x0; x <= x1; ++x) edge = edge || row[x] != o;
                }
                gutter[size_t(i) * width + j] = edge;
            }
        }
    });
    return gutter;
}

}  // namespace lmrefine
