#include "lmrefine/bake/dilation.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "lmrefine/core/nearest_point.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/texel_space.h"
#include "lmrefine/layout/chart.h"

namespace lmrefine {

NearCharts::NearCharts(int width, int height)
    : width_(width), height_(height), chart_(size_t(int64_t(width) * height), -1),
      distance2_(chart_.size(), 0.0f) {}

void NearCharts::add(const UvLayout& layout, const int32_t* triangle_chart, int32_t chart_base, const uint8_t* skip,
                     const std::vector<int32_t>& texel_chart) {
    const float reach2 = float(kNearChartReach * kNearChartReach);
    // Texel centres (col + 0.5, row + 0.5) inside [low, high], clamped to the
    // image in double first (UVs far outside [0, 1] would overflow an int).
    const auto first = [](double low, int size) { return int(std::clamp(std::ceil(low - 0.5), 0.0, double(size))); };
    const auto end = [](double high, int size) {
        return int(std::clamp(std::floor(high - 0.5) + 1.0, 0.0, double(size)));
    };
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        if (skip != nullptr && skip[t]) continue;
        glm::dvec2 c[3];
        for (int j = 0; j < 3; ++j) {
            const float* uv = layout.uvs + 2 * int64_t(layout.triangles[3 * t + j]);
            c[j] = uv_to_pixel(glm::dvec2(uv[0], uv[1]), width_, height_);
        }
        const double area = (c[1].x - c[0].x) * (c[2].y - c[0].y) - (c[1].y - c[0].y) * (c[2].x - c[0].x);
        if (!(std::abs(area) > 0.0)) continue;  // the raster skips these too
        const int col_begin = first(std::min({c[0].x, c[1].x, c[2].x}) - kNearChartReach, width_);
        const int col_end = end(std::max({c[0].x, c[1].x, c[2].x}) + kNearChartReach, width_);
        const int row_begin = first(std::min({c[0].y, c[1].y, c[2].y}) - kNearChartReach, height_);
        const int row_end = end(std::max({c[0].y, c[1].y, c[2].y}) + kNearChartReach, height_);
        const int32_t chart = chart_base + triangle_chart[t];
        for (int row = row_begin; row < row_end; ++row) {
            for (int col = col_begin; col < col_end; ++col) {
                const size_t texel = size_t(int64_t(row) * width_ + col);
                if (texel_chart[texel] >= 0) continue;
                const float d = float(squared_distance_to_triangle({col + 0.5, row + 0.5}, c));
                if (!(d < reach2)) continue;  // NaN too (a triangle of huge UVs)
                const int32_t held = chart_[texel];
                if (held < 0 || d < distance2_[texel] || (d == distance2_[texel] && chart < held)) {
                    distance2_[texel] = d;
                    chart_[texel] = chart;
                }
            }
        }
    }
}

std::vector<int32_t> NearCharts::take(const std::vector<int32_t>& texel_chart) {
    // A texel a later layout of the map covers is not in the gutter.
    for (size_t i = 0; i < chart_.size(); ++i) {
        if (texel_chart[i] >= 0) chart_[i] = -1;
    }
    distance2_.clear();
    return std::move(chart_);
}

void dilate(float* rgba, int width, int height, const int32_t* texel_chart, const int32_t* near_chart,
            int iterations) {
    std::vector<int32_t> chart(texel_chart, texel_chart + int64_t(width) * height);
    std::vector<int32_t> next = chart;
    struct Candidate {
        int32_t chart;
        int count;
        float sum[3];
    };
    // A ring reads only texels filled before it (`chart`) and writes only
    // texels still empty there, so its rows are independent: the result is
    // the same for any thread count.
    const auto fill_rows = [&](int64_t begin, int64_t end, bool& changed) {
        for (int row = int(begin); row < int(end); ++row) {
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
                const int32_t near = near_chart != nullptr ? near_chart[index] : -1;
                for (int k = 0; k < found && near >= 0; ++k) {
                    if (candidates[k].chart == near) best = k;
                }
                for (int ch = 0; ch < 3; ++ch) rgba[4 * index + ch] = candidates[best].sum[ch] / float(candidates[best].count);
                rgba[4 * index + 3] = 0.0f;
                next[index] = candidates[best].chart;
                changed = true;
            }
        }
    };
    constexpr int64_t kRowsPerTask = 16;
    const int64_t tasks = (int64_t(height) + kRowsPerTask - 1) / kRowsPerTask;
    std::vector<uint8_t> task_changed(static_cast<size_t>(tasks), 0);
    for (int ring = 0; ring < iterations; ++ring) {
        std::fill(task_changed.begin(), task_changed.end(), uint8_t(0));
        parallel_for(tasks, 1, [&](int64_t first, int64_t last) {
            for (int64_t task = first; task < last; ++task) {
                bool changed = false;
                fill_rows(task * kRowsPerTask, std::min<int64_t>(height, (task + 1) * kRowsPerTask), changed);
                task_changed[size_t(task)] = changed;
            }
        });
        if (std::find(task_changed.begin(), task_changed.end(), uint8_t(1)) == task_changed.end()) break;
        chart = next;
    }
}

void dilate(float* rgba, int width, int height, const UvLayout& layout, int iterations) {
    const Charts charts = find_charts(layout);
    std::vector<int32_t> texel_chart(size_t(int64_t(width) * height), -1);
    for_each_covered_texel(layout, width, height, [&](int64_t t, int row, int col) {
        int32_t& owner = texel_chart[size_t(int64_t(row) * width + col)];
        if (owner < 0) owner = charts.triangle_chart[size_t(t)];
    });
    NearCharts near(width, height);
    near.add(layout, charts.triangle_chart.data(), 0, nullptr, texel_chart);
    const std::vector<int32_t> near_chart = near.take(texel_chart);
    dilate(rgba, width, height, texel_chart.data(), near_chart.data(), iterations);
}

}  // namespace lmrefine
