#include "lmrefine/coverage.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <glm/geometric.hpp>

#include "lmrefine/error.h"
#include "lmrefine/texel_space.h"

namespace lmrefine {
namespace {

// Overlap below this (in texels) counts as touching, not covering, so a chart
// edge that lies exactly on a texel border does not claim the next texel.
constexpr double kTouch = 1e-7;

// Separating-axis test of a triangle against the unit square at (x0, y0).
bool overlaps_texel(const glm::dvec2 p[3], double x0, double y0) {
    const glm::dvec2 corners[4] = {{x0, y0}, {x0 + 1, y0}, {x0, y0 + 1}, {x0 + 1, y0 + 1}};
    for (int e = 0; e < 3; ++e) {
        const glm::dvec2 a = p[e], b = p[(e + 1) % 3];
        const glm::dvec2 axis(a.y - b.y, b.x - a.x);
        const double scale = glm::length(axis);
        if (scale == 0.0) return false;
        double tmin = glm::dot(axis, p[0]), tmax = tmin;
        for (int k = 1; k < 3; ++k) {
            const double t = glm::dot(axis, p[k]);
            tmin = std::min(tmin, t);
            tmax = std::max(tmax, t);
        }
        double smin = glm::dot(axis, corners[0]), smax = smin;
        for (int k = 1; k < 4; ++k) {
            const double s = glm::dot(axis, corners[k]);
            smin = std::min(smin, s);
            smax = std::max(smax, s);
        }
        if (tmax <= smin + kTouch * scale || smax <= tmin + kTouch * scale) return false;
    }
    return true;
}

}  // namespace

void validate_layout(const UvLayout& layout) {
    LMREFINE_REQUIRE(layout.uv_count >= 0 && layout.triangle_count >= 0, "negative layout size");
    for (int64_t i = 0; i < layout.uv_count * 2; ++i) {
        if (!std::isfinite(layout.uvs[i])) {
            LMREFINE_THROW(InvalidArgument, "uvs[" + std::to_string(i / 2) + "] is NaN or Inf; "
                                            "fix or remove the broken UVs before refining");
        }
    }
    for (int64_t i = 0; i < layout.triangle_count * 3; ++i) {
        const int32_t index = layout.triangles[i];
        if (index < 0 || index >= layout.uv_count) {
            LMREFINE_THROW(InvalidArgument,
                           "triangles[" + std::to_string(i / 3) + "] refers to UV " + std::to_string(index) +
                               ", but there are only " + std::to_string(layout.uv_count) +
                               " UVs (indices must be in [0, len(uvs)))");
        }
    }
}

void for_each_covered_texel(const UvLayout& layout, int width, int height,
                            const std::function<void(int64_t, int, int)>& visit) {
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        glm::dvec2 p[3];
        for (int k = 0; k < 3; ++k) {
            const int32_t index = layout.triangles[3 * t + k];
            p[k] = uv_to_pixel({layout.uvs[2 * index], layout.uvs[2 * index + 1]}, width, height);
        }
        const double xmin = std::min({p[0].x, p[1].x, p[2].x}), xmax = std::max({p[0].x, p[1].x, p[2].x});
        const double ymin = std::min({p[0].y, p[1].y, p[2].y}), ymax = std::max({p[0].y, p[1].y, p[2].y});
        const int c0 = std::max(0, int(std::floor(xmin))), c1 = std::min(width - 1, int(std::ceil(xmax)));
        const int r0 = std::max(0, int(std::floor(ymin))), r1 = std::min(height - 1, int(std::ceil(ymax)));
        for (int row = r0; row <= r1; ++row) {
            for (int col = c0; col <= c1; ++col) {
                if (overlaps_texel(p, col, row)) visit(t, row, col);
            }
        }
    }
}

std::vector<uint8_t> coverage_mask(const UvLayout& layout, int width, int height) {
    LMREFINE_REQUIRE(width > 0 && height > 0, "resolution must be positive, got " + std::to_string(width) +
                                                  "x" + std::to_string(height));
    validate_layout(layout);
    std::vector<uint8_t> mask(size_t(width) * height, 0);
    for_each_covered_texel(layout, width, height,
                           [&](int64_t, int row, int col) { mask[size_t(row) * width + col] = 1; });
    return mask;
}

}  // namespace lmrefine
