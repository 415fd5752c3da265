#include <pybind11/pybind11.h>

#include <utility>
#include <vector>

#include "lmrefine/chart/bounding_box.h"
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

    m.def(
        "smallest_box_turns",
        [](const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& charts_in) {
            auto uvs = py_util::require_points(uvs_in, "uvs", 2, /*allow_empty=*/true);
            auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
            UvLayout layout{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0)};
            validate_layout(layout);
            auto [ids, count] = py_util::require_chart_ids(charts_in, layout.triangle_count);
            std::vector<glm::dvec2> turns;
            {
                py::gil_scoped_release release;
                turns = chart::smallest_box_turns(layout, ids, count);
            }
            std::vector<double> flat;
            flat.reserve(2 * turns.size());
            for (const glm::dvec2& turn : turns) flat.insert(flat.end(), {turn.x, turn.y});
            return py_util::to_numpy(std::move(flat), {py::ssize_t(turns.size()), py::ssize_t(2)});
        },
        py::arg("uvs"), py::arg("triangles"), py::arg("charts"),
        R"doc(Per chart, the turn that gives it its smallest axis-aligned bounding box.

The packer turns charts by quarter turns only; a chart stretched along a
diagonal, or unwrapped along one, packs as its larger box otherwise. A
minimal-area rectangle has a side along an edge of the convex hull, so
those are the turns tried.

Args:
    uvs (numpy.ndarray): (N, 2) UVs.
    triangles (numpy.ndarray): (T, 3) integer indices into ``uvs``.
    charts (numpy.ndarray): (T,) integer chart id per triangle, in [0, T)
        (find_charts' numbering).

Returns:
    numpy.ndarray: float64 (C, 2), C = the largest id + 1: each chart's
    (cos, sin) of the angle to turn its UVs by, counter-clockwise about any
    point; (1, 0) for a chart without triangles or area.

Raises:
    ValueError: bad shapes, indices or chart ids out of range, NaN/Inf UVs.
)doc");
}

}  // namespace lmrefine::bindings
