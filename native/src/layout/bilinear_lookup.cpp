#include "lmrefine/layout/bilinear_lookup.h"

#include "lmrefine/core/parallel.h"

namespace lmrefine {
namespace {

template <class T>
void lookup(const T* image, int64_t width, int64_t height, int64_t channels, const double* uvs, int64_t count,
            double* out) {
    parallel_for(count, 1 << 14, [&](int64_t begin, int64_t end) {
        for (int64_t p = begin; p < end; ++p) {
            bilinear_sample(image, width, height, channels, uvs[2 * p], uvs[2 * p + 1], out + p * channels);
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
