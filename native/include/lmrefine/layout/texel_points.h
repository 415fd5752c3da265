// Texel points: the surface point behind each texel of a layout, as the
// re-chart route needs to carry a lightmap from one layout to another
// (python/lmrefine/rechart_route.py, resample_lightmap).
#pragma once

#include <cstdint>
#include <vector>

namespace lmrefine {

// For every texel (row-major, row 0 at the top, v = 1): the triangle whose
// interior holds the texel's centre deepest (the largest smallest
// barycentric, negative outside; the first such triangle on a tie) among
// the triangles whose texel bounding box holds the texel, with the centre's
// barycentrics there and that score. Texels no such triangle with area
// reaches keep triangle 0, barycentrics 0 and score -inf. Double precision
// throughout, in the same order of operations as the numpy reference in
// tests/test_rechart_route.py, so both give the same bits.
struct TexelPoints {
    std::vector<int64_t> triangle;  // (H * W)
    std::vector<double> bary;       // (H * W, 3)
    std::vector<double> score;      // (H * W)
};

// uvs: (uv_count, 2) doubles, finite; triangles: (triangle_count, 3)
// indices into them, in range (the caller validates both).
TexelPoints texel_points(const double* uvs, const int32_t* triangles, int64_t triangle_count, int width,
                         int height);

// A lightmap `image` (height, width, channels) baked on the source layout
// (source_uvs, source_triangles) carried over to the layout whose texel
// points are `points` (texel_points of the same triangles, same size): each
// texel of `mask` (H * W bytes, nonzero = covered) takes the value of the
// source map at the same surface point, its barycentrics clamped to >= 0
// and normalized (a third each where no triangle with area reaches), read
// from the texels of that triangle's source chart only: `source_chart`
// (per triangle) and `source_owner` (per texel of the source map,
// texel_owners). The bilinear value (bilinear_lookup.h) where the chart owns
// all four texels; else the bilinear weights of those it owns,
// renormalized; else its nearest texel within two; else the bilinear value.
// Other texels are 0. Returns H * W * channels floats, in the same order of
// operations as the numpy reference in tests/test_rechart_route.py: the same
// bits. Indices must be in range (the caller validates them).
std::vector<float> carry_lightmap(const TexelPoints& points, const uint8_t* mask, const double* source_uvs,
                                  const int32_t* source_triangles, const int32_t* source_chart,
                                  const int32_t* source_owner, const float* image, int width, int height,
                                  int channels);

}  // namespace lmrefine
