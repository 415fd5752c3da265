#include "lmrefine/layout/coverage.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <glm/geometric.hpp>

#include "lmrefine/core/error.h"
#include "lmrefine/layout/layout_raster.h"
#include "lmrefine/core/texel_space.h"

namespace lmrefine {
namespace {

// Overlap below this (in texels) counts as touching, not covering, so a chart
// edge that lies exactly on a texel border does not claim the next texel.
constexpr double kTouch = 1e-7;

// The smallest index in [lo, hi) where `holds` is true, or hi; `holds` must
// be false then true along the range (monotone). Starts from `guess` (any
// value, NaN too: it only decides how many steps the walk takes).
template <class Holds>
int first_true(int lo, int hi, double guess, Holds&& holds) {
    int k = guess > lo ? (guess < hi ? int(guess) : hi) : lo;
    while (k > lo && holds(k - 1)) --k;
    while (k < hi && !holds(k)) ++k;
    return k;
}

}  // namespace

TriangleCover::TriangleCover(const glm::dvec2 p[3], int width, int height, double grow) {
    const double xmin = std::min({p[0].x, p[1].x, p[2].x}) - grow, xmax = std::max({p[0].x, p[1].x, p[2].x}) + grow;
    const double ymin = std::min({p[0].y, p[1].y, p[2].y}) - grow, ymax = std::max({p[0].y, p[1].y, p[2].y}) + grow;
    c0_ = std::max(0, int(std::floor(xmin)));
    c1_ = std::min(width - 1, int(std::ceil(xmax)));
    r0_ = std::max(0, int(std::floor(ymin)));
    r1_ = std::min(height - 1, int(std::ceil(ymax)));
    empty_ = c0_ > c1_ || r0_ > r1_;
    for (int e = 0; e < 3; ++e) {
        const glm::dvec2 a = p[e], b = p[(e + 1) % 3];
        axis_[e] = glm::dvec2(a.y - b.y, b.x - a.x);
        const double scale = glm::length(axis_[e]);
        if (scale == 0.0) empty_ = true;  // zero area: touches nothing
        tmin_[e] = tmax_[e] = glm::dot(axis_[e], p[0]);
        for (int k = 1; k < 3; ++k) {
            const double t = glm::dot(axis_[e], p[k]);
            tmin_[e] = std::min(tmin_[e], t);
            tmax_[e] = std::max(tmax_[e], t);
        }
        touch_[e] = kTouch * scale - grow * scale;
        inverse_ax_[e] = axis_[e].x != 0.0 ? 1.0 / axis_[e].x : 0.0;
    }
}

TriangleCover::TriangleCover(const UvLayout& layout, int64_t t, int width, int height) {
    glm::dvec2 p[3];
    for (int k = 0; k < 3; ++k) {
        const int32_t index = layout.triangles[3 * t + k];
        p[k] = uv_to_pixel({layout.uvs[2 * index], layout.uvs[2 * index + 1]}, width, height);
    }
    *this = TriangleCover(p, width, height);
}

// Separating-axis test of the triangle against the texel's unit square, per
// edge normal: the square's projection is [smin, smax]. Since a + b rounds
// monotonically in a and b, the smallest of the four corners' dot products
// (a.x * x + a.y * y) is the sum of the smallest x and y terms, bit for bit.
bool TriangleCover::overlaps(int row, int col) const {
    if (empty_ || row < r0_ || row > r1_ || col < c0_ || col > c1_) return false;
    for (int e = 0; e < 3; ++e) {
        const double x0 = axis_[e].x * col, x1 = axis_[e].x * (col + 1.0);
        const double y0 = axis_[e].y * row, y1 = axis_[e].y * (row + 1.0);
        const double smin = std::min(x0, x1) + std::min(y0, y1), smax = std::max(x0, x1) + std::max(y0, y1);
        if (tmax_[e] <= smin + touch_[e] || smax <= tmin_[e] + touch_[e]) return false;
    }
    return true;
}

// Each of the six half-tests of `overlaps` is monotone along a row (smin and
// smax move one way with the column), so each bounds the span from one side.
// The bound is guessed from the real-valued crossing (rounded up to the
// next column) and then walked to the exact column where the rounded
// half-test flips: the span holds exactly the texels `overlaps` accepts.
std::pair<int, int> TriangleCover::columns(int row) const {
    int begin = c0_, end = c1_ + 1;
    if (empty_) return {c0_, c0_};
    for (int e = 0; e < 3 && begin < end; ++e) {
        const double ax = axis_[e].x;
        const double y0 = axis_[e].y * row, y1 = axis_[e].y * (row + 1.0);
        const double ymin = std::min(y0, y1), ymax = std::max(y0, y1);
        const double tmax = tmax_[e], tmin_touch = tmin_[e] + touch_[e], touch = touch_[e];
        // below(col): the triangle reaches past the square's low end
        // (tmax > smin + touch); above(col): past its high end (smax > tmin
        // + touch). With ax > 0 the square's low end is at its left column
        // edge (ax * col), else at its right one: the same rounded values
        // as the min / max in `overlaps`.
        if (ax > 0) {
            auto above = [&](int col) { return ax * (col + 1.0) + ymax > tmin_touch; };
            auto not_below = [&](int col) { return !(tmax > ax * col + ymin + touch); };
            begin = first_true(begin, end, (tmin_touch - ymax) * inverse_ax_[e], above);
            end = first_true(begin, end, (tmax - ymin - touch) * inverse_ax_[e] + 1.0, not_below);
        } else if (ax < 0) {
            auto below = [&](int col) { return tmax > ax * (col + 1.0) + ymin + touch; };
            auto not_above = [&](int col) { return !(ax * col + ymax > tmin_touch); };
            begin = first_true(begin, end, (tmax - ymin - touch) * inverse_ax_[e], below);
            end = first_true(begin, end, (tmin_touch - ymax) * inverse_ax_[e] + 1.0, not_above);
        } else if (!(tmax > ymin + touch) || !(ymax > tmin_touch)) {  // the same for every column
            end = begin;
        }
    }
    return begin >= end ? std::pair<int, int>(c0_, c0_) : std::pair<int, int>(begin, end);
}

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

double texel_pairs_at_least(const UvLayout& layout, int width, int height) {
    // A texel crossing the triangle's border lies within sqrt(2) of it: those
    // cover at most sqrt(2) x perimeter of its area, texels wholly inside the rest.
    double pairs = 0.0;
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        glm::dvec2 p[3];
        bool inside = true;
        for (int k = 0; k < 3; ++k) {
            const float* uv = layout.uvs + 2 * int64_t(layout.triangles[3 * t + k]);
            inside = inside && uv[0] >= 0.0f && uv[0] <= 1.0f && uv[1] >= 0.0f && uv[1] <= 1.0f;
            p[k] = glm::dvec2(double(uv[0]) * width, double(uv[1]) * height);
        }
        if (!inside) continue;
        const glm::dvec2 e1 = p[1] - p[0], e2 = p[2] - p[0];
        const double area = 0.5 * std::abs(e1.x * e2.y - e1.y * e2.x);
        const double perimeter = glm::length(p[1] - p[0]) + glm::length(p[2] - p[1]) + glm::length(p[0] - p[2]);
        pairs += std::max(0.0, area - std::sqrt(2.0) * perimeter);
    }
    return pairs;
}

std::vector<uint8_t> coverage_mask(const UvLayout& layout, int width, int height) {
    LMREFINE_REQUIRE(width > 0 && height > 0, "resolution must be positive, got " + std::to_string(width) +
                                                  "x" + std::to_string(height));
    validate_layout(layout);
    return coverage_mask(LayoutRaster(layout, width, height));
}

}  // namespace lmrefine
