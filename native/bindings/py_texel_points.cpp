#include <pybind11/pybind11.h>

#include <cmath>
#include <string>

#include "lmrefine/layout/texel_points.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {

void bind_texel_points(py::module_& m) {
    m.def(
        "texel_points",
        [](const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution) {
            auto uvs = py_util::contiguous<double>(uvs_in, "uvs");
            if (uvs.ndim() != 2 || uvs.shape(1) != 2) {
                throw py::value_error("uvs must have shape (N, 2), got " + py_util::shape_string(uvs));
            }
            auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
            // Every texel holds 8 + 24 + 8 bytes of output.
            const auto [height, width] = py_util::parse_resolution(resolution, "the texel points", 40);
            const int64_t count = uvs.shape(0);
            for (int64_t k = 0; k < 2 * count; ++k) {
                if (!std::isfinite(uvs.data()[k])) {
                    throw py::value_error("uvs[" + std::to_string(k / 2) + "] is NaN or Inf");
                }
            }
            const int32_t* index = triangles.data();
            for (int64_t k = 0; k < 3 * triangles.shape(0); ++k) {
                if (index[k] < 0 || index[k] >= count) {
                    throw py::value_error("triangles[" + std::to_string(k / 3) + "] indexes uv " +
                                          std::to_string(index[k]) + ", outside 0.." + std::to_string(count - 1));
                }
            }
            TexelPoints points;
            {
                py::gil_scoped_release release;
                points = texel_points(uvs.data(), index, triangles.shape(0), width, height);
            }
            return py::make_tuple(py_util::to_numpy(std::move(points.triangle), {height, width}),
                                  py_util::to_numpy(std::move(points.bary), {height, width, 3}),
                                  py_util::to_numpy(std::move(points.score), {height, width}));
        },
        py::arg("uvs"), py::arg("triangles"), py::arg("resolution"),
        R"doc(The surface point behind every texel of a UV layout.

Args:
    uvs (numpy.ndarray): (N, 2) UVs, used as float64.
    triangles (numpy.ndarray): (T, 3) integer indices into ``uvs``.
    resolution (int | tuple[int, int]): lightmap size, square or (height, width).

Returns:
    tuple: (triangle int64 (H, W), barycentrics float64 (H, W, 3), score
    float64 (H, W)). For each texel (row 0 at the top, v = 1), the triangle
    whose interior holds the texel's centre deepest (the largest smallest
    barycentric, negative outside; the first on a tie) among the triangles
    whose texel bounding box holds the texel, the centre's barycentrics
    there (not clamped) and that score; -inf (triangle 0, barycentrics 0)
    where no triangle with area reaches.

Raises:
    ValueError: bad shapes, indices out of range, NaN UVs, resolution <= 0.
)doc");
}

}  // namespace lmrefine::bindings
