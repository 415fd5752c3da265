// The lifting kernel shared by the 1-D and 2-D transforms (private).
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/gradient/wavelet.h"

namespace lmrefine::lifting {

// Maps a possibly out-of-range index of a sub-band of `count` elements into
// [0, count). `odd` says whether the band holds the odd samples (d) or the
// even ones (s): symmetric mode mirrors the signal index 2n + odd.
int64_t fold_index(int64_t n, int64_t count, bool odd, BoundaryMode mode);

// Runs `scheme` forward (or, if `inverse`, backward) on the two halves of a
// signal: s and d each hold `count` elements of `lanes` floats, element n
// at s + n * stride. lanes == 1 (stride 1) is a 1-D signal; lanes > 1 runs
// many columns at once, one row of each band per element (the column pass
// of the 2-D transform, done row-wise so it vectorizes). `scratch` is
// resized as needed and may be reused between calls.
void lift(const LiftingScheme& scheme, BoundaryMode mode, float* s, float* d, int64_t count,
          int64_t stride, int64_t lanes, bool inverse, std::vector<float>& scratch);

}  // namespace lmrefine::lifting
