#include <pybind11/pybind11.h>

#include <string>
#include <vector>

#include "lmrefine/chart/shape_fit.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {

void bind_shape_fit(py::module_& m) {
    m.def(
        "_fit_shapes",
        [](const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& targets_in) {
            auto uvs = py_util::contiguous<double>(uvs_in, "uvs");
            if (uvs.ndim() != 2 || uvs.shape(1) != 2) {
                throw py::value_error("uvs must have shape (N, 2), got " + py_util::shape_string(uvs));
            }
            auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
            auto targets = py_util::contiguous<double>(targets_in, "targets");
            if (targets.ndim() != 3 || targets.shape(0) != triangles.shape(0) || targets.shape(1) != 2 ||
                targets.shape(2) != 2) {
                throw py::value_error("targets must have shape (T, 2, 2), one per triangle, got " +
                                      py_util::shape_string(targets));
            }
            ShapeFitInput input{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0), targets.data()};
            std::vector<glm::dvec2> fitted;
            {
                py::gil_scoped_release release;
                fitted = fit_shapes(input);
            }
            std::vector<double> out(fitted.size() * 2);
            for (size_t i = 0; i < fitted.size(); ++i) out[2 * i] = fitted[i].x, out[2 * i + 1] = fitted[i].y;
            return py_util::to_numpy(std::move(out), {py::ssize_t(fitted.size()), 2});
        },
        py::arg("uvs"), py::arg("triangles"), py::arg("targets"),
        R"doc(Fit a layout's vertices to a target shape per triangle (lmrefine.stretch).

Args:
    uvs (numpy.ndarray): float64 (N, 2), shared by the triangles that meet there.
    triangles (numpy.ndarray): (T, 3) integer indices into uvs.
    targets (numpy.ndarray): float64 (T, 2, 2): each triangle's edges should
        become targets[t] @ edge.

Returns:
    numpy.ndarray: float64 (N, 2), the least-squares fit (each edge's
    residual relative to its length, weighted by its triangle's area; a
    faint pull to the input positions keeps every piece in place).
)doc");
}

}  // namespace lmrefine::bindings
