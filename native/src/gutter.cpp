#include "lmrefine/gutter.h"

#include <algorithm>

#include "lmrefine/chart.h"
#include "lmrefine/error.h"
#include "lmrefine/parallel.h"

namespace lmrefine {

std::vector<uint8_t> gutter_texels(const UvLayout& layout, int width, int height) {
    LMREFINE_REQUIRE(width > 0 && height > 0, "resolution must be positive");
    validate_layout(layout);
    const Charts charts = find_charts(layout);
    constexpr int32_t kUncovered = -1, kShared = -2;
    std::vector<int32_t> owner(size_t(width) * height, kUncovered);
    for_each_covered_texel(layout, width, height, [&](int64_t t, int row, int col) {
        int32_t& o = owner[size_t(row) * width + col];
        const int32_t chart = charts.triangle_chart[size_t(t)];
        if (o == kUncovered) o = chart;
        else if (o != chart) o = kShared;
    });
    std::vector<uint8_t> gutter(size_t(width) * height, 0);
    parallel_for(height, 16, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            for (int j = 0; j < width; ++j) {
                const int32_t o = owner[size_t(i) * width + j];
                bool edge = o < 0;
                for (int y = std::max(0, i - 1); y <= std::min(height - 1, i + 1) && !edge; ++y) {
                    for (int x = std::max(0, j - 1); x <= std::min(width - 1, j + 1); ++x) {
                        const int32_t other = owner[size_t(y) * width + x];
                        edge = edge || (other != o && other != kUncovered);
                    }
                }
                gutter[size_t(i) * width + j] = edge;
            }
        }
    });
    return gutter;
}

}  // namespace lmrefine
