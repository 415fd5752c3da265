// Chart coverage: which lightmap texels a UV layout touches, found by
// rasterizing the layout (never from image alpha: Blender's bake leaves
// alpha 1 everywhere once a margin is applied).
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <glm/vec2.hpp>

namespace lmrefine {

// A UV layout as it crosses the boundary: per-corner UVs and triangles of
// indices into them. Views only; the caller owns the arrays.
struct UvLayout {
    const float* uvs = nullptr;          // (uv_count, 2): u, v
    int64_t uv_count = 0;
    const int32_t* triangles = nullptr;  // (triangle_count, 3)
    int64_t triangle_count = 0;
};

// Throws InvalidArgument naming the first bad index or UV (index out of
// range, NaN/Inf UV).
void validate_layout(const UvLayout& layout);

// The texels one triangle (in pixel space) covers: every texel whose square
// overlaps it with positive area (conservative rasterization: thin triangles
// and chart borders are not lost), clipped to the image. A triangle is
// convex, so the covered texels of a row are contiguous: the per-texel
// separating-axis test only runs across each row's span, with everything
// that does not depend on the texel computed once here.
class TriangleCover {
public:
    // `grow` > 0 (texels) also covers texels the triangle misses by less
    // than that (along its edge normals and the axes: a superset of the
    // triangle grown by a disc of that radius), as the packer's footprints need.
    TriangleCover(const glm::dvec2 p[3], int width, int height, double grow = 0.0);
    TriangleCover(const UvLayout& layout, int64_t triangle, int width, int height);

    // Rows [row_begin, row_end) may hold covered texels (empty if the
    // triangle has zero area or misses the image).
    int row_begin() const { return r0_; }
    int row_end() const { return empty_ ? r0_ : r1_ + 1; }
    // The covered columns [first, second) of a row in [row_begin, row_end).
    std::pair<int, int> columns(int row) const;
    // Does the triangle overlap texel (row, col) with positive area?
    bool overlaps(int row, int col) const;

private:
    glm::dvec2 axis_[3];  // edge normals (not normalized)
    double tmin_[3], tmax_[3], touch_[3];
    double inverse_ax_[3];  // 1 / axis_.x (0 if 0): the guess of a span's end, not its exact test
    int c0_, c1_, r0_, r1_;
    bool empty_ = false;
};

// Calls visit(triangle, row, col) for every texel TriangleCover finds, in
// triangle order, rows top to bottom, columns left to right. A template, so
// the per-texel visit inlines (it runs ~10^6 times per layout at 1024^2).
template <class Visit>
void for_each_covered_texel(const UvLayout& layout, int width, int height, Visit&& visit) {
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        const TriangleCover cover(layout, t, width, height);
        for (int row = cover.row_begin(); row < cover.row_end(); ++row) {
            const auto [begin, end] = cover.columns(row);
            for (int col = begin; col < end; ++col) visit(t, row, col);
        }
    }
}

// (height * width) bytes, 1 where some triangle covers the texel.
std::vector<uint8_t> coverage_mask(const UvLayout& layout, int width, int height);

// A lower bound on the (texel, triangle) pairs whose texel centre lies in
// the triangle, summed over the (validated) layout's triangles: one wholly
// inside [0, 1]^2 holds at least its area less sqrt(2) times its perimeter
// (in texels: the texels wholly inside it), others count 0. O(triangles), for
// a memory estimate before pairs are gathered: a stack of faces (a texture map
// taken for a lightmap) makes them texels x depth.
double texel_pairs_at_least(const UvLayout& layout, int width, int height);

}  // namespace lmrefine
