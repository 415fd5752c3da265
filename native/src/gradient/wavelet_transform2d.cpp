// One-level separable 2-D transform: rows along x, then columns along y.
// The column pass runs on whole rows of the sub-bands (strips of lanes), so
// it streams through memory and vectorizes instead of striding down columns.
#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"
#include "lmrefine/gradient/wavelet.h"
#include "wavelet_lifting.h"

namespace lmrefine {
namespace {

// Columns handled together by one task of the column pass. A strip of both
// bands is copied into a contiguous buffer and every lifting step runs on it
// there: read in place, rows a power of two apart would all fall into the
// same few cache sets, and the strip would not stay in cache between steps.
constexpr int64_t kStripLanes = 32;

void require_even_size(int64_t height, int64_t width) {
    LMREFINE_REQUIRE(height >= 2 && width >= 2 && height % 2 == 0 && width % 2 == 0,
                     "a one-level 2-D wavelet transform needs an even height and width (>= 2), got " +
                         std::to_string(height) + "x" + std::to_string(width) +
                         ": each level halves both sizes; crop or pad the image by one texel");
}

// The column pass on a band pair (s rows, d rows), `lanes` wide, in strips.
struct ColumnPair {
    float* s;
    float* d;
    int64_t stride;
    int64_t lanes;
};

void column_pass(const LiftingScheme& scheme, BoundaryMode mode, const std::vector<ColumnPair>& pairs,
                 int64_t count, bool inverse, Progress* progress) {
    std::vector<std::pair<int, int64_t>> strips;  // (pair, first lane)
    for (int p = 0; p < int(pairs.size()); ++p) {
        for (int64_t lane = 0; lane < pairs[p].lanes; lane += kStripLanes) strips.emplace_back(p, lane);
    }
    // A few chunks per thread: enough to balance the load, few enough that
    // the strip buffers (a fresh, page-faulting allocation each) are cheap.
    const int64_t grain = std::max<int64_t>(1, int64_t(strips.size()) / (4 * thread_count()));
    parallel_for(
        int64_t(strips.size()), grain,
        [&](int64_t begin, int64_t end) {
            std::vector<float> scratch, s(size_t(count * kStripLanes)), d(s.size());
            for (int64_t t = begin; t < end; ++t) {
                const ColumnPair& pair = pairs[strips[t].first];
                const int64_t lane = strips[t].second;
                const int64_t lanes = std::min(kStripLanes, pair.lanes - lane);
                const size_t bytes = sizeof(float) * size_t(lanes);
                for (int64_t n = 0; n < count; ++n) {
                    std::memcpy(&s[n * lanes], pair.s + n * pair.stride + lane, bytes);
                    std::memcpy(&d[n * lanes], pair.d + n * pair.stride + lane, bytes);
                }
                lifting::lift(scheme, mode, s.data(), d.data(), count, lanes, lanes, inverse, scratch);
                for (int64_t n = 0; n < count; ++n) {
                    std::memcpy(pair.s + n * pair.stride + lane, &s[n * lanes], bytes);
                    std::memcpy(pair.d + n * pair.stride + lane, &d[n * lanes], bytes);
                }
            }
        },
        progress);
}

}  // namespace

void dwt2(const float* image, int64_t height, int64_t width, Wavelet wavelet, BoundaryMode mode, float* ll,
          float* lh, float* hl, float* hh, Progress* progress) {
    require_even_size(height, width);
    const LiftingScheme& scheme = lifting_scheme(wavelet);
    const int64_t half_w = width / 2, half_h = height / 2;
    if (progress) progress->begin("wavelet transform", uint64_t(height + 2 * ((half_w + kStripLanes - 1) / kStripLanes)));

    // Rows: even image rows give the low-pass-along-y rows (LL | HL), odd
    // rows the high-pass ones (LH | HH), so the column pass finds its s and
    // d elements as rows of those bands.
    parallel_for(
        height, 16,
        [&](int64_t begin, int64_t end) {
            std::vector<float> scratch;
            for (int64_t i = begin; i < end; ++i) {
                const bool odd = i % 2;
                float* s = (odd ? lh : ll) + (i / 2) * half_w;
                float* d = (odd ? hh : hl) + (i / 2) * half_w;
                const float* row = image + i * width;
                for (int64_t n = 0; n < half_w; ++n) {
                    s[n] = row[2 * n];
                    d[n] = row[2 * n + 1];
                }
                lifting::lift(scheme, mode, s, d, half_w, 1, 1, false, scratch);
            }
        },
        progress);
    if (progress) progress->check();

    column_pass(scheme, mode, {{ll, lh, half_w, half_w}, {hl, hh, half_w, half_w}}, half_h, false, progress);
    if (progress) {
        progress->check();
        progress->finish();
    }
}

void idwt2(const float* ll, const float* lh, const float* hl, const float* hh, int64_t half_height,
           int64_t half_width, Wavelet wavelet, BoundaryMode mode, float* image, Progress* progress) {
    LMREFINE_REQUIRE(half_height >= 1 && half_width >= 1, "the sub-bands are empty");
    const LiftingScheme& scheme = lifting_scheme(wavelet);
    const int64_t width = 2 * half_width, height = 2 * half_height;
    if (progress) progress->begin("inverse wavelet transform", uint64_t(2 * height + (width + kStripLanes - 1) / kStripLanes));

    // Lay the bands out as the forward row pass left them: image row 2n holds
    // (LL | HL) row n, row 2n+1 holds (LH | HH) row n. The inputs stay untouched.
    parallel_for(
        height, 32,
        [&](int64_t begin, int64_t end) {
            for (int64_t i = begin; i < end; ++i) {
                const int64_t n = i / 2;
                float* row = image + i * width;
                std::memcpy(row, (i % 2 ? lh : ll) + n * half_width, sizeof(float) * half_width);
                std::memcpy(row + half_width, (i % 2 ? hh : hl) + n * half_width, sizeof(float) * half_width);
            }
        },
        progress);
    if (progress) progress->check();

    // Columns: one pass over the full width, (LL|HL) rows as s, (LH|HH) as d.
    column_pass(scheme, mode, {{image, image + width, 2 * width, width}}, half_height, true, progress);
    if (progress) progress->check();

    parallel_for(
        height, 16,
        [&](int64_t begin, int64_t end) {
            std::vector<float> scratch, s(half_width), d(half_width);
            for (int64_t i = begin; i < end; ++i) {
                float* row = image + i * width;
                std::memcpy(s.data(), row, sizeof(float) * half_width);
                std::memcpy(d.data(), row + half_width, sizeof(float) * half_width);
                lifting::lift(scheme, mode, s.data(), d.data(), half_width, 1, 1, true, scratch);
                for (int64_t n = 0; n < half_width; ++n) {
                    row[2 * n] = s[n];
                    row[2 * n + 1] = d[n];
                }
            }
        },
        progress);
    if (progress) {
        progress->check();
        progress->finish();
    }
}

}  // namespace lmrefine
