// The 1-D transforms and the detail filter of a lifting scheme.
#include <cmath>
#include <vector>

#include "lmrefine/core/error.h"
#include "lmrefine/gradient/wavelet.h"
#include "wavelet_lifting.h"

namespace lmrefine {

void dwt(const float* signal, int64_t length, Wavelet wavelet, BoundaryMode mode, float* approx,
         float* detail) {
    LMREFINE_REQUIRE(length >= 2 && length % 2 == 0,
                     "a one-level wavelet transform needs an even number of samples (>= 2), got " +
                         std::to_string(length) + "; crop or pad the signal by one sample");
    const int64_t half = length / 2;
    for (int64_t n = 0; n < half; ++n) {
        approx[n] = signal[2 * n];
        detail[n] = signal[2 * n + 1];
    }
    std::vector<float> scratch;
    lifting::lift(lifting_scheme(wavelet), mode, approx, detail, half, 1, 1, false, scratch);
}

void idwt(const float* approx, const float* detail, int64_t half, Wavelet wavelet, BoundaryMode mode,
          float* signal) {
    LMREFINE_REQUIRE(half >= 1, "the sub-bands are empty");
    std::vector<float> s(approx, approx + half), d(detail, detail + half), scratch;
    lifting::lift(lifting_scheme(wavelet), mode, s.data(), d.data(), half, 1, 1, true, scratch);
    for (int64_t n = 0; n < half; ++n) {
        signal[2 * n] = s[n];
        signal[2 * n + 1] = d[n];
    }
}

DetailFilter detail_filter(Wavelet wavelet) {
    // The detail is linear in the signal: its impulse responses, taken in
    // double precision on a periodic signal long enough that nothing wraps
    // into the sample looked at, are the filter taps.
    const LiftingScheme& scheme = lifting_scheme(wavelet);
    constexpr int64_t kHalf = 64, kCentre = kHalf / 2;
    std::vector<double> taps;
    int first = 0;
    bool found = false;
    for (int64_t i = 0; i < 2 * kHalf; ++i) {
        std::vector<double> s(kHalf, 0.0), d(kHalf, 0.0);
        (i % 2 ? d : s)[i / 2] = 1.0;
        for (int k = 0; k < scheme.step_count; ++k) {
            const LiftingStep& step = scheme.steps[k];
            const bool predict = step.kind == LiftingStep::Predict;
            std::vector<double>& dst = predict ? d : s;
            const std::vector<double>& src = predict ? s : d;
            std::vector<double> sum(kHalf, 0.0);
            for (int64_t n = 0; n < kHalf; ++n) {
                for (int j = 0; j < step.count; ++j) {
                    sum[n] += step.coeffs[j] * src[((n + step.offset + j) % kHalf + kHalf) % kHalf];
                }
            }
            for (int64_t n = 0; n < kHalf; ++n) dst[n] += sum[n];
        }
        const double tap = d[kCentre] * scheme.scale_d;
        if (std::abs(tap) < 1e-12) {
            if (found) taps.push_back(0.0);  // an inner zero tap is kept in place
            continue;
        }
        if (!found) first = int(i - 2 * kCentre);
        found = true;
        taps.push_back(tap);
    }
    while (!taps.empty() && taps.back() == 0.0) taps.pop_back();
    return {taps, first};
}

}  // namespace lmrefine
