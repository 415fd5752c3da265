#include "lmrefine/bake/dilation.h"

#include <vector>

namespace lmrefine {

void dilate(float* rgba, int width, int height, const int32_t* texel_chart, int iterations) {
    std::vector<int32_t> chart(texel_chart, texel_chart + int64_t(width) * height);
    std::vector<int32_t> next = chart;
    struct Candidate {
        int32_t chart;
        int count;
        float sum[3];
    };
    for (int ring = 0; ring < iterations; ++ring) {
        bool changed = false;
        for (int row = 0; row < height; ++row) {
            for (int col = 0; col < width; ++col) {
                const int64_t index = int64_t(row) * width + col;
                if (chart[index] >= 0) continue;
                Candidate candidates[8];
                int found = 0;
                for (int dr = -1; dr <= 1; ++dr) {
                    for (int dc = -1; dc <= 1; ++dc) {
                        const int r = row + dr, c = col + dc;
                        if ((dr == 0 && dc == 0) || r < 0 || r >= height || c < 0 || c >= width) continue;
                        const int64_t n = int64_t(r) * width + c;
                        if (chart[n] < 0) continue;
                        int k = 0;
                        while (k < found && candidates[k].chart != chart[n]) ++k;
                        if (k == found) candidates[found++] = {chart[n], 0, {0, 0, 0}};
                        ++candidates[k].count;
                        for (int ch = 0; ch < 3; ++ch) candidates[k].sum[ch] += rgba[4 * n + ch];
                    }
                }
                if (found == 0) continue;
                int best = 0;
                for (int k = 1; k < found; ++k) {
                    const Candidate &a = candidates[k], &b = candidates[best];
                    if (a.count > b.count || (a.count == b.count && a.chart < b.chart)) best = k;
                }
                for (int ch = 0; ch < 3; ++ch) rgba[4 * index + ch] = candidates[best].sum[ch] / float(candidates[best].count);
                rgba[4 * index + 3] = 0.0f;
                next[index] = candidates[best].chart;
                changed = true;
            }
        }
        if (!changed) break;
        chart = next;
    }
}

}  // namespace lmrefine
