#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>

#include "grid_array.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "lmrefine/core/texel_space.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine {
namespace py_util {

py::array_t<float> grid_to_numpy(const NodeGrid& grid, int width, int height) {
    LargeVector<float> values(grid.nodes.size() * 2);
    for (size_t k = 0; k < grid.nodes.size(); ++k) {
        const glm::dvec2 uv = pixel_to_uv(grid.nodes[k], width, height);
        values[2 * k] = float(uv.x);
        values[2 * k + 1] = float(uv.y);
    }
    return to_numpy(std::move(values), {grid.rows + 1, grid.cols + 1, 2});
}

UvGridArray grid_from_numpy(const py::handle& object, const char* name) {
    auto array = require_float32(object, name, {3});
    if (array.shape(2) != 2 || array.shape(0) < 2 || array.shape(1) < 2) {
        throw py::value_error(std::string(name) + " must have shape (H + 1, W + 1, 2), got " +
                              shape_string(array));
    }
    const float* p = array.data();
    if (!std::all_of(p, p + array.size(), [](float x) { return std::isfinite(x); })) {
        throw py::value_error(std::string(name) + " holds NaN or Inf node positions");
    }
    return {array, UvGridView{p, int(array.shape(0)) - 1, int(array.shape(1)) - 1}};
}

}  // namespace py_util

namespace bindings {

void bind_warp(py::module_& m) {
    m.def(
        "warp_uvs",
        [](const py::handle& uvs_in, const py::handle& grid_in) {
            auto uvs = py_util::require_points(uvs_in, "uvs", 2, /*allow_empty=*/true);
            const auto grid = py_util::grid_from_numpy(grid_in, "grid");
            const int64_t n = uvs.shape(0);
            for (int64_t k = 0; k < 2 * n; ++k) {
                if (!std::isfinite(uvs.data()[k])) {
                    throw py::value_error("uvs[" + std::to_string(k / 2) + "] is NaN or Inf");
                }
            }
            std::vector<float> out(size_t(n) * 2);
            {
                py::gil_scoped_release release;
                warp_uvs(grid.view, uvs.data(), n, out.data());
            }
            return py_util::to_numpy(std::move(out), {py::ssize_t(n), 2});
        },
        py::arg("uvs"), py::arg("grid"),
        R"doc(Carry UVs through a deformed grid (the warp of the refiner).

Args:
    uvs (numpy.ndarray): (N, 2) UVs (any real dtype).
    grid (numpy.ndarray): float32 (H + 1, W + 1, 2) node positions in UV
        space over an H x W lightmap; the identity grid has node (i, j) at
        u = j / W, v = 1 - i / H.

Returns:
    numpy.ndarray: float32 (N, 2). Each UV is moved to the deformed cell of
    the texel that holds it, at the same bilinear position inside the cell.
    UVs outside [0, 1] are clamped onto the border first.
)doc");

    m.def(
        "grid_invalid_cells",
        [](const py::handle& grid_in) {
            auto grid = py_util::require_float32(grid_in, "grid", {3});
            if (grid.shape(2) != 2 || grid.shape(0) < 2 || grid.shape(1) < 2) {
                throw py::value_error("grid must have shape (H + 1, W + 1, 2), got " + py_util::shape_string(grid));
            }
            const int rows = int(grid.shape(0)) - 1, cols = int(grid.shape(1)) - 1;
            std::vector<uint8_t> bad;
            {
                py::gil_scoped_release release;
                bad = invalid_cells(grid.data(), rows, cols);
            }
            auto bytes = py_util::to_numpy(std::move(bad), {rows, cols});
            return bytes.attr("view")(py::dtype::of<bool>()).cast<py::array_t<bool>>();
        },
        py::arg("grid"),
        R"doc(Cells of a deformed grid that are not convex, non-inverted quadrilaterals.

Args:
    grid (numpy.ndarray): float32 (H + 1, W + 1, 2) node positions in UV space.

Returns:
    numpy.ndarray: bool (H, W), True where a corner's cross product (float32,
    UV space, v up: a valid cell turns clockwise) is >= 0.
)doc");

    m.def(
        "grid_cell_areas",
        [](const py::handle& grid_in) {
            const auto grid = py_util::grid_from_numpy(grid_in, "grid");
            LargeVector<float> areas;
            {
                py::gil_scoped_release release;
                areas = cell_areas(grid.view);
            }
            return py_util::to_numpy(std::move(areas), {grid.view.rows, grid.view.cols});
        },
        py::arg("grid"),
        R"doc(Area of every cell of a deformed grid, in texels.

Args:
    grid (numpy.ndarray): float32 (H + 1, W + 1, 2) node positions in UV space.

Returns:
    numpy.ndarray: float32 (H, W). The identity grid gives 1 everywhere; a
    cell of area 3 gives the surface of its original texel three texels, so
    this is also the texel-density ratio. Negative means an inverted cell.
)doc");
}

}  // namespace bindings
}  // namespace lmrefine
