// The native half of lmrefine.trace_rays (python/lmrefine/baker.py): the closest hit of camera rays (python/lmrefine/surface_view.py
// shades them with a lightmap lookup).
#include <pybind11/pybind11.h>

#include <string>

#include "lmrefine/bake/primary_rays.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

py::tuple trace_rays(const Scene& scene, const py::handle& origins_in, const py::handle& directions_in,
                     const py::object& progress) {
    auto origins = py_util::require_points(origins_in, "origins", 3);
    auto directions = py_util::require_points(directions_in, "directions", 3);
    if (directions.shape(0) != origins.shape(0)) {
        throw py::value_error("directions must have one row per origin: origins " + py_util::shape_string(origins) +
                              ", directions " + py_util::shape_string(directions));
    }
    const int64_t count = origins.shape(0);
    py_util::PythonProgress reporter(progress);
    const Scene::Reading reading(scene);
    PrimaryHits hits = reporter.run(
        [&](Progress& p) { return trace_primary_rays(scene, origins.data(), directions.data(), count, p); });
    const py::ssize_t n = py::ssize_t(count);
    return py::make_tuple(py_util::to_numpy(std::move(hits.mesh), {n}),
                          py_util::to_numpy(std::move(hits.triangle), {n}),
                          py_util::to_numpy(std::move(hits.barycentric), {n, 2}),
                          py_util::to_numpy(std::move(hits.distance), {n}));
}

}  // namespace

void bind_primary_rays(py::module_& m) {
    m.def("_trace_rays", &trace_rays, py::arg("scene"), py::arg("origins"), py::arg("directions"),
          py::arg("progress") = py::none(),
          "Native primary rays: returns (mesh, triangle, barycentric, distance). Use lmrefine.trace_rays.");
}

}  // namespace lmrefine::bindings
