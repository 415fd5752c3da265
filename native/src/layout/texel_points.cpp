#include "lmrefine/layout/texel_points.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/vec2.hpp>

#include "lmrefine/core/parallel.h"
#include "lmrefine/layout/bilinear_lookup.h"

namespace lmrefine {
namespace {

// How far (in texels) a point with none of its 2 x 2 texels in its own chart
// looks for the nearest one: a sliver chart, or a point on its border.
constexpr int kOwnedSearch = 2;

// The source map's value at (u, v) read from the texels `owner` gives to
// `chart` only: the bilinear weights of those of the 2 x 2 texels (exactly
// bilinear_sample when it owns all four), renormalized; where it owns none
// of them, its nearest texel within kOwnedSearch; where none is that close,
// the plain bilinear value. A texel of another chart beside it holds other
// light (Lightmap Pack packs unrelated faces a texel apart).
void owned_sample(const float* image, int width, int height, int channels, const int32_t* owner, int32_t chart,
                  double u, double v, double* out) {
    const BilinearFootprint f = bilinear_footprint(width, height, u, v);
    if (owner[f.texel[0]] == chart && owner[f.texel[1]] == chart && owner[f.texel[2]] == chart &&
        owner[f.texel[3]] == chart) {
        bilinear_blend(image, channels, f, out);
        return;
    }
    const double weight[4] = {(1.0 - f.fx) * (1.0 - f.fy), f.fx * (1.0 - f.fy), (1.0 - f.fx) * f.fy, f.fx * f.fy};
    double total = 0.0;
    for (int c = 0; c < channels; ++c) out[c] = 0.0;
    for (int k = 0; k < 4; ++k) {
        if (owner[f.texel[k]] != chart || !(weight[k] > 0.0)) continue;
        total += weight[k];
        for (int c = 0; c < channels; ++c) out[c] += weight[k] * double(image[f.texel[k] * channels + c]);
    }
    if (total > 0.0) {
        for (int c = 0; c < channels; ++c) out[c] /= total;
        return;
    }
    // The nearest texel of the chart (the first in row order on a tie).
    const int64_t ci = int64_t(std::floor(f.y + 0.5)), cj = int64_t(std::floor(f.x + 0.5));
    int64_t best = -1;
    double best_distance = std::numeric_limits<double>::infinity();
    for (int64_t i = std::max<int64_t>(ci - kOwnedSearch, 0); i <= std::min<int64_t>(ci + kOwnedSearch, height - 1);
         ++i) {
        for (int64_t j = std::max<int64_t>(cj - kOwnedSearch, 0);
             j <= std::min<int64_t>(cj + kOwnedSearch, width - 1); ++j) {
            if (owner[i * width + j] != chart) continue;
            const double distance = (double(j) - f.x) * (double(j) - f.x) + (double(i) - f.y) * (double(i) - f.y);
            if (distance < best_distance) best_distance = distance, best = i * width + j;
        }
    }
    if (best < 0) {
        bilinear_blend(image, channels, f, out);
        return;
    }
    for (int c = 0; c < channels; ++c) out[c] = double(image[best * channels + c]);
}

}  // namespace

TexelPoints texel_points(const double* uvs, const int32_t* triangles, int64_t triangle_count, int width,
                         int height) {
    const size_t texels = size_t(width) * size_t(height);
    TexelPoints out;
    out.triangle.assign(texels, 0);
    out.bary.assign(texels * 3, 0.0);
    out.score.assign(texels, -std::numeric_limits<double>::infinity());
    for (int64_t t = 0; t < triangle_count; ++t) {
        glm::dvec2 p[3];
        for (int k = 0; k < 3; ++k) {
            const int32_t index = triangles[3 * t + k];
            // Texel units, rows down: x = u W, y = H - v H.
            p[k] = glm::dvec2(uvs[2 * index] * width, height - uvs[2 * index + 1] * height);
        }
        const glm::dvec2 ab = p[1] - p[0], ac = p[2] - p[0];
        const double det = ab.x * ac.y - ab.y * ac.x;
        if (det == 0.0) continue;  // no area: its score is -inf, never better
        const auto clamp_floor = [](double value, int size) {
            return int(std::clamp(std::floor(value), 0.0, double(size - 1)));
        };
        const int c0 = clamp_floor(std::min({p[0].x, p[1].x, p[2].x}), width);
        const int c1 = clamp_floor(std::max({p[0].x, p[1].x, p[2].x}), width);
        const int r0 = clamp_floor(std::min({p[0].y, p[1].y, p[2].y}), height);
        const int r1 = clamp_floor(std::max({p[0].y, p[1].y, p[2].y}), height);
        for (int row = r0; row <= r1; ++row) {
            for (int col = c0; col <= c1; ++col) {
                const glm::dvec2 ap = glm::dvec2(col + 0.5, row + 0.5) - p[0];
                const double beta = (ap.x * ac.y - ap.y * ac.x) / det;
                const double gamma = (ab.x * ap.y - ab.y * ap.x) / det;
                const double alpha = 1.0 - beta - gamma;
                const double score = std::min({alpha, beta, gamma});
                const size_t texel = size_t(row) * size_t(width) + size_t(col);
                if (!(score > out.score[texel])) continue;  // the first deepest triangle wins a tie
                out.score[texel] = score;
                out.triangle[texel] = t;
                out.bary[3 * texel] = alpha;
                out.bary[3 * texel + 1] = beta;
                out.bary[3 * texel + 2] = gamma;
            }
        }
    }
    return out;
}

std::vector<float> carry_lightmap(const TexelPoints& points, const uint8_t* mask, const double* source_uvs,
                                  const int32_t* source_triangles, const int32_t* source_chart,
                                  const int32_t* source_owner, const float* image, int width, int height,
                                  int channels) {
    const int64_t texels = int64_t(width) * int64_t(height);
    std::vector<float> out(size_t(texels) * size_t(channels), 0.0f);
    parallel_for(texels, 1 << 14, [&](int64_t begin, int64_t end) {
        std::vector<double> value(static_cast<size_t>(channels));  // one texel's channels
        for (int64_t i = begin; i < end; ++i) {
            if (!mask[i]) continue;
            double w[3];
            if (std::isfinite(points.score[size_t(i)])) {
                // Clamped into the triangle (a texel it only grazes), summed left to right as numpy sums.
                for (int k = 0; k < 3; ++k) w[k] = std::max(points.bary[size_t(3 * i + k)], 0.0);
                const double sum = std::max((0.0 + w[0]) + w[1] + w[2], 1e-300);
                for (double& weight : w) weight /= sum;
            } else {
                w[0] = w[1] = w[2] = 1.0 / 3.0;  // a texel only degenerate triangles touch
            }
            const int32_t* corner = source_triangles + 3 * points.triangle[size_t(i)];
            double u = 0.0, v = 0.0;
            for (int k = 0; k < 3; ++k) {
                u += w[k] * source_uvs[2 * corner[k]];
                v += w[k] * source_uvs[2 * corner[k] + 1];
            }
            owned_sample(image, width, height, channels, source_owner, source_chart[points.triangle[size_t(i)]], u,
                         v, value.data());
            for (int c = 0; c < channels; ++c) out[size_t(i * channels + c)] = float(value[size_t(c)]);
        }
    });
    return out;
}

}  // namespace lmrefine
