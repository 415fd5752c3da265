#include <pybind11/pybind11.h>

#include <cmath>
#include <string>
#include <vector>

#include "lmrefine/layout/chart.h"
#include "lmrefine/layout/layout_raster.h"
#include "lmrefine/layout/texel_points.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

// (N, 2) UVs as float64, finite.
py::array_t<double, py::array::c_style> finite_uvs(const py::handle& object, const char* name) {
    auto uvs = py_util::contiguous<double>(object, name);
    if (uvs.ndim() != 2 || uvs.shape(1) != 2) {
        throw py::value_error(std::string(name) + " must have shape (N, 2), got " + py_util::shape_string(uvs));
    }
    for (int64_t k = 0; k < 2 * uvs.shape(0); ++k) {
        if (!std::isfinite(uvs.data()[k])) {
            throw py::value_error(std::string(name) + "[" + std::to_string(k / 2) + "] is NaN or Inf");
        }
    }
    return uvs;
}

// Every index of `triangles` in [0, count).
void require_in_range(const py_util::IndexArray& triangles, const char* name, int64_t count, const char* uvs_name) {
    const int32_t* index = triangles.data();
    for (int64_t k = 0; k < 3 * triangles.shape(0); ++k) {
        if (index[k] < 0 || index[k] >= count) {
            throw py::value_error(std::string(name) + "[" + std::to_string(k / 3) + "] indexes " + uvs_name + " " +
                                  std::to_string(index[k]) + ", outside 0.." + std::to_string(count - 1));
        }
    }
}

}  // namespace

void bind_texel_points(py::module_& m) {
    m.def(
        "texel_points",
        [](const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution) {
            auto uvs = finite_uvs(uvs_in, "uvs");
            auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
            // Every texel holds 8 + 24 + 8 bytes of output.
            const auto [height, width] = py_util::parse_resolution(resolution, "the texel points", 40);
            require_in_range(triangles, "triangles", uvs.shape(0), "uv");
            const int32_t* index = triangles.data();
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

    m.def(
        "carry_lightmap",
        [](const py::handle& lightmap_in, const py::handle& source_uvs_in, const py::handle& source_triangles_in,
           const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& mask_in) {
            auto lightmap = py_util::require_float32(lightmap_in, "lightmap", {2, 3});
            const int height = int(lightmap.shape(0)), width = int(lightmap.shape(1));
            const int channels = lightmap.ndim() == 3 ? int(lightmap.shape(2)) : 1;
            auto source_uvs = finite_uvs(source_uvs_in, "source_uvs");
            auto uvs = finite_uvs(uvs_in, "uvs");
            auto source_triangles = py_util::require_indices(source_triangles_in, "source_triangles", 3, true);
            auto triangles = py_util::require_indices(triangles_in, "triangles", 3, true);
            if (source_triangles.shape(0) != triangles.shape(0)) {
                throw py::value_error("source_triangles and triangles must be the same triangles, got " +
                                      std::to_string(source_triangles.shape(0)) + " and " +
                                      std::to_string(triangles.shape(0)));
            }
            require_in_range(source_triangles, "source_triangles", source_uvs.shape(0), "source_uvs row");
            require_in_range(triangles, "triangles", uvs.shape(0), "uvs row");
            if (!py::isinstance<py::array>(mask_in)) {
                throw py::value_error("mask must be a numpy array, got " +
                                      py::str(py::type::of(mask_in).attr("__name__")).cast<std::string>());
            }
            auto mask = py_util::contiguous<bool>(mask_in, "mask");
            if (mask.ndim() != 2 || mask.shape(0) != height || mask.shape(1) != width) {
                throw py::value_error("mask must have the lightmap's shape (" + std::to_string(height) + ", " +
                                      std::to_string(width) + "), got " + py_util::shape_string(mask));
            }
            // The texel points (40 bytes a texel), the source's texel owners and the output.
            py_util::parse_resolution(py::make_tuple(height, width), "the carried lightmap",
                                      44 + 4 * uint64_t(channels));
            std::vector<float> out;
            {
                py::gil_scoped_release release;
                // The source map's texels per chart, as the baker charts the layout it baked on.
                const std::vector<float> source_float(source_uvs.data(), source_uvs.data() + source_uvs.size());
                const UvLayout source{source_float.data(), source_uvs.shape(0), source_triangles.data(),
                                      source_triangles.shape(0)};
                const Charts charts = find_charts(source);
                const std::vector<int32_t> owner = texel_owners(LayoutRaster(source, width, height),
                                                                charts.triangle_chart);
                const TexelPoints points = texel_points(uvs.data(), triangles.data(), triangles.shape(0), width, height);
                out = carry_lightmap(points, reinterpret_cast<const uint8_t*>(mask.data()), source_uvs.data(),
                                     source_triangles.data(), charts.triangle_chart.data(), owner.data(),
                                     lightmap.data(), width, height, channels);
            }
            std::vector<py::ssize_t> shape(lightmap.shape(), lightmap.shape() + lightmap.ndim());
            return py_util::to_numpy(std::move(out), shape);
        },
        py::arg("lightmap"), py::arg("source_uvs"), py::arg("source_triangles"), py::arg("uvs"),
        py::arg("triangles"), py::arg("mask"),
        R"doc(A lightmap carried from one layout of a mesh to another (the re-chart route).

Args:
    lightmap (numpy.ndarray): (H, W) or (H, W, C) float32, baked on the source layout.
    source_uvs (numpy.ndarray): (N, 2) UVs of the source layout, used as float64.
    source_triangles (numpy.ndarray): (T, 3) indices into ``source_uvs``.
    uvs (numpy.ndarray): (M, 2) UVs of the new layout, used as float64.
    triangles (numpy.ndarray): (T, 3) indices into ``uvs``, the same triangles.
    mask (numpy.ndarray): (H, W) bool, the texels to fill (the new layout's coverage).

Returns:
    numpy.ndarray: float32 of the lightmap's shape: each texel of ``mask``
    holds the value of ``lightmap`` at the same surface point (the texel's
    centre in the triangle texel_points gives it, barycentrics clamped into
    that triangle), read from the texels of that triangle's source chart
    (texel_owners of the source layout, charts as the baker finds them): the
    bilinear value where the chart owns all four texels, else the weights
    of those it owns renormalized, else its nearest texel within two, else
    the bilinear value; 0 elsewhere. Bit-identical to the numpy reference in
    tests/test_rechart_route.py.

Raises:
    ValueError: bad shapes, indices out of range, NaN UVs, a mask of another shape.
)doc");
}

}  // namespace lmrefine::bindings
