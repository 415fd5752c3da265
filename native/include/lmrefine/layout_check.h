// Validity of a UV layout at a lightmap resolution (method §7): flipped and
// degenerate triangles, triangles of different charts that overlap, UVs
// outside [0, 1], and the narrowest gutter between charts in texels.
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/coverage.h"

namespace lmrefine {

struct LayoutReport {
    int64_t flipped = 0;        // triangles whose orientation differs from the reference (see below)
    int64_t degenerate = 0;     // triangles with (numerically) zero area
    int64_t overlapping = 0;    // triangles overlapping a triangle of another chart
    int64_t out_of_bounds = 0;  // UVs outside [0, 1]
    double min_gutter_texels = 0;  // smallest distance between two charts; +inf for fewer than two charts
    int32_t charts = 0;
    // With relative_gutter: chart pairs closer than min(padding, their
    // distance in the reference layout) - 1e-4 texel.
    int64_t gutter_violations = 0;
    bool valid = false;  // nothing flipped, degenerate, overlapping or out of bounds, gutter >= padding
    // Charts with a flipped, overlapping or (newly) degenerate triangle, or
    // closer than `padding` to another chart; sorted. Only filled on request.
    std::vector<int32_t> failing_charts;
};

// Orientation: with `reference_uvs` (the original layout, same shape as
// layout.uvs) a triangle is flipped when its signed area's sign differs from
// the reference triangle's; without, when it differs from the majority of its
// chart (a mirrored chart may be wholly clockwise). Overlap is exact: pairs
// of triangles of different charts that share a rasterized texel are tested
// for an intersection of positive area. The gutter is the exact smallest
// distance, in texels, between boundary edges of different charts.
// With `relative_gutter` (needs reference_uvs) the gutter is also judged per
// chart pair against the reference: gutter_violations counts the pairs now
// closer than min(padding, their reference distance), and failing_charts
// lists their charts (instead of every chart closer than padding). `valid`
// stays absolute.
LayoutReport check_layout(const UvLayout& layout, int width, int height, double padding,
                          const float* reference_uvs = nullptr, bool list_failing_charts = false,
                          bool relative_gutter = false);

}  // namespace lmrefine
