#include <pybind11/pybind11.h>

#include <cmath>

#include <memory>
#include <tuple>
#include <vector>

#include "lmrefine/core/error.h"
#include "lmrefine/layout/gutter.h"
#include "lmrefine/layout/layout_check.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

py::dict report_dict(LayoutReport& r, bool relative_gutter, bool failing_charts) {
    py::dict out;
    out["flipped"] = r.flipped;
    out["degenerate"] = r.degenerate;
    out["overlapping"] = r.overlapping;
    out["out_of_bounds"] = r.out_of_bounds;
    out["min_gutter_texels"] = r.min_gutter_texels;
    out["charts"] = r.charts;
    out["valid"] = r.valid;
    if (relative_gutter) out["gutter_violations"] = r.gutter_violations;
    if (failing_charts) {
        const py::ssize_t n = py::ssize_t(r.failing_charts.size());
        out["failing_charts"] = py_util::to_numpy(std::move(r.failing_charts), {n});
        const py::ssize_t m = py::ssize_t(r.overlapping_charts.size());
        out["overlapping_charts"] = py_util::to_numpy(std::move(r.overlapping_charts), {m});
    }
    return out;
}

// The Python object owns copies of the original layout (small next to a
// lightmap) so the checker's view of it stays valid.
class PyLayoutChecker {
public:
    PyLayoutChecker(const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution,
                    const py::handle& padding_in) {
        auto uvs = py_util::require_points(uvs_in, "uvs", 2);
        auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
        std::tie(height_, width_) = py_util::parse_resolution(resolution, "a layout check");
        const double padding = py_util::real_param(padding_in, "padding");
        uvs_.assign(uvs.data(), uvs.data() + uvs.size());
        triangles_.assign(triangles.data(), triangles.data() + triangles.size());
        const UvLayout layout{uvs_.data(), uvs.shape(0), triangles_.data(), triangles.shape(0)};
        py::gil_scoped_release release;
        checker_ = std::make_unique<LayoutChecker>(layout, width_, height_, padding);
    }

    py::dict check(const py::handle& uvs_in, const py::handle& failing_charts_in,
                   const py::handle& relative_gutter_in) {
        const bool failing_charts = py_util::bool_param(failing_charts_in, "failing_charts");
        const bool relative_gutter = py_util::bool_param(relative_gutter_in, "relative_gutter");
        LayoutReport r;
        if (uvs_in.is_none()) {
            if (relative_gutter) {
                throw py::value_error("relative_gutter compares a warped layout with the original: pass uvs");
            }
            py::gil_scoped_release release;
            r = checker_->check_original(failing_charts);
        } else {
            auto uvs = py_util::require_points(uvs_in, "uvs", 2);
            if (uvs.shape(0) * 2 != py::ssize_t(uvs_.size())) {
                throw py::value_error("uvs has " + std::to_string(uvs.shape(0)) + " UVs but the original layout has " +
                                      std::to_string(uvs_.size() / 2) + "; pass a warped version of the same layout");
            }
            py::gil_scoped_release release;
            validate_layout({uvs.data(), uvs.shape(0), triangles_.data(), py::ssize_t(triangles_.size() / 3)});
            r = checker_->check(uvs.data(), failing_charts, relative_gutter);
        }
        return report_dict(r, relative_gutter, failing_charts);
    }

    py::array_t<bool> mask(std::vector<uint8_t> (*compute)(const LayoutChecker&)) {
        std::vector<uint8_t> mask;
        {
            py::gil_scoped_release release;
            mask = compute(*checker_);
        }
        auto bytes = py_util::to_numpy(std::move(mask), {height_, width_});
        return bytes.attr("view")(py::dtype::of<bool>()).cast<py::array_t<bool>>();
    }

    py::array_t<int32_t> owners() {
        std::vector<int32_t> owner;
        {
            py::gil_scoped_release release;
            owner = checker_->owners();
        }
        return py_util::to_numpy(std::move(owner), {height_, width_});
    }

    py::array_t<int32_t> charts() const {
        std::vector<int32_t> ids = checker_->charts().triangle_chart;
        const py::ssize_t n = py::ssize_t(ids.size());
        return py_util::to_numpy(std::move(ids), {n});
    }

private:
    std::vector<float> uvs_;
    std::vector<int32_t> triangles_;
    int width_ = 0, height_ = 0;
    std::unique_ptr<LayoutChecker> checker_;
};

std::vector<uint8_t> checker_coverage(const LayoutChecker& checker) { return coverage_mask(checker.raster()); }

std::vector<uint8_t> checker_gutter(const LayoutChecker& checker) {
    return gutter_texels(checker.owners(), checker.raster().width(), checker.raster().height());
}

py::dict check(const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution,
               const py::handle& padding_in, const py::handle& reference_in, const py::handle& failing_charts_in,
               const py::handle& relative_gutter_in, const py::handle& tolerance_in) {
    const bool failing_charts = py_util::bool_param(failing_charts_in, "failing_charts");
    const bool relative_gutter = py_util::bool_param(relative_gutter_in, "relative_gutter");
    const double tolerance = py_util::real_param(tolerance_in, "tolerance");
    auto uvs = py_util::require_points(uvs_in, "uvs", 2);
    auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
    const auto [height, width] = py_util::parse_resolution(resolution, "a layout check");
    const double padding = py_util::real_param(padding_in, "padding");
    py_util::FloatArray reference;
    if (!reference_in.is_none()) {
        reference = py_util::require_points(reference_in, "reference_uvs", 2);
        if (reference.shape(0) != uvs.shape(0)) {
            throw py::value_error("reference_uvs has " + std::to_string(reference.shape(0)) + " UVs but uvs has " +
                                  std::to_string(uvs.shape(0)) + "; pass the original layout of the same mesh");
        }
    }
    if (!(tolerance >= 0.0) || !std::isfinite(tolerance)) {
        throw py::value_error("tolerance must be a finite UV distance >= 0 (got " + std::to_string(tolerance) +
                              "); 0 joins bit-identical corners only");
    }
    UvLayout layout{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0)};
    LayoutReport r;
    {
        py::gil_scoped_release release;
        r = check_layout(layout, width, height, padding, reference_in.is_none() ? nullptr : reference.data(),
                         failing_charts, relative_gutter, tolerance);
    }
    return report_dict(r, relative_gutter, failing_charts);
}

py::array_t<bool> gutter(const py::handle& uvs, const py::handle& triangles, const py::handle& resolution) {
    return py_util::layout_mask(uvs, triangles, resolution,
                                [](const UvLayout& layout, int width, int height) {
                                    return gutter_texels(layout, width, height);
                                });
}

}  // namespace

void bind_layout_check(py::module_& m) {
    m.def("gutter_texels", &gutter, py::arg("uvs"), py::arg("triangles"), py::arg("resolution"),
          R"doc(Texels the refiner may shift but not compress: (H, W) bool, True for
texels no chart covers and texels next to (8-neighbourhood) a texel of
another owner (uncovered, another chart, or two charts). Pass as
``run_automaton(..., rigid=)`` so chart pairs do not get closer.
)doc");
    m.def("check_layout", &check, py::arg("uvs"), py::arg("triangles"), py::arg("resolution"),
          py::arg("padding") = 2.0, py::kw_only(), py::arg("reference_uvs") = py::none(),
          py::arg("failing_charts") = py::bool_(false), py::arg("relative_gutter") = py::bool_(false),
          py::arg("tolerance") = py::float_(0.0),
          R"doc(Check a UV layout for use as a lightmap layout at a resolution.

Args:
    uvs (numpy.ndarray): (N, 2) per-corner UVs.
    triangles (numpy.ndarray): (T, 3) integer indices into ``uvs``.
    resolution (int | tuple[int, int]): lightmap size, square or (height, width).
    padding (float): the smallest acceptable gutter between charts, in texels.
    reference_uvs (numpy.ndarray | None): the original layout (N, 2); with
        it, a triangle is flipped if its orientation differs from the
        original's, without it if it differs from most of its chart's.
    failing_charts (bool): also return ``failing_charts``, the ids of charts
        with a flipped, overlapping or newly degenerate triangle or too close
        to another chart.
    relative_gutter (bool): with ``reference_uvs``, judge the gutter per
        chart pair: a pair must stay at least min(padding, its distance in
        the reference) apart (less 1e-4 texel); adds ``gutter_violations``
        (pairs closer than that), and ``failing_charts`` then lists their
        charts rather than every chart closer than padding. ``valid`` stays
        absolute (min_gutter_texels >= padding).
    tolerance (float): charts are ``find_charts(..., tolerance=tolerance)``:
        corners closer than this UV distance join charts. 0 (default) joins
        bit-identical corners only; pass ``lmrefine.CHART_TOLERANCE`` for a
        Blender layout that was not welded (its islands are not bit-exact,
        so they would read as touching charts, gutter 0).

Returns:
    dict: flipped, degenerate (zero area to float precision), overlapping
    (triangles that share area with a triangle of another chart, tested
    exactly where their rasterizations meet), out_of_bounds (UVs outside
    [0, 1]), min_gutter_texels (exact smallest distance between two charts'
    boundaries in texels; inf with fewer than two charts), charts, and valid
    (nothing flipped, degenerate, overlapping or out of bounds, and
    min_gutter_texels >= padding). Charts are those of find_charts with the
    tolerance (of the reference layout when given).

Raises:
    ValueError: bad shapes, indices out of range, NaN UVs, resolution <= 0.
)doc");

    py::class_<PyLayoutChecker>(m, "LayoutChecker", R"doc(One original layout, analysed once for many checks.

The refiner checks the original, rasterizes it for its coverage and gutter
texels, and checks every warped version against it (back-off rounds). A
LayoutChecker computes what depends only on the original (charts,
orientations, rasterization, chart-pair distances) once; each result equals
the corresponding check_layout / coverage_mask / gutter_texels call exactly.

Args:
    uvs (numpy.ndarray): (N, 2) per-corner UVs of the original (copied).
    triangles (numpy.ndarray): (T, 3) integer indices into ``uvs`` (copied).
    resolution (int | tuple[int, int]): lightmap size, square or (height, width).
    padding (float): the smallest acceptable gutter between charts, in texels.

Raises:
    ValueError: bad shapes, indices out of range, NaN UVs, resolution <= 0,
        padding < 0.
)doc")
        .def(py::init<const py::handle&, const py::handle&, const py::handle&, const py::handle&>(), py::arg("uvs"),
             py::arg("triangles"), py::arg("resolution"), py::arg("padding") = 2.0)
        .def("check", &PyLayoutChecker::check, py::arg("uvs") = py::none(), py::kw_only(),
             py::arg("failing_charts") = py::bool_(false), py::arg("relative_gutter") = py::bool_(false),
             R"doc(check_layout of the original (uvs=None), or of a warped version of it.

With ``uvs`` (N, 2) (the original's triangles), the same as
``check_layout(uvs, triangles, resolution, padding, reference_uvs=original,
failing_charts=..., relative_gutter=...)``; without, the same as
``check_layout(original, triangles, resolution, padding,
failing_charts=...)``.
)doc")
        .def("coverage_mask", [](PyLayoutChecker& self) { return self.mask(checker_coverage); },
             "coverage_mask(original, triangles, resolution): (H, W) bool.")
        .def("gutter_texels", [](PyLayoutChecker& self) { return self.mask(checker_gutter); },
             "gutter_texels(original, triangles, resolution): (H, W) bool.")
        .def("texel_owners", &PyLayoutChecker::owners,
             R"doc((H, W) int32: per texel the chart (``charts``' id) of every triangle
covering it, -1 where none does, -2 where triangles of two charts do.)doc")
        .def_property_readonly("charts", &PyLayoutChecker::charts,
                               "find_charts(original, triangles): (T,) int32 chart id per triangle.");
}

}  // namespace lmrefine::bindings
