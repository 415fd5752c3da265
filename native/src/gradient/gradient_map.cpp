#include "lmrefine/gradient/gradient_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"

namespace lmrefine {
namespace {

struct LineFilter {
    std::vector<float> taps;  // the detail filter, float32
    int centre = 0;           // c: the forward value at i reads x[i - c .. i - c + L)
    int pad = 0;              // samples of extension needed past each end of a run
};

// The longest detail filter (D20).
constexpr int kMaxTaps = 20;

LineFilter make_line_filter(Wavelet wavelet) {
    const DetailFilter detail = detail_filter(wavelet);
    LMREFINE_REQUIRE(int(detail.taps.size()) <= kMaxTaps, "detail filter longer than kMaxTaps");
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

// The stencil sums of `count` texels, forward and backward:
//   fwd[t] = |sum_k g[k] (forward[k][t] - centre[t])|, likewise backward.
// The taps sum to zero, so sums over differences equal the detail, and the
// differences make a flat run exactly 0 and keep HDR offsets out. A length
// known at compile time unrolls the taps so the loop over texels vectorizes
// with the sums in registers; kLength = 0 takes the length at run time.
// Both directions go through here, so they agree bit for bit.
template <int kLength>
void stencil_sums(const float* taps, int length, const float* const* forward, const float* const* backward,
                  const float* centre, int64_t count, float* __restrict fwd, float* __restrict bwd) {
    const int taps_count = kLength ? kLength : length;
    const float* sources[2][kMaxTaps];
    for (int k = 0; k < taps_count; ++k) {
        sources[0][k] = forward[k];
        sources[1][k] = backward[k];
    }
    for (int64_t t = 0; t < count; ++t) {
        const float x = centre[t];
        float sf = 0.0f, sb = 0.0f;
        for (int k = 0; k < taps_count; ++k) {
            sf += taps[k] * (sources[0][k][t] - x);
            sb += taps[k] * (sources[1][k][t] - x);
        }
        fwd[t] = std::abs(sf);
        bwd[t] = std::abs(sb);
    }
}

void stencil(const LineFilter& f, const float* const* forward, const float* const* backward, const float* centre,
             int64_t count, float* fwd, float* bwd) {
    const float* g = f.taps.data();
    const int n = int(f.taps.size());
    switch (n) {
        case 2: return stencil_sums<2>(g, n, forward, backward, centre, count, fwd, bwd);
        case 3: return stencil_sums<3>(g, n, forward, backward, centre, count, fwd, bwd);
        case 4: return stencil_sums<4>(g, n, forward, backward, centre, count, fwd, bwd);
        case 7: return stencil_sums<7>(g, n, forward, backward, centre, count, fwd, bwd);
        case 12: return stencil_sums<12>(g, n, forward, backward, centre, count, fwd, bwd);
        case 20: return stencil_sums<20>(g, n, forward, backward, centre, count, fwd, bwd);
        default: return stencil_sums<0>(g, n, forward, backward, centre, count, fwd, bwd);
    }
}

// Filters one row of `n` texels along x: writes |forward| and |backward|
// detail to fwd[0..n), bwd[0..n), 0 where the row is not covered.
// `extended` is scratch space.
void filter_line(const LineFilter& f, const float* x, const uint8_t* covered, int64_t n, float* fwd, float* bwd,
                 std::vector<float>& extended) {
    const int length = int(f.taps.size()), c = f.centre, pad = f.pad;
    int64_t i = 0;
    while (i < n) {
        if (covered && !covered[i]) {
            fwd[i] = bwd[i] = 0.0f;
            ++i;
            continue;
        }
        int64_t end = i + 1;
        while (end < n && (!covered || covered[end])) ++end;
        const int64_t run = end - i;
        const float* r = x + i;

        // The run with `pad` extended samples on each side.
        extended.resize(run + 2 * pad);
        float* e = extended.data() + pad;
        for (int64_t j = -pad; j < 0; ++j) e[j] = float(antireflect(r, run, j));
        std::copy(r, r + run, e);
        for (int64_t j = run; j < run + pad; ++j) e[j] = float(antireflect(r, run, j));

        const float* forward[kMaxTaps];
        const float* backward[kMaxTaps];
        for (int k = 0; k < length; ++k) {
            forward[k] = e - c + k;
            backward[k] = e + c - k;
        }
        stencil(f, forward, backward, e, run, fwd + i, bwd + i);
        i = end;
    }
}

// The value of one texel whose vertical stencil leaves its column's run of
// covered texels (or the image): the run through it, clipped to the rows the
// stencil can reach (a reflection about a real end never lands past the
// clip), extended like filter_line does, with the same float arithmetic.
void filter_column_texel(const LineFilter& f, const float* lum, const uint8_t* mask, int64_t height, int64_t width,
                         int64_t i, int64_t j, float* fwd, float* bwd, std::vector<float>& segment) {
    auto covered = [&](int64_t row) { return !mask || mask[row * width + j]; };
    if (!covered(i)) {
        *fwd = *bwd = 0.0f;
        return;
    }
    const int length = int(f.taps.size()), c = f.centre, pad = f.pad;
    int64_t lo = i, hi = i;
    while (lo > 0 && lo > i - pad && covered(lo - 1)) --lo;
    while (hi < height - 1 && hi < i + pad && covered(hi + 1)) ++hi;
    segment.resize(hi - lo + 1);
    for (int64_t r = lo; r <= hi; ++r) segment[r - lo] = lum[r * width + j];
    const int64_t n = hi - lo + 1, t = i - lo;
    float values[2][kMaxTaps];
    const float* forward[kMaxTaps];
    const float* backward[kMaxTaps];
    for (int k = 0; k < length; ++k) {
        values[0][k] = float(antireflect(segment.data(), n, t - c + k));
        values[1][k] = float(antireflect(segment.data(), n, t + c - k));
        forward[k] = &values[0][k];
        backward[k] = &values[1][k];
    }
    stencil(f, forward, backward, &segment[t], 1, fwd, bwd);
}

struct RowScratch {
    std::vector<float> along_x_fwd, along_x_bwd, along_y_fwd, along_y_bwd, extended, segment;
    std::vector<uint8_t> inside;
};

// Along y for one texel row: rows i - c .. i + c are read row by row, so the
// loop runs along memory over every column at once; texels whose stencil
// leaves their column's run are then redone by filter_column_texel. The
// arithmetic is filter_line's, so both directions agree bit for bit.
void filter_columns_at_row(const LineFilter& f, const float* lum, const uint8_t* mask, int64_t height,
                           int64_t width, int64_t i, float* fwd, float* bwd, RowScratch& s) {
    const int length = int(f.taps.size()), c = f.centre, pad = f.pad;
    // Rows past the image are clamped only to stay in memory: the texels
    // that read them are redone below.
    const float* forward[kMaxTaps];
    const float* backward[kMaxTaps];
    for (int k = 0; k < length; ++k) {
        forward[k] = lum + std::clamp<int64_t>(i - c + k, 0, height - 1) * width;
        backward[k] = lum + std::clamp<int64_t>(i + c - k, 0, height - 1) * width;
    }
    stencil(f, forward, backward, lum + i * width, width, fwd, bwd);

    const bool rows_exist = i - pad >= 0 && i + pad < height;
    if (rows_exist && !mask) return;  // every stencil is inside the image and covered
    s.inside.assign(width, rows_exist ? 1 : 0);
    uint8_t* inside = s.inside.data();
    if (rows_exist) {
        for (int o = -pad; o <= pad; ++o) {
            const uint8_t* m = mask + (i + o) * width;
            for (int64_t j = 0; j < width; ++j) inside[j] &= m[j] ? 1 : 0;
        }
    }
    for (int64_t j = 0; j < width; ++j) {
        if (!inside[j]) filter_column_texel(f, lum, mask, height, width, i, j, fwd + j, bwd + j, s.segment);
    }
}

// Checks the covered texels (all finite, at least one) and, for RGB(A),
// writes their luminance (uncovered ones are set to 0 and never read).
struct CoverageScan {
    int64_t covered = 0, bad = 0, first_bad = std::numeric_limits<int64_t>::max();
};

CoverageScan scan_and_luminance(const float* image, int64_t height, int64_t width, int channels,
                                const uint8_t* mask, float* lum, Progress* progress) {
    CoverageScan total;
    std::mutex merge;
    parallel_for(
        height, 16,
        [&](int64_t begin, int64_t end) {
            CoverageScan part;
            for (int64_t i = begin; i < end; ++i) {
                for (int64_t j = 0; j < width; ++j) {
                    const int64_t t = i * width + j;
                    if (mask && !mask[t]) {
                        if (lum) lum[t] = 0.0f;
                        continue;
                    }
                    const float* p = image + t * channels;
                    // A finite RGB can overflow to Inf in the weighted sum;
                    // that is reported as non-finite too.
                    const float y = channels == 1 ? p[0] : kLumaR * p[0] + kLumaG * p[1] + kLumaB * p[2];
                    ++part.covered;
                    if (!std::isfinite(y)) {
                        ++part.bad;
                        part.first_bad = std::min(part.first_bad, t);
                    }
                    if (lum) lum[t] = y;
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

}  // namespace

void gradient_map(const float* image, int64_t height, int64_t width, int channels, const uint8_t* mask,
                  Wavelet wavelet, float* out, Progress* progress) {
    LMREFINE_REQUIRE(height >= 1 && width >= 1, "the image is empty");
    LMREFINE_REQUIRE(channels == 1 || channels == 3 || channels == 4,
                     "the image must have 1, 3 or 4 channels (luminance, RGB or RGBA), got " +
                         std::to_string(channels));
    const LineFilter filter = make_line_filter(wavelet);
    // Units: scanned rows, then filtered rows.
    if (progress) progress->begin("gradient map", uint64_t(2 * height));

    // A single channel is read in place (only covered texels are ever used);
    // RGB(A) is reduced to luminance once.
    LargeVector<float> luminance;
    if (channels != 1) luminance.resize(size_t(height * width));
    const CoverageScan scan =
        scan_and_luminance(image, height, width, channels, mask, channels == 1 ? nullptr : luminance.data(), progress);
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
    const float* lum = channels == 1 ? image : luminance.data();

    // Every output row is written once: g, a along the row, r, b down the columns.
    parallel_for(
        height, 4,
        [&](int64_t begin, int64_t end) {
            RowScratch s;
            for (auto* v : {&s.along_x_fwd, &s.along_x_bwd, &s.along_y_fwd, &s.along_y_bwd}) v->resize(width);
            for (int64_t i = begin; i < end; ++i) {
                filter_line(filter, lum + i * width, mask ? mask + i * width : nullptr, width, s.along_x_fwd.data(),
                            s.along_x_bwd.data(), s.extended);
                filter_columns_at_row(filter, lum, mask, height, width, i, s.along_y_fwd.data(),
                                      s.along_y_bwd.data(), s);
                float* texel = out + i * width * 4;
                for (int64_t j = 0; j < width; ++j, texel += 4) {
                    texel[0] = s.along_y_fwd[j];
                    texel[1] = s.along_x_fwd[j];
                    texel[2] = s.along_y_bwd[j];
                    texel[3] = s.along_x_bwd[j];
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
