#include "lmrefine/automaton/warp.h"

#include <algorithm>

#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/texel_space.h"

namespace lmrefine {
namespace {

// Index of the interval [v[k], v[k+1]] that holds x (clamped to the ends).
// Grids are nearly always evenly spaced (all but the last interval), so the
// index is guessed from the first spacing and searched for only if wrong.
int interval(const std::vector<double>& v, double x) {
    const int last = int(v.size()) - 2;
    const int guess = std::clamp(int((x - v[0]) / (v[1] - v[0])), 0, last);
    if ((v[guess] <= x || guess == 0) && (x <= v[guess + 1] || guess == last)) return guess;
    const auto it = std::upper_bound(v.begin() + 1, v.end() - 1, x);
    return int(it - v.begin()) - 1;
}

double cross(const glm::dvec2& a, const glm::dvec2& b) { return a.x * b.y - a.y * b.x; }

// The point at bilinear position (s, t) inside cell (i, j), for either grid form.
template <class Grid>
glm::dvec2 bilinear(const Grid& grid, int i, int j, double s, double t) {
    const glm::dvec2 top = grid.node(i, j) * (1 - s) + grid.node(i, j + 1) * s;
    const glm::dvec2 bottom = grid.node(i + 1, j) * (1 - s) + grid.node(i + 1, j + 1) * s;
    return top * (1 - t) + bottom * t;
}

template <class Grid>
float cell_area(const Grid& grid, int i, int j) {
    const glm::dvec2 d1 = grid.node(i + 1, j + 1) - grid.node(i, j);
    const glm::dvec2 d2 = grid.node(i + 1, j) - grid.node(i, j + 1);
    return float(0.5 * cross(d1, d2));
}

// A UV grid's cells are one texel: the cell and the position inside it come
// straight from the pixel coordinates (what `interval` finds on unit spacing).
glm::dvec2 warp_point(const UvGridView& grid, glm::dvec2 p) {
    p.x = std::clamp(p.x, 0.0, double(grid.cols));
    p.y = std::clamp(p.y, 0.0, double(grid.rows));
    const int j = std::min(int(p.x), grid.cols - 1), i = std::min(int(p.y), grid.rows - 1);
    return bilinear(grid, i, j, p.x - j, p.y - i);
}

template <class Grid>
void warp_uvs_through(const Grid& grid, int width, int height, const float* uvs, int64_t count, float* out) {
    parallel_for(count, 4096, [&](int64_t begin, int64_t end) {
        for (int64_t k = begin; k < end; ++k) {
            const glm::dvec2 p = uv_to_pixel({uvs[2 * k], uvs[2 * k + 1]}, width, height);
            const glm::dvec2 uv = pixel_to_uv(warp_point(grid, p), width, height);
            out[2 * k] = float(uv.x);
            out[2 * k + 1] = float(uv.y);
        }
    });
}

template <class Grid>
LargeVector<float> cell_areas_of(const Grid& grid) {
    LargeVector<float> areas(size_t(grid.rows) * grid.cols);
    parallel_for(grid.rows, 16, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            for (int j = 0; j < grid.cols; ++j) areas[size_t(i) * grid.cols + j] = cell_area(grid, i, j);
        }
    });
    return areas;
}

}  // namespace

NodeGrid grid_axes(int width, int height, int block) {
    LMREFINE_REQUIRE(width > 0 && height > 0 && block > 0, "grid size must be positive");
    NodeGrid grid;
    grid.cols = (width + block - 1) / block;
    grid.rows = (height + block - 1) / block;
    for (int j = 0; j <= grid.cols; ++j) grid.xs.push_back(std::min(j * block, width));
    for (int i = 0; i <= grid.rows; ++i) grid.ys.push_back(std::min(i * block, height));
    return grid;
}

glm::dvec2 warp_point(const NodeGrid& grid, glm::dvec2 p) {
    p.x = std::clamp(p.x, grid.xs.front(), grid.xs.back());
    p.y = std::clamp(p.y, grid.ys.front(), grid.ys.back());
    const int j = interval(grid.xs, p.x), i = interval(grid.ys, p.y);
    const double s = (p.x - grid.xs[j]) / (grid.xs[j + 1] - grid.xs[j]);
    const double t = (p.y - grid.ys[i]) / (grid.ys[i + 1] - grid.ys[i]);
    return bilinear(grid, i, j, s, t);
}

void warp_uvs(const NodeGrid& grid, int width, int height, const float* uvs, int64_t count, float* out) {
    warp_uvs_through(grid, width, height, uvs, count, out);
}

void warp_uvs(const UvGridView& grid, const float* uvs, int64_t count, float* out) {
    warp_uvs_through(grid, grid.cols, grid.rows, uvs, count, out);
}

}  // namespace lmrefine

namespace lmrefine {

LargeVector<float> cell_areas(const NodeGrid& grid) { return cell_areas_of(grid); }

LargeVector<float> cell_areas(const UvGridView& grid) { return cell_areas_of(grid); }

}  // namespace lmrefine

namespace lmrefine {

std::vector<uint8_t> invalid_cells(const float* g, int rows, int cols) {
    std::vector<uint8_t> bad(size_t(rows) * cols);
    const size_t stride = size_t(cols + 1) * 2;
    parallel_for(rows, 16, [&](int64_t begin, int64_t end) {
        for (int64_t i = begin; i < end; ++i) {
            const float* top = g + size_t(i) * stride;
            const float* bottom = top + stride;
            for (int j = 0; j < cols; ++j) {
                // Around the cell: top-left, top-right, bottom-right, bottom-left.
                const float* q[4] = {top + 2 * j, top + 2 * j + 2, bottom + 2 * j + 2, bottom + 2 * j};
                bool invalid = false;
                for (int k = 0; k < 4; ++k) {
                    const float* p = q[k];
                    const float* next = q[(k + 1) % 4];
                    const float* prev = q[(k + 3) % 4];
                    const float ax = next[0] - p[0], ay = next[1] - p[1];
                    const float bx = prev[0] - p[0], by = prev[1] - p[1];
                    // A float product is exact in double, so rounding it to
                    // float is float32 multiplication even if the compiler
                    // would fuse a*b - c*d into an FMA.
                    const float c = float(double(ax) * by) - float(double(ay) * bx);
                    invalid = invalid || c >= 0;
                }
                bad[size_t(i) * cols + j] = invalid;
            }
        }
    });
    return bad;
}

}  // namespace lmrefine
