// Dilation (docs/method.md §1, step 4): fill the gutter texels next to charts so
// that bilinear sampling at a chart border does not show seams.
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine {

// Bilinear lookup reads the four texel centres around a point, each less than
// sqrt(2) texels away: a gutter texel within this distance of a chart can be
// read from a point on that chart, and only from the nearest chart's points
// when charts are at least two texels apart.
constexpr double kNearChartReach = 1.5;

// For each gutter texel, the chart nearest its centre within kNearChartReach
// (the smaller id on a tie), gathered layout by layout.
class NearCharts {
public:
    NearCharts(int width, int height);
    // Adds `layout`'s triangles (chart triangle_chart[t] + chart_base; those
    // with skip[t] != 0 left out, `skip` may be null) for the texels that
    // texel_chart (height * width) leaves in the gutter (-1).
    void add(const UvLayout& layout, const int32_t* triangle_chart, int32_t chart_base, const uint8_t* skip,
             const std::vector<int32_t>& texel_chart);
    // The near chart per texel (-1: none, or covered by texel_chart).
    std::vector<int32_t> take(const std::vector<int32_t>& texel_chart);

private:
    int width_, height_;
    std::vector<int32_t> chart_;
    std::vector<float> distance2_;  // squared distance to chart_; float: what ties is what matters
};

// `texel_chart` (height * width): the chart covering each texel, or -1 in the
// gutter. `near_chart` (height * width, may be null): for a gutter texel, its
// NearCharts chart, else -1. Each of `iterations` rings gives every gutter
// texel that touches filled texels (8-neighbourhood) the mean colour of its
// neighbours of one chart: its near chart when it has neighbours of it, else
// the chart with most such neighbours, the smaller id on a tie; the texel
// then belongs to that chart for the next ring. So colour never mixes across
// charts, a chart's border texels read its own light where two charts are two
// texels apart, and covered texels are never written. `rgba` is (height,
// width, 4); colour channels are filled, alpha (coverage) stays 0.
void dilate(float* rgba, int width, int height, const int32_t* texel_chart, const int32_t* near_chart,
            int iterations);

// The same dilation for an image baked elsewhere (a Cycles bake, maps merged
// into a shared atlas): the texels `layout`'s triangles cover (coverage_mask)
// keep their colour, the charts are find_charts' (the first to cover a texel
// owns it), and the gutter is filled anew. The layout must be valid.
void dilate(float* rgba, int width, int height, const UvLayout& layout, int iterations);

}  // namespace lmrefine
