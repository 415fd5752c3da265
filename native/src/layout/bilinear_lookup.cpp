#include "lmrefine/layout/bilinear_lookup.h"

#include <algorithm>
#include <cmath>

#include "lmrefine/core/parallel.h"

namespace lmrefine {
namespace {

template <class T>
void lookup(const T* image, int64_t width, int64_t height, int64_t channels, const double* uvs, int64_t count,
            double* out) {
    const double w = double(width), h = double(height);
    parallel_for(count, 1 << 14, [&](int64_t begin, int64_t end) {
        for (int64_t p = begin; p < end; ++p) {
            // Texel coordinates of the point, centres on integers, clamped to the border.
            const double x = std::clamp(uvs[2 * p] * w - 0.5, 0.0, w - 1.0);
            const double y = std::clamp((1.0 - uvs[2 * p + 1]) * h - 0.5, 0.0, h - 1.0);
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
                out[p * channels + k] = top * (1.0 - fy) + bottom * fy;
            }
        }
    });
}

}  // namespace

void bilinear_lookup(const float* image, int64_t width, int64_t height, int64_t channels, const double* uvs,
                     int64_t count, double* out) {
    lookup(image, width, height, channels, uvs, count, out);
}

void bilinear_lookup(const double* image, int64_t width, int64_t height, int64_t channels, const double* uvs,
                     int64_t count, double* out) {
    lookup(image, width, height, channels, uvs, count, out);
}

}  // namespace lmrefine
