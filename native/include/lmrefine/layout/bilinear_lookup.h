// Bilinear lookup: a lightmap read at arbitrary UVs, as a GPU sampler reads
// it at run time. The quality metrics read every bake through it, and the
// re-chart route carries the first bake over to the re-charted layout with it
// (python/lmrefine/rechart_route.py, resample_lightmap).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace lmrefine {

// One point: the bilinear value at (u, v) of every channel, written to out[0, channels).
template <class T>
inline void bilinear_sample(const T* image, int64_t width, int64_t height, int64_t channels, double u, double v,
                            double* out) {
    const double w = double(width), h = double(height);
    // Texel coordinates of the point, centres on integers, clamped to the border.
    const double x = std::clamp(u * w - 0.5, 0.0, w - 1.0);
    const double y = std::clamp((1.0 - v) * h - 0.5, 0.0, h - 1.0);
    // The 2 x 2 texels around it (one column or row on an image that narrow).
    const int64_t j0 = width > 1 ? std::min(int64_t(std::floor(x)), width - 2) : 0;
    const int64_t i0 = height > 1 ? std::min(int64_t(std::floor(y)), height - 2) : 0;
    const double fx = width > 1 ? x - double(j0) : 0.0;
    const double fy = height > 1 ? y - double(i0) : 0.0;
    const int64_t j1 = std::min(j0 + 1, width - 1), i1 = std::min(i0 + 1, height - 1);
    const T* a = image + (i0 * width + j0) * channels;
    const T* b = image + (i0 * width + j1) * channels;
    const T* c = image + (i1 * width + j0) * channels;
    const T* d = image + (i1 * width + j1) * channels;
    for (int64_t k = 0; k < channels; ++k) {
        const double top = double(a[k]) * (1.0 - fx) + double(b[k]) * fx;
        const double bottom = double(c[k]) * (1.0 - fx) + double(d[k]) * fx;
        out[k] = top * (1.0 - fy) + bottom * fy;
    }
}

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
