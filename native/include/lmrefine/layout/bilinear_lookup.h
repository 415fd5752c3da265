// Bilinear lookup: a lightmap read at arbitrary UVs, as a GPU sampler reads
// it at run time. The quality metrics read every bake through it, and the
// re-chart route carries the first bake over to the re-charted layout with it
// (python/lmrefine/rechart_route.py, resample_lightmap).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace lmrefine {

// The 2 x 2 texels a bilinear read at (u, v) blends (one column or row on
// an image that narrow), row-major indices, and the point's fraction
// between them; (x, y) are its texel coordinates, centres on integers,
// clamped to the border.
struct BilinearFootprint {
    int64_t texel[4];  // (i0, j0), (i0, j1), (i1, j0), (i1, j1)
    double x, y, fx, fy;
};

inline BilinearFootprint bilinear_footprint(int64_t width, int64_t height, double u, double v) {
    BilinearFootprint f;
    const double w = double(width), h = double(height);
    f.x = std::clamp(u * w - 0.5, 0.0, w - 1.0);
    f.y = std::clamp((1.0 - v) * h - 0.5, 0.0, h - 1.0);
    const int64_t j0 = width > 1 ? std::min(int64_t(std::floor(f.x)), width - 2) : 0;
    const int64_t i0 = height > 1 ? std::min(int64_t(std::floor(f.y)), height - 2) : 0;
    f.fx = width > 1 ? f.x - double(j0) : 0.0;
    f.fy = height > 1 ? f.y - double(i0) : 0.0;
    const int64_t j1 = std::min(j0 + 1, width - 1), i1 = std::min(i0 + 1, height - 1);
    f.texel[0] = i0 * width + j0;
    f.texel[1] = i0 * width + j1;
    f.texel[2] = i1 * width + j0;
    f.texel[3] = i1 * width + j1;
    return f;
}

// The bilinear value of every channel over footprint `f`, written to out[0, channels).
template <class T>
inline void bilinear_blend(const T* image, int64_t channels, const BilinearFootprint& f, double* out) {
    const T* a = image + f.texel[0] * channels;
    const T* b = image + f.texel[1] * channels;
    const T* c = image + f.texel[2] * channels;
    const T* d = image + f.texel[3] * channels;
    for (int64_t k = 0; k < channels; ++k) {
        const double top = double(a[k]) * (1.0 - f.fx) + double(b[k]) * f.fx;
        const double bottom = double(c[k]) * (1.0 - f.fx) + double(d[k]) * f.fx;
        out[k] = top * (1.0 - f.fy) + bottom * f.fy;
    }
}

// One point: the bilinear value at (u, v) of every channel, written to out[0, channels).
template <class T>
inline void bilinear_sample(const T* image, int64_t width, int64_t height, int64_t channels, double u, double v,
                            double* out) {
    bilinear_blend(image, channels, bilinear_footprint(width, height, u, v), out);
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
