#include <pybind11/pybind11.h>

#include "lmrefine/layout/chart.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {

void bind_chart(py::module_& m) {
    m.def(
        "find_charts",
        [](const py::handle& uvs_in, const py::handle& triangles_in, double tolerance) {
            auto uvs = py_util::require_points(uvs_in, "uvs", 2);
            auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
            UvLayout layout{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0)};
            validate_layout(layout);
            Charts charts = find_charts(layout, tolerance);
            return py_util::to_numpy(std::move(charts.triangle_chart), {py::ssize_t(layout.triangle_count)});
        },
        py::arg("uvs"), py::arg("triangles"), py::arg("tolerance") = 0.0,
        R"doc(Split a UV layout into charts (connected UV islands).

Args:
    uvs (numpy.ndarray): (N, 2) per-corner UVs.
    triangles (numpy.ndarray): (T, 3) integer indices into ``uvs``.
    tolerance (float): UV-space distance; corners closer than it are joined
        (Blender's layouts are not bit-exact: 1e-5 joins its islands).
        0 joins bit-identical corners only.

Returns:
    numpy.ndarray: int32 of shape (T,), the chart of each triangle, numbered
    0.. in order of first appearance. Triangles are in one chart when they
    share a UV index or corners closer than ``tolerance`` (or bit-identical).

Raises:
    ValueError: bad shapes, indices out of range, NaN UVs, tolerance < 0.
)doc");
}

}  // namespace lmrefine::bindings
