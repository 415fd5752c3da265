#include "lmrefine/gradient_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "lmrefine/error.h"
#include "lmrefine/parallel.h"
#include "lmrefine/progress.h"

namespace lmrefine {
namespace {

// Columns handled per task of the vertical pass (their results are written
// back texel-row by texel-row, so the writes stay local).
constexpr int64_t kColumnBlock = 16;

struct LineFilter {
    std::vector<float> taps;  // the detail filter, float32
    int centre = 0;           // c: the forward value at i reads x[i - c .. i - c + L)
    int pad = 0;              // samples of extension needed past each end of a run
};

LineFilter make_line_filter(Wavelet wavelet) {
    const DetailFilter detail = detail_filter(wavelet);
    LineFilter f;
    f.taps.assign(detail.taps.begin(), detail.taps.end());
    const int length = int(f.taps.size());
    f.centre = length / 2;
    f.pad = std::max(f.centre, length - 1 - f.centre);
    return f;
}

// x[j] of a run x[0..n) extended point-symmetrically about its end samples,
// repeatedly, so any j is defined; in double so the reflection is exact for
// flat runs and as exact as float data allows for ramps.
double antireflect(const float* x, int64_t n, int64_t j) {
    if (n == 1) return x[0];
    double offset = 0.0, sign = 1.0;  // value = offset + sign * x[j]
    while (j < 0 || j >= n) {
        if (j < 0) {
            offset += sign * 2.0 * x[0];
            sign = -sign;
            j = -j;
        } else {
            offset += sign * 2.0 * x[n - 1];
            sign = -sign;
            j = 2 * (n - 1) - j;
        }
    }
    return offset + sign * x[j];
}

struct LineScratch {
    std::vector<float> extended, forward, backward;
};

// Filters one line (a row, or a column stored as a row) of `n` texels:
// writes |forward| and |backward| detail to fwd[i * step], bwd[i * step],
// 0 where the line is not covered.
void filter_line(const LineFilter& f, const float* x, const uint8_t* covered, int64_t n, float* fwd, float* bwd,
                 int64_t step, LineScratch& scratch) {
    const int length = int(f.taps.size()), c = f.centre, pad = f.pad;
    int64_t i = 0;
    while (i < n) {
        if (covered && !covered[i]) {
            fwd[i * step] = 0.0f;
            bwd[i * step] = 0.0f;
            ++i;
            continue;
        }
        int64_t end = i + 1;
        while (end < n && (!covered || covered[end])) ++end;
        const int64_t run = end - i;
        const float* r = x + i;

        // The run with `pad` extended samples on each side.
        scratch.extended.resize(run + 2 * pad);
        float* e = scratch.extended.data() + pad;
        for (int64_t j = -pad; j < 0; ++j) e[j] = float(antireflect(r, run, j));
        std::copy(r, r + run, e);
        for (int64_t j = run; j < run + pad; ++j) e[j] = float(antireflect(r, run, j));

        // The taps sum to zero, so sum g[k] (x[k] - x[i]) equals the detail;
        // differences make a flat run exactly 0 and keep HDR offsets out.
        scratch.forward.assign(run, 0.0f);
        scratch.backward.assign(run, 0.0f);
        float* af = scratch.forward.data();
        float* ab = scratch.backward.data();
        for (int k = 0; k < length; ++k) {
            const float g = f.taps[k];
            const float* ef = e - c + k;
            const float* eb = e + c - k;
            for (int64_t t = 0; t < run; ++t) {
                af[t] += g * (ef[t] - e[t]);
                ab[t] += g * (eb[t] - e[t]);
            }
        }
        for (int64_t t = 0; t < run; ++t) {
            fwd[(i + t) * step] = std::abs(af[t]);
            bwd[(i + t) * step] = std::abs(ab[t]);
        }
        i = end;
    }
}

// Luminance of every covered texel (uncovered ones are set to 0 and never
// read); counts non-finite covered texels and covered ones.
struct LuminanceScan {
    int64_t covered = 0, bad = 0, first_bad = std::numeric_limits<int64_t>::max();
};

LuminanceScan luminance(const float* image, int64_t height, int64_t width, int channels, const uint8_t* mask,
                        float* lum, Progress* progress) {
    LuminanceScan total;
    std::mutex merge;
    parallel_for(
        height, 16,
        [&](int64_t begin, int64_t end) {
            LuminanceScan part;
            for (int64_t i = begin; i < end; ++i) {
                for (int64_t j = 0; j < width; ++j) {
                    const int64_t t = i * width + j;
                    if (mask && !mask[t]) {
                        lum[t] = 0.0f;
                        continue;
                    }
                    const float* p = image + t * channels;
                    const float y = channels == 1 ? p[0] : kLumaR * p[0] + kLumaG * p[1] + kLumaB * p[2];
                    ++part.covered;
                    // A finite RGB can overflow to Inf in the weighted sum;
                    // that is reported as non-finite too.
                    if (!std::isfinite(y)) {
                        ++part.bad;
                        part.first_bad = std::min(part.first_bad, t);
                    }
                    lum[t] = y;
                }
            }
            std::lock_guard<std::mutex> lock(merge);
            total.covered += part.covered;
            total.bad += part.bad;
            total.first_bad = std::min(total.first_bad, part.first_bad);
        },
        progress);
    return total;
}

template <class T>
void transpose(const T* in, int64_t height, int64_t width, T* out) {
    constexpr int64_t kTile = 32;
    const int64_t tiles_i = (height + kTile - 1) / kTile;
    parallel_for(tiles_i, 1, [&](int64_t begin, int64_t end) {
        for (int64_t ti = begin; ti < end; ++ti) {
            const int64_t i0 = ti * kTile, i1 = std::min(height, i0 + kTile);
            for (int64_t j0 = 0; j0 < width; j0 += kTile) {
                const int64_t j1 = std::min(width, j0 + kTile);
                for (int64_t i = i0; i < i1; ++i) {
                    for (int64_t j = j0; j < j1; ++j) out[j * height + i] = in[i * width + j];
                }
            }
        }
    });
}

}  // namespace

void gradient_map(const float* image, int64_t height, int64_t width, int channels, const uint8_t* mask,
                  Wavelet wavelet, float* out, Progress* progress) {
    LMREFINE_REQUIRE(height >= 1 && width >= 1, "the image is empty");
    LMREFINE_REQUIRE(channels == 1 || channels == 3 || channels == 4,
                     "the image must have 1, 3 or 4 channels (luminance, RGB or RGBA), got " +
                         std::to_string(channels));
    const LineFilter filter = make_line_filter(wavelet);
    const int64_t blocks = (width + kColumnBlock - 1) / kColumnBlock;
    // Units: luminance rows, filtered rows, blocks of filtered columns.
    if (progress) progress->begin("gradient map", uint64_t(2 * height + blocks));

    std::vector<float> lum(size_t(height * width));
    const LuminanceScan scan = luminance(image, height, width, channels, mask, lum.data(), progress);
    if (progress) progress->check();
    if (scan.covered == 0) {
        LMREFINE_THROW(InvalidArgument,
                       "the mask covers no texel, so there is nothing to analyse; compute it with "
                       "lmrefine.coverage_mask(uvs, triangles, resolution) for this lightmap's UV layout");
    }
    if (scan.bad > 0) {
        LMREFINE_THROW(InvalidArgument,
                       "the image has " + std::to_string(scan.bad) +
                           " non-finite (NaN or Inf) texel(s) inside the covered area, the first at row " +
                           std::to_string(scan.first_bad / width) + ", column " +
                           std::to_string(scan.first_bad % width) +
                           "; fix the bake, or replace them (numpy.nan_to_num) or leave them out of the mask");
    }

    // Along x (g, a): rows as they are.
    parallel_for(
        height, 8,
        [&](int64_t begin, int64_t end) {
            LineScratch scratch;
            for (int64_t i = begin; i < end; ++i) {
                float* row = out + i * width * 4;
                filter_line(filter, lum.data() + i * width, mask ? mask + i * width : nullptr, width, row + 1,
                            row + 3, 4, scratch);
            }
        },
        progress);
    if (progress) progress->check();

    // Along y (r, b): columns become rows of the transposed image, so the
    // same run-aware line filter reads contiguous memory.
    std::vector<float> lum_t(lum.size());
    transpose(lum.data(), height, width, lum_t.data());
    lum = {};
    std::vector<uint8_t> mask_t;
    if (mask) {
        mask_t.resize(size_t(height * width));
        transpose(mask, height, width, mask_t.data());
    }
    parallel_for(
        blocks, 1,
        [&](int64_t begin, int64_t end) {
            LineScratch scratch;
            std::vector<float> fwd(size_t(kColumnBlock * height)), bwd(size_t(kColumnBlock * height));
            for (int64_t block = begin; block < end; ++block) {
                const int64_t j0 = block * kColumnBlock, j1 = std::min(width, j0 + kColumnBlock);
                for (int64_t j = j0; j < j1; ++j) {
                    filter_line(filter, lum_t.data() + j * height, mask ? mask_t.data() + j * height : nullptr,
                                height, fwd.data() + (j - j0) * height, bwd.data() + (j - j0) * height, 1,
                                scratch);
                }
                for (int64_t i = 0; i < height; ++i) {
                    float* texel = out + (i * width + j0) * 4;
                    for (int64_t j = j0; j < j1; ++j, texel += 4) {
                        texel[0] = fwd[(j - j0) * height + i];
                        texel[2] = bwd[(j - j0) * height + i];
                    }
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
