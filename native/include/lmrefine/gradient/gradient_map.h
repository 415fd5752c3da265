// The gradient map of the thesis (docs/method.md §3): for every lightmap texel,
// how fast the light changes, per direction and sense, from the magnitude of
// a wavelet detail evaluated at every texel (undecimated / stationary).
//
// Channels of the (H, W, 4) result:
//   0 r  light changing along y, filter scanning down the columns (forward)
//   1 g  light changing along x, filter scanning along the rows (forward)
//   2 b  along y, scanning up the columns (backward)
//   3 a  along x, scanning right to left (backward)
// With the detail filter g[0..L) of the wavelet (detail_filter(), unit norm)
// and c = L/2, the forward value at texel i of a line is
// |sum_k g[k] x[i - c + k]| and the backward one |sum_k g[k] x[i + c - k]|:
// the same filter run on the reversed line. For D4 this is the thesis'
// modified predict: after the predict step the D4 detail is final up to the
// normalization, so |detail| is |predict residual| * (sqrt3+1)/sqrt2. Other
// wavelets use the magnitude of their full high-pass detail the same way.
//
// Coverage: each row (for g, a) and column (for r, b) splits into runs of
// covered texels; a run is extended past both of its ends point-symmetrically
// (x[-k] = 2 x[0] - x[k], repeated for short runs), which continues a linear
// light ramp exactly, so a smooth ramp gives no false edge at a chart border
// or at the image border (which is a border, never a wrap). Uncovered texels
// are never read for a covered texel and come out 0 in every channel.
#pragma once

#include <cstdint>

#include "lmrefine/gradient/wavelet.h"

namespace lmrefine {

class Progress;

// Rec.709 luminance weights, used for RGB(A) input (alpha is ignored).
constexpr float kLumaR = 0.2126f, kLumaG = 0.7152f, kLumaB = 0.0722f;

// image: row-major (height, width, channels) float32, channels 1, 3 or 4.
// mask: (height, width) bytes, nonzero = covered, or nullptr = all covered.
// out: (height, width, 4) float32. Throws InvalidArgument for non-finite
// covered texels (naming their count and the first one) and for a mask that
// covers nothing. Parallel over rows and columns; polls `progress`.
void gradient_map(const float* image, int64_t height, int64_t width, int channels, const uint8_t* mask,
                  Wavelet wavelet, float* out, Progress* progress = nullptr);

}  // namespace lmrefine
