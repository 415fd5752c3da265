// The warp: carrying points through a deformed grid (docs/method.md §5). A grid has
// nodes at known original positions (a tensor grid of columns xs and rows ys
// in pixel space, see texel_space.h) and their deformed positions; a point is
// carried to the deformed cell that holds it with its bilinear coordinates
// inside the cell preserved. For grids whose cells are convex and
// non-inverted the map is one-to-one.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

#include "lmrefine/core/memory.h"
#include "lmrefine/core/texel_space.h"

namespace lmrefine {

struct NodeGrid {
    int rows = 0;                    // cells down
    int cols = 0;                    // cells across
    std::vector<double> xs;          // cols + 1 original node x, increasing
    std::vector<double> ys;          // rows + 1 original node y, increasing
    LargeVector<glm::dvec2> nodes;   // (rows + 1) * (cols + 1) deformed positions, row-major

    glm::dvec2& node(int i, int j) { return nodes[size_t(i) * (cols + 1) + j]; }
    const glm::dvec2& node(int i, int j) const { return nodes[size_t(i) * (cols + 1) + j]; }
};

// A grid over [0, width] x [0, height] with `block`-texel cells (the last row
// and column may be narrower): its rows, cols, xs and ys, and no nodes (the
// caller places them; fresh node arrays are costly to fault in).
NodeGrid grid_axes(int width, int height, int block = 1);

// Carries a point given in original coordinates. Points outside the grid's
// original rectangle are clamped onto it first.
glm::dvec2 warp_point(const NodeGrid& grid, glm::dvec2 p);

// Carries `count` UVs (u, v pairs) through a grid laid over a width x height
// lightmap; `out` may not alias `uvs`. Runs in parallel.
void warp_uvs(const NodeGrid& grid, int width, int height, const float* uvs, int64_t count, float* out);

// A grid as it crosses the boundary: float32 (rows + 1) x (cols + 1) nodes
// of (u, v) in UV space, one cell per texel of a cols x rows lightmap, read
// in place. Each node is converted to pixel space when used, exactly as a
// NodeGrid would hold it, so results equal the NodeGrid ones bit for bit
// without converting (and allocating) every node of a large grid first.
struct UvGridView {
    const float* nodes = nullptr;
    int rows = 0, cols = 0;

    glm::dvec2 node(int i, int j) const {
        const float* p = nodes + 2 * (size_t(i) * (cols + 1) + j);
        return uv_to_pixel({p[0], p[1]}, cols, rows);
    }
};

// warp_uvs and cell_areas of the NodeGrid the view describes.
void warp_uvs(const UvGridView& grid, const float* uvs, int64_t count, float* out);

}  // namespace lmrefine

namespace lmrefine {

// Area of every cell (rows * cols, row-major), in the grid's units (texels^2
// for a pixel-space grid).
LargeVector<float> cell_areas(const NodeGrid& grid);
LargeVector<float> cell_areas(const UvGridView& grid);

// Cells (rows * cols bytes, row-major) of a float32 UV-space grid, nodes
// (rows + 1) x (cols + 1) of (u, v) with v up, that are not convex,
// non-inverted quadrilaterals: some corner's cross product, computed in
// float32 (the grid's own precision, as the refiner's numpy code did), is
// >= 0. Reads the float32 nodes in place: no NodeGrid conversion. This is
// what the warp needs to be one-to-one (the back-off judges blended grids
// with it), weaker than the automaton's cell validity (automaton_cell.h):
// judging by that instead changes results (docs/refiner.md, "Invariants").
std::vector<uint8_t> invalid_cells(const float* uv_nodes, int rows, int cols);

}  // namespace lmrefine
