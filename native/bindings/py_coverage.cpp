#include <pybind11/pybind11.h>

#include "lmrefine/layout/coverage.h"
#include "lmrefine/core/error.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

py::array_t<bool> coverage(const py::handle& uvs, const py::handle& triangles, const py::handle& resolution) {
    return py_util::layout_mask(uvs, triangles, resolution, [](const UvLayout& layout, int width, int height) {
        return coverage_mask(layout, width, height);
    });
}

}  // namespace

void bind_coverage(py::module_& m) {
    m.def("coverage_mask", &coverage, py::arg("uvs"), py::arg("triangles"), py::arg("resolution"),
          R"doc(Rasterize a UV layout: which lightmap texels some chart covers.

Args:
    uvs (numpy.ndarray): (N, 2) per-corner UVs (any real dtype; used as float32).
    triangles (numpy.ndarray): (T, 3) integer indices into ``uvs``.
    resolution (int | tuple[int, int]): lightmap size, square or (height, width).

Returns:
    numpy.ndarray: bool of shape (H, W), row 0 at the top (v = 1); True where
    a triangle overlaps the texel with positive area (conservative: thin
    triangles are not lost). Use it as the ``mask`` of gradient_map; never
    derive coverage from a baked image's alpha.

Raises:
    ValueError: bad shapes, indices out of range, NaN UVs, resolution <= 0.
)doc");
}

}  // namespace lmrefine::bindings
