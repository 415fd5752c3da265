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

// Along y for one texel row: rows i - pad .. i + pad are read row by row,
// so the loop runs along memory over every column at once. Texels whose
// stencil leaves their column's run of covered texels (or the image) are
// redone one by one with the run's extension; the arithmetic is the same as
// filter_line's, so the two directions agree bit for bit.
struct RowScratch {
    LineScratch line;
    std::vector<float> forward, backward, segment;
    std::vector<uint8_t> inside;
};

void filter_columns_at_row(const LineFilter& f, const float* lum, const uint8_t* mask, int64_t height,
                           int64_t width, int64_t i, float* out_row, RowScratch& s) {
    const int length = int(f.taps.size()), c = f.centre, pad = f.pad;
    const bool rows_exist = i - pad >= 0 && i + pad < height;
    s.inside.assign(width, rows_exist ? 1 : 0);
    if (rows_exist && mask) {
        for (int o = -pad; o <= pad; ++o) {
            const uint8_t* m = mask + (i + o) * width;
            for (int64_t j = 0; j < width; ++j) s.inside[j] &= m[j] ? 1 : 0;
        }
    }
    s.forward.assign(width, 0.0f);
    s.backward.assign(width, 0.0f);
    float* af = s.forward.data();
    float* ab = s.backward.data();
    const float* centre = lum + i * width;
    for (int k = 0; k < length; ++k) {
        const float g = f.taps[k];
        const float* xf = lum + std::clamp<int64_t>(i - c + k, 0, height - 1) * width;
        const float* xb = lum + std::clamp<int64_t>(i + c - k, 0, height - 1) * width;
        for (int64_t j = 0; j < width; ++j) {
            af[j] += g * (xf[j] - centre[j]);
            ab[j] += g * (xb[j] - centre[j]);
        }
    }
    for (int64_t j = 0; j < width; ++j) {
        out_row[4 * j] = std::abs(af[j]);
        out_row[4 * j + 2] = std::abs(ab[j]);
    }
    for (int64_t j = 0; j < width; ++j) {
        if (s.inside[j]) continue;
        auto covered = [&](int64_t row) { return !mask || mask[row * width + j]; };
        if (!covered(i)) {
            out_row[4 * j] = out_row[4 * j + 2] = 0.0f;
            continue;
        }
        // The run through texel i, clipped to the rows the stencil can reach
        // (a reflection about a real end never lands past the clip).
        int64_t lo = i, hi = i;
        while (lo > 0 && lo > i - pad && covered(lo - 1)) --lo;
        while (hi < height - 1 && hi < i + pad && covered(hi + 1)) ++hi;
        s.segment.resize(hi - lo + 1);
        for (int64_t r = lo; r <= hi; ++r) s.segment[r - lo] = lum[r * width + j];
        const int64_t n = hi - lo + 1, t = i - lo;
        const float xi = s.segment[t];
        float sf = 0.0f, sb = 0.0f;
        for (int k = 0; k < length; ++k) {
            const float g = f.taps[k];
            sf += g * (float(antireflect(s.segment.data(), n, t - c + k)) - xi);
            sb += g * (float(antireflect(s.segment.data(), n, t + c - k)) - xi);
        }
        out_row[4 * j] = std::abs(sf);
        out_row[4 * j + 2] = std::abs(sb);
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
    std::vector<float> luminance;
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
            RowScratch scratch;
            for (int64_t i = begin; i < end; ++i) {
                float* row = out + i * width * 4;
                filter_line(filter, lum + i * width, mask ? mask + i * width : nullptr, width, row + 1, row + 3, 4,
                            scratch.line);
                filter_columns_at_row(filter, lum, mask, height, width, i, row, scratch);
            }
        },
        progress);
    if (progress) {
        progress->check();
        progress->finish();
    }
}

}  // namespace lmrefine
