// Chart coverage: which lightmap texels a UV layout touches, found by
// rasterizing the layout (never from image alpha: Blender's bake leaves
// alpha 1 everywhere once a margin is applied).
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

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

// Calls visit(triangle, row, col) for every texel whose square overlaps the
// triangle with positive area (conservative rasterization: thin triangles and
// chart borders are not lost). Texels outside the image are skipped;
// zero-area triangles touch nothing. Triangles are visited in order.
void for_each_covered_texel(const UvLayout& layout, int width, int height,
                            const std::function<void(int64_t triangle, int row, int col)>& visit);

// (height * width) bytes, 1 where some triangle covers the texel.
std::vector<uint8_t> coverage_mask(const UvLayout& layout, int width, int height);

}  // namespace lmrefine
