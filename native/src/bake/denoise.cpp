#include "lmrefine/bake/denoise.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include "lmrefine/core/parallel.h"

namespace lmrefine {
namespace {

// How many noise deviations apart two colours may be and still mix (SVGF's sigma_l).
constexpr float kColorSigma = 4.0f;
// Normal weight: max(0, n.n')^kNormalPower (SVGF).
constexpr float kNormalPower = 64.0f;
// Distance from the tangent plane, in texel sizes, that halves (about) the weight.
constexpr float kPlaneSigma = 1.0f;

float luminance(const float* c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

glm::vec3 load3(const float* p, int64_t i) { return {p[3 * i], p[3 * i + 1], p[3 * i + 2]}; }

// A per-texel variance from a few samples is itself noisy (zero when all
// samples agreed by chance), so the colour weight uses it blurred over the
// 3x3 covered neighbourhood (as SVGF does).
std::vector<float> blurred_variance(const std::vector<float>& variance, const DenoiseGuides& g) {
    std::vector<float> out(variance.size(), 0.0f);
    const float kernel[2] = {0.5f, 0.25f};
    for (int row = 0; row < g.height; ++row) {
        for (int col = 0; col < g.width; ++col) {
            const int64_t p = int64_t(row) * g.width + col;
            if (!g.covered[p]) continue;
            float sum = 0.0f, weights = 0.0f;
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    const int r = row + dy, c = col + dx;
                    if (r < 0 || r >= g.height || c < 0 || c >= g.width) continue;
                    const int64_t q = int64_t(r) * g.width + c;
                    if (!g.covered[q]) continue;
                    const float w = kernel[std::abs(dx)] * kernel[std::abs(dy)];
                    sum += w * variance[q];
                    weights += w;
                }
            }
            out[p] = sum / weights;
        }
    }
    return out;
}

}  // namespace

void denoise(float* rgba, float* variance, const DenoiseGuides& g, int iterations) {
    const int64_t texels = int64_t(g.width) * g.height;
    std::vector<float> color_in(rgba, rgba + texels * 4), color_out(color_in);
    std::vector<float> var_in(variance, variance + texels), var_out(var_in);
    const float kernel[3] = {3.0f / 8.0f, 1.0f / 4.0f, 1.0f / 16.0f};  // B3 spline, taps 0, +-1, +-2
    for (int level = 0; level < iterations; ++level) {
        const int step = 1 << level;
        const std::vector<float> var_guide = blurred_variance(var_in, g);
        // Rows are independent within a level: each reads only the previous level.
        parallel_for(g.height, 16, [&](int64_t row_begin, int64_t row_end) {
            for (int row = int(row_begin); row < int(row_end); ++row) {
                for (int col = 0; col < g.width; ++col) {
                    const int64_t p = int64_t(row) * g.width + col;
                    if (!g.covered[p]) continue;
                    const glm::vec3 xp = load3(g.position, p), np = load3(g.normal, p);
                    const float lp = luminance(&color_in[4 * p]);
                    // Noise scale of a colour difference between p and a neighbour.
                    const float sigma = kColorSigma * std::sqrt(std::max(var_guide[p], 0.0f)) + 1e-6f * (1.0f + std::abs(lp));
                    const float plane_scale = 1.0f / (kPlaneSigma * std::max(g.texel_size[p], 1e-20f) * step);
                    float sum[3] = {0, 0, 0}, weights = 0.0f, var_sum = 0.0f;
                    for (int dy = -2; dy <= 2; ++dy) {
                        for (int dx = -2; dx <= 2; ++dx) {
                            const int r = row + dy * step, c = col + dx * step;
                            if (r < 0 || r >= g.height || c < 0 || c >= g.width) continue;
                            const int64_t q = int64_t(r) * g.width + c;
                            if (!g.covered[q]) continue;
                            const float h = kernel[std::abs(dx)] * kernel[std::abs(dy)];
                            const float plane = std::abs(glm::dot(np, load3(g.position, q) - xp)) * plane_scale;
                            const float wn = std::pow(std::max(0.0f, glm::dot(np, load3(g.normal, q))), kNormalPower);
                            const float wl = std::abs(luminance(&color_in[4 * q]) - lp) / sigma;
                            const float w = h * wn * std::exp(-plane * plane - wl);
                            if (!(w > 0.0f)) continue;
                            for (int ch = 0; ch < 3; ++ch) sum[ch] += w * color_in[4 * q + ch];
                            weights += w;
                            var_sum += w * w * var_in[q];
                        }
                    }
                    // The texel itself always has weight h(0)^2 > 0, so weights > 0.
                    for (int ch = 0; ch < 3; ++ch) color_out[4 * p + ch] = sum[ch] / weights;
                    var_out[p] = var_sum / (weights * weights);
                }
            }
        });
        std::swap(color_in, color_out);
        std::swap(var_in, var_out);
    }
    for (int64_t p = 0; p < texels; ++p) {
        if (!g.covered[p]) continue;
        for (int ch = 0; ch < 3; ++ch) rgba[4 * p + ch] = color_in[4 * p + ch];
        variance[p] = var_in[p];
    }
}

}  // namespace lmrefine
