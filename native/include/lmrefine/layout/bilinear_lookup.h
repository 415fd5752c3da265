// Bilinear lookup: a lightmap read at arbitrary UVs, as a GPU sampler reads
// it at run time. The quality metrics read every bake through it, and the
// re-chart route carries the first bake over to the re-charted layout with it
// (python/lmrefine/rechart_route.py, resample_lightmap).
#pragma once

#include <cstdint>

namespace lmrefine {

// Samples an image (height, width, channels), row-major, row 0 at the top
// (v = 1), at `count` UVs (count, 2): texel centres at ((j + .5) / W,
// 1 - (i + .5) / H), clamped to the border. Writes (count, channels)
// doubles to `out`. Double precision, in the same order of operations as the
// numpy reference in tests/test_metrics.py, so both give the same bits.
// UVs must not be NaN (the caller validates them); +-Inf clamps to the border.
void bilinear_lookup(const float* image, int64_t width, int64_t height, int64_t channels, const double* uvs,
                     int64_t count, double* out);
void bilinear_lookup(const double* image, int64_t width, int64_t height, int64_t channels, const double* uvs,
                     int64_t count, double* out);

}  // namespace lmrefine
