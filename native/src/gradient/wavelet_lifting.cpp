#include "wavelet_lifting.h"

#include <algorithm>

namespace lmrefine::lifting {

int64_t fold_index(int64_t n, int64_t count, bool odd, BoundaryMode mode) {
    if (n >= 0 && n < count) return n;
    if (mode == BoundaryMode::Periodic) {
        const int64_t r = n % count;
        return r < 0 ? r + count : r;
    }
    // Whole-sample symmetric extension of the signal x (length N = 2 count,
    // period 2N - 2); the period is even, so a sample keeps its parity.
    const int64_t length = 2 * count, period = 2 * length - 2;
    int64_t i = (2 * n + (odd ? 1 : 0)) % period;
    if (i < 0) i += period;
    if (i >= length) i = period - i;
    return (i - (odd ? 1 : 0)) / 2;
}

namespace {

// dst[n] += sign * sum_j c[j] src[n + offset + j] for one contiguous signal.
// The sum is formed first and then added, so the inverse step (sign -1)
// subtracts exactly the same float value.
void step_single_lane(const LiftingStep& step, BoundaryMode mode, float* dst, const float* src,
                      bool src_odd, int64_t count, float sign, std::vector<float>& acc) {
    acc.assign(count, 0.0f);
    const int64_t first = std::clamp<int64_t>(-step.offset, 0, count);
    const int64_t last = std::clamp<int64_t>(count - step.offset - step.count + 1, first, count);
    for (int j = 0; j < step.count; ++j) {
        const float c = float(step.coeffs[j]);
        const int64_t k = step.offset + j;
        for (int64_t n = first; n < last; ++n) acc[n] += c * src[n + k];
    }
    auto edge = [&](int64_t n) {
        float sum = 0.0f;
        for (int j = 0; j < step.count; ++j) {
            sum += float(step.coeffs[j]) * src[fold_index(n + step.offset + j, count, src_odd, mode)];
        }
        acc[n] = sum;
    };
    for (int64_t n = 0; n < first; ++n) edge(n);
    for (int64_t n = last; n < count; ++n) edge(n);
    for (int64_t n = 0; n < count; ++n) dst[n] += sign * acc[n];
}

// The same step where every element is a row of `lanes` floats.
void step_lanes(const LiftingStep& step, BoundaryMode mode, float* dst, const float* src, bool src_odd,
                int64_t count, int64_t stride, int64_t lanes, float sign, std::vector<float>& acc) {
    acc.resize(lanes);
    float* a = acc.data();
    for (int64_t n = 0; n < count; ++n) {
        // Same order of float operations as step_single_lane: 0 + c0 x0 + c1 x1 ...
        std::fill(a, a + lanes, 0.0f);
        for (int j = 0; j < step.count; ++j) {
            const float c = float(step.coeffs[j]);
            const float* in = src + fold_index(n + step.offset + j, count, src_odd, mode) * stride;
            for (int64_t l = 0; l < lanes; ++l) a[l] += c * in[l];
        }
        float* out = dst + n * stride;
        for (int64_t l = 0; l < lanes; ++l) out[l] += sign * a[l];
    }
}

void scale(float* band, int64_t count, int64_t stride, int64_t lanes, float factor) {
    if (stride == lanes) {  // contiguous: one loop the compiler vectorizes
        for (int64_t i = 0; i < count * lanes; ++i) band[i] *= factor;
        return;
    }
    for (int64_t n = 0; n < count; ++n) {
        float* p = band + n * stride;
        for (int64_t l = 0; l < lanes; ++l) p[l] *= factor;
    }
}

}  // namespace

void lift(const LiftingScheme& scheme, BoundaryMode mode, float* s, float* d, int64_t count,
          int64_t stride, int64_t lanes, bool inverse, std::vector<float>& scratch) {
    auto run = [&](const LiftingStep& step, float sign) {
        const bool predict = step.kind == LiftingStep::Predict;
        float* dst = predict ? d : s;
        const float* src = predict ? s : d;
        if (lanes == 1 && stride == 1) {
            step_single_lane(step, mode, dst, src, /*src_odd=*/!predict, count, sign, scratch);
        } else {
            step_lanes(step, mode, dst, src, !predict, count, stride, lanes, sign, scratch);
        }
    };
    if (!inverse) {
        for (int i = 0; i < scheme.step_count; ++i) run(scheme.steps[i], 1.0f);
        scale(s, count, stride, lanes, float(scheme.scale_s));
        scale(d, count, stride, lanes, float(scheme.scale_d));
    } else {
        scale(s, count, stride, lanes, float(1.0 / scheme.scale_s));
        scale(d, count, stride, lanes, float(1.0 / scheme.scale_d));
        for (int i = scheme.step_count - 1; i >= 0; --i) run(scheme.steps[i], -1.0f);
    }
}

}  // namespace lmrefine::lifting
