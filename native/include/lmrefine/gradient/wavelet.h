// One-level discrete wavelet transforms by lifting (Daubechies & Sweldens
// 1998): Haar, Daubechies D4 (exactly the steps of docs/method.md §3), D12, D20,
// and the Cohen-Daubechies-Feauveau 5/3 and 9/7 biorthogonal wavelets.
//
// 1-D: a signal x of even length N is split into even samples s[n] = x[2n]
// and odd samples d[n] = x[2n+1]; lifting steps then add filtered copies of
// one half to the other, and a last scaling gives the approximation s and
// the detail d (N/2 each). Every step is inverted by subtracting the same
// sum, so the inverse is exact up to float rounding, whatever the boundary.
//
// 2-D (one level, separable packet): rows are transformed along x (axis 1),
// then columns along y (axis 0). Sub-band names give the filter along x
// first, then along y:
//   LL  low x,  low y   (the approximation)
//   LH  low x,  high y  light changing along y: horizontal edges (PyWavelets cH)
//   HL  high x, low y   light changing along x: vertical edges   (PyWavelets cV)
//   HH  high x, high y  diagonal detail                          (PyWavelets cD)
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace lmrefine {

class Progress;

enum class Wavelet { Haar, D4, D12, D20, Cdf53, Cdf97 };

// How a lifting step reads past the end of a sub-band.
//  Periodic:  the signal wraps around (x[-1] = x[N-1]); the D4 of docs/method.md §3.
//  Symmetric: the signal is mirrored about its end samples (x[-k] = x[k],
//             x[N-1+k] = x[N-1-k]), applied per step to the sub-band it
//             reads; for the symmetric CDF wavelets this is the classic
//             symmetric-extension transform (as in JPEG 2000).
enum class BoundaryMode { Periodic, Symmetric };

// Parse a name ("haar", "d4", "d12", "d20", "cdf53", "cdf97" / "periodic",
// "symmetric"); an unknown one throws InvalidArgument listing the valid names.
Wavelet parse_wavelet(const std::string& name);
BoundaryMode parse_boundary_mode(const std::string& name);
const char* wavelet_name(Wavelet wavelet);
const char* valid_wavelet_names();

// One lifting step: Predict updates the detail from the approximation,
// d[n] += sum_j coeffs[j] * s[n + offset + j]; Update the other way round,
// s[n] += sum_j coeffs[j] * d[n + offset + j].
struct LiftingStep {
    enum Kind { Update, Predict };
    Kind kind;
    int offset;
    int count;
    const double* coeffs;
};

// The whole factorization: steps in forward order, then s *= scale_s and
// d *= scale_d.
struct LiftingScheme {
    const LiftingStep* steps;
    int step_count;
    double scale_s;
    double scale_d;
};

const LiftingScheme& lifting_scheme(Wavelet wavelet);

// The detail (high-pass) output as a filter on the signal, derived from the
// lifting steps in double precision: d[n] = sum_k taps[k] * x[2n + first + k]
// (periodic, away from the boundary). Its taps sum to zero.
struct DetailFilter {
    std::vector<double> taps;
    int first = 0;
};
DetailFilter detail_filter(Wavelet wavelet);

// 1-D transform of `length` samples (even, >= 2) into approx[length/2] and
// detail[length/2]; the inverse takes them back. Buffers must not overlap.
void dwt(const float* signal, int64_t length, Wavelet wavelet, BoundaryMode mode,
         float* approx, float* detail);
void idwt(const float* approx, const float* detail, int64_t half, Wavelet wavelet,
          BoundaryMode mode, float* signal);

// 2-D transform of a row-major (height, width) image, both even and >= 2,
// into four (height/2, width/2) sub-bands (see the naming above). Parallel
// over rows; `progress` (optional) is advanced and polled for cancellation.
void dwt2(const float* image, int64_t height, int64_t width, Wavelet wavelet, BoundaryMode mode,
          float* ll, float* lh, float* hl, float* hh, Progress* progress = nullptr);
// Inverse of dwt2: four (half_height, half_width) sub-bands into a
// (2*half_height, 2*half_width) image. The sub-bands are not modified.
void idwt2(const float* ll, const float* lh, const float* hl, const float* hh, int64_t half_height,
           int64_t half_width, Wavelet wavelet, BoundaryMode mode, float* image,
           Progress* progress = nullptr);

}  // namespace lmrefine
