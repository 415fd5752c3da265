// Deformed grids cross the boundary as (H + 1, W + 1, 2) float32 arrays of
// node positions in UV space (the identity grid has node (i, j) at
// u = j / W, v = 1 - i / H); natively they are NodeGrids in pixel space, or
// UvGridViews of the array itself.
#pragma once

#include <pybind11/numpy.h>

#include "lmrefine/automaton/warp.h"

namespace lmrefine::py_util {

namespace py = pybind11;

py::array_t<float> grid_to_numpy(const NodeGrid& grid, int width, int height);

// A grid array checked (shape, dtype, finite nodes) and viewed in place;
// `array` keeps the viewed memory alive. The grid is over a
// (shape[0] - 1) x (shape[1] - 1) lightmap.
struct UvGridArray {
    py::array_t<float, py::array::c_style> array;
    UvGridView view;
};
UvGridArray grid_from_numpy(const py::handle& array, const char* name);

}  // namespace lmrefine::py_util
