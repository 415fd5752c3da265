#include <pybind11/pybind11.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "lmrefine/chart/rechart.h"
#include "lmrefine/core/error.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

py::tuple rechart_mesh(const py::handle& positions_in, const py::handle& triangles_in, const py::handle& angle_in,
                       const py::handle& weld_tolerance_in, py::object progress_callback, const py::handle& normals_in,
                       const py::handle& smooth_angle_in, const py::handle& polygons_in) {
    RechartOptions options;
    options.angle_degrees = py_util::real_param(angle_in, "angle");
    options.smooth_angle_degrees = py_util::real_param(smooth_angle_in, "smooth_angle");
    if (!weld_tolerance_in.is_none()) {
        options.weld_tolerance = py_util::real_param(weld_tolerance_in, "weld_tolerance");
        if (!(options.weld_tolerance >= 0.0)) {
            throw py::value_error("weld_tolerance must be a distance >= 0, or None for 1e-6 of the mesh's size (got " +
                                  std::to_string(options.weld_tolerance) + ")");
        }
    }
    auto positions = py_util::require_points(positions_in, "positions", 3);
    auto triangles = py_util::require_indices(triangles_in, "triangles", 3);
    SurfaceMesh mesh{positions.data(), positions.shape(0), triangles.data(), triangles.shape(0)};
    // Shading normals per vertex (V, 3) or per corner (T*3, 3); the core reads them per corner.
    std::vector<float> corner_normals;
    if (!normals_in.is_none()) {
        auto normals = py_util::require_points(normals_in, "normals", 3, true);
        const py::ssize_t count = normals.shape(0), corners = 3 * triangles.shape(0);
        if (count != corners && count != positions.shape(0)) {
            throw py::value_error("normals must be per vertex (" + std::to_string(positions.shape(0)) +
                                  ", 3) or per corner (" + std::to_string(corners) + ", 3), got (" +
                                  std::to_string(count) + ", 3)");
        }
        const float* n = normals.data();
        corner_normals.resize(size_t(3 * corners));
        for (py::ssize_t c = 0; c < corners; ++c) {
            // An index out of range reads a zero normal here; the core then rejects the triangle.
            const int64_t row = count == corners ? int64_t(c) : int64_t(triangles.data()[c]);
            const bool inside = row >= 0 && row < int64_t(count);
            for (int k = 0; k < 3; ++k) corner_normals[size_t(3 * c + k)] = inside ? n[3 * row + k] : 0.0f;
        }
        mesh.corner_normals = corner_normals.data();
    }
    // Polygon ids are labels: any int32 value, one per triangle.
    std::vector<int32_t> polygons;
    if (!polygons_in.is_none()) {
        py::array array = py::array::ensure(polygons_in);
        if (!array || (array.dtype().kind() != 'i' && array.dtype().kind() != 'u')) {
            throw py::value_error("polygons must be an integer array: one polygon id per triangle");
        }
        if (array.ndim() != 1 || array.shape(0) != triangles.shape(0)) {
            throw py::value_error("polygons must have shape (" + std::to_string(triangles.shape(0)) +
                                  ",): one polygon id per triangle, got " + py_util::shape_string(array));
        }
        const auto wide = py_util::wide_integers(array, "polygons");
        polygons.resize(size_t(triangles.shape(0)));
        for (py::ssize_t t = 0; t < wide.size(); ++t) {
            const int64_t id = wide.data()[t];
            if (id < std::numeric_limits<int32_t>::min() || id > std::numeric_limits<int32_t>::max()) {
                throw py::value_error("polygons[" + std::to_string(t) + "] is " + py_util::element_text(array, t) +
                                      ", outside the int32 range: number the polygons 0..P-1");
            }
            polygons[size_t(t)] = int32_t(id);
        }
        mesh.polygons = polygons.data();
    }
    py_util::PythonProgress progress(std::move(progress_callback));
    RechartResult result = progress.run([&](Progress& p) { return rechart(mesh, options, &p); });
    py::dict report;
    report["charts"] = result.chart_count;
    report["grown_charts"] = result.grown_charts;
    report["split_charts"] = result.split_charts;
    report["degenerate_triangles"] = result.degenerate;
    report["welded_vertices"] = result.welded_vertices;
    const py::ssize_t count = py::ssize_t(mesh.triangle_count);
    return py::make_tuple(py_util::to_numpy(std::move(result.uvs), {3 * count, 2}),
                          py_util::to_numpy(std::move(result.triangle_chart), {count}), report);
}

}  // namespace

void bind_rechart(py::module_& m) {
    m.def("rechart_mesh", &rechart_mesh, py::arg("positions"), py::arg("triangles"), py::arg("angle") = 10.0,
          py::arg("weld_tolerance") = py::none(), py::arg("progress") = py::none(), py::arg("normals") = py::none(),
          py::arg("smooth_angle") = 45.0, py::arg("polygons") = py::none(),
          R"doc(Charts of a mesh, each unwrapped with a least-squares conformal map (not packed).

lmrefine.rechart is the public entry (it packs the charts too).

Args:
    positions (numpy.ndarray): (V, 3) vertex positions.
    triangles (numpy.ndarray): (T, 3) integer indices into ``positions``.
    angle (float): largest angle in degrees, in (0, 90), between a chart's
        face normals and its first (largest) face's.
    weld_tolerance (float or None): positions closer than this are one
        vertex; None: 1e-6 of the diagonal of the mesh's bounding box.
    progress: callable ``progress(fraction, stage)``; False cancels.
    normals (numpy.ndarray or None): shading normals, (V, 3) per vertex or
        (T*3, 3) per corner. An edge whose two faces have the same normals
        at both its ends is smooth-shaded; None: every edge is hard.
    smooth_angle (float): the angle in (0, 90) used instead of ``angle``
        across smooth-shaded edges.
    polygons (numpy.ndarray or None): (T,) integer polygon id per
        triangle: triangles with one id (a quad's or an n-gon's, which
        share their corners' UVs) always join one chart.

Returns:
    (uvs, charts, report): uvs float32 (3T, 2), corner k of triangle t at
    row 3t + k, in world units (every chart's UV area is its world area);
    charts int32 (T,); report dict (charts, grown_charts, split_charts,
    degenerate_triangles, welded_vertices).

Raises:
    ValueError: bad shapes, indices out of range, non-finite positions, no
        triangle with an area, an angle outside (0, 90).
)doc");
}

}  // namespace lmrefine::bindings
