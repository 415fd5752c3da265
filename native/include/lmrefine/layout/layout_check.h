// Validity of a UV layout at a lightmap resolution (docs/method.md §7): flipped and
// degenerate triangles, triangles of different charts that overlap, UVs
// outside [0, 1], and the narrowest gutter between charts in texels.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "lmrefine/layout/chart.h"
#include "lmrefine/layout/coverage.h"
#include "lmrefine/layout/layout_raster.h"

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
    // Charts with an overlapping triangle (of failing_charts); sorted. Filled
    // with failing_charts: a refinement may not make a chart overlap that did
    // not, while the count of a chart that overlapped itself may grow with its
    // scale (it is counted in texels).
    std::vector<int32_t> overlapping_charts;
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
// Charts are find_charts(reference or layout, chart_tolerance).
LayoutReport check_layout(const UvLayout& layout, int width, int height, double padding,
                          const float* reference_uvs = nullptr, bool list_failing_charts = false,
                          bool relative_gutter = false, double chart_tolerance = 0.0);

// Checks of one original layout and of its warped versions (same triangles,
// moved UVs), as the refiner's back-off rounds make them: what depends only
// on the original (its charts, orientations, rasterization and chart-pair
// distances) is computed once instead of per check. Results equal
// check_layout's bit for bit. `original` is viewed, not copied: it must
// outlive the checker. Caches fill on first use (once, thread-safe).
class LayoutChecker {
public:
    LayoutChecker(const UvLayout& original, int width, int height, double padding, double chart_tolerance = 0.0);
    ~LayoutChecker();

    const Charts& charts() const { return charts_; }
    // The original's rasterization (computed on first use).
    const LayoutRaster& raster() const;
    // texel_owners of the original, every triangle counted (computed on first use).
    const std::vector<int32_t>& owners() const;

    // check_layout(original, width, height, padding, nullptr, list_failing_charts).
    LayoutReport check_original(bool list_failing_charts = false) const;
    // check_layout({uvs, original's triangles}, width, height, padding,
    // original.uvs, list_failing_charts, relative_gutter); uvs must be valid.
    LayoutReport check(const float* uvs, bool list_failing_charts, bool relative_gutter) const;

private:
    struct Gutter;
    const Gutter& original_gutter() const;
    LayoutReport check_against(const UvLayout& layout, const LayoutRaster& raster, bool with_reference,
                               bool list_failing_charts, bool relative_gutter) const;

    UvLayout original_;
    int width_, height_;
    double padding_;
    Charts charts_;
    std::vector<int8_t> orientation_;  // of the original, per triangle
    mutable std::once_flag raster_once_, owners_once_, gutter_once_;
    mutable std::unique_ptr<LayoutRaster> raster_;
    mutable std::vector<int32_t> owners_;
    mutable std::unique_ptr<Gutter> gutter_;
};

}  // namespace lmrefine
