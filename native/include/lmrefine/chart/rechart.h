// Re-charting: a lightmap layout made from the mesh instead of the user's
// UVs. Faces are grouped into charts by their normals (charting.h), each
// chart is unwrapped with a least-squares conformal map (conformal_map.h)
// and scaled to its world-space area, so every chart has the same texel
// density once the packer (pack/packer.h) places them. A chart whose
// unwrap folds or overlaps itself is charted again with half the angle.
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/chart/charting.h"

namespace lmrefine {

class Progress;

// The default weld tolerance, relative to the mesh's size: far below any
// modelled detail, far above float32 rounding of coincident vertices.
constexpr double kRelativeWeld = 1e-6;

struct RechartOptions {
    double angle_degrees = 10.0;  // largest angle between a chart's normals and its first face's, in (0, 90)
    // The same across smooth-shaded edges (SurfaceMesh::corner_normals), in
    // (0, 90): there the angle only bounds the chart's curvature.
    double smooth_angle_degrees = 45.0;
    // Positions closer than this are one vertex (world units); negative:
    // kRelativeWeld times the diagonal of the used positions' bounding box.
    double weld_tolerance = -1.0;
};

struct RechartResult {
    // (3 * triangle_count, 2): corner k of triangle t at row 3t + k, in
    // world units (a chart's UV area is its world area), each chart with its
    // lower-left corner at the origin. Not yet packed.
    std::vector<float> uvs;
    std::vector<int32_t> triangle_chart;  // chart id per triangle, 0..chart_count-1
    int32_t chart_count = 0;
    int32_t grown_charts = 0;    // charts the first growth made
    int32_t split_charts = 0;    // charts charted again because their unwrap folded or overlapped
    int64_t degenerate = 0;      // degenerate faces, each in a chart of its own (a small right triangle)
    int64_t welded_vertices = 0; // vertices merged into another by the weld
};

// Throws InvalidArgument for bad input (indices, non-finite positions, no
// triangle with an area, an angle outside (0, 90)) and Cancelled.
RechartResult rechart(const SurfaceMesh& mesh, const RechartOptions& options, Progress* progress = nullptr);

}  // namespace lmrefine
