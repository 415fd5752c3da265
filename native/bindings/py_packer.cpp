#include <pybind11/pybind11.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/layout/chart.h"
#include "lmrefine/pack/packer.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

// The layout's total triangle area in UV units (the atlas is 1): its chart
// area, whatever the texel grid; overlapping triangles count twice.
double uv_area(const UvLayout& layout) {
    double area = 0.0;
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        const int32_t* tri = layout.triangles + 3 * t;
        const double ax = layout.uvs[2 * tri[0]], ay = layout.uvs[2 * tri[0] + 1];
        const double bx = layout.uvs[2 * tri[1]] - ax, by = layout.uvs[2 * tri[1] + 1] - ay;
        const double cx = layout.uvs[2 * tri[2]] - ax, cy = layout.uvs[2 * tri[2] + 1] - ay;
        area += 0.5 * std::abs(bx * cy - by * cx);
    }
    return area;
}

double utilisation(const UvLayout& layout, int width, int height) {
    const std::vector<uint8_t> mask = coverage_mask(layout, width, height);
    int64_t covered = 0;
    for (uint8_t m : mask) covered += m;
    return double(covered) / (double(width) * height);
}

py::tuple pack(const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution,
                  const py::handle& padding_in, const py::handle& charts_in, const py::handle& scales_in,
                  const py::handle& rotate_in, py::object progress_callback, const py::handle& tolerance_in,
                  const py::handle& subdivision_in, const py::handle& boxes_in, const py::handle& fixed_scale_in) {
    const double padding = py_util::real_param(padding_in, "padding");
    const bool rotate = py_util::bool_param(rotate_in, "rotations");
    const double tolerance = py_util::real_param(tolerance_in, "tolerance");
    const int subdivision = int(py_util::int_param(subdivision_in, "subdivision", 1, 8));
    const bool boxes = py_util::bool_param(boxes_in, "boxes");
    const double fixed_scale = fixed_scale_in.is_none() ? 0.0 : py_util::real_param(fixed_scale_in, "fixed_scale");
    if (!fixed_scale_in.is_none() && !(fixed_scale > 0.0)) {
        throw py::value_error("fixed_scale must be a finite global scale > 0, or None to search it (got " +
                              std::to_string(fixed_scale) + ")");
    }
    const auto start = std::chrono::steady_clock::now();
    auto uvs = py_util::require_points(uvs_in, "uvs", 2, /*allow_empty=*/true);
    auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
    PackOptions options;
    std::tie(options.height, options.width) = py_util::parse_resolution(resolution, "a packed atlas");
    options.padding = padding;
    options.rotate = rotate;
    options.weld_tolerance = tolerance;
    options.subdivision = subdivision;
    options.boxes = boxes;
    options.fixed_scale = fixed_scale;
    if (!(padding >= 0.0) || !std::isfinite(padding)) {
        throw py::value_error("padding must be a finite number of texels >= 0 (got " + std::to_string(padding) + ")");
    }
    if (!(tolerance >= 0.0) || !std::isfinite(tolerance)) {
        throw py::value_error("tolerance must be a finite UV distance >= 0 (got " + std::to_string(tolerance) + ")");
    }
    const UvLayout layout{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0)};
    validate_layout(layout);

    std::vector<int32_t> chart_ids;
    int32_t chart_count = 0;
    if (charts_in.is_none()) {
        Charts charts = find_charts(layout, tolerance);
        chart_ids = std::move(charts.triangle_chart);
        chart_count = charts.count;
    } else {
        std::tie(chart_ids, chart_count) = py_util::require_chart_ids(charts_in, layout.triangle_count);
    }
    std::vector<double> scales(size_t(chart_count), 1.0);
    if (!scales_in.is_none()) {
        py::array array = py::array::ensure(scales_in);
        if (!array || (array.dtype().kind() != 'f' && array.dtype().kind() != 'i' && array.dtype().kind() != 'u')) {
            throw py::value_error("scales must be a real array, one scale per chart");
        }
        if (array.ndim() != 1 || array.shape(0) != chart_count) {
            throw py::value_error("scales must have shape (" + std::to_string(chart_count) + ",): one scale per chart, got " +
                                  py_util::shape_string(array));
        }
        py::array_t<double, py::array::c_style | py::array::forcecast> values(array);
        for (int32_t c = 0; c < chart_count; ++c) {
            const double s = values.data()[c];
            if (!(s > 0.0) || !std::isfinite(s)) {
                throw py::value_error("scales must be finite and > 0: scales[" + std::to_string(c) + "] is " + std::to_string(s));
            }
            scales[size_t(c)] = s;
        }
    }

    py_util::PythonProgress progress(std::move(progress_callback));
    double utilisation_in = 0, utilisation_out = 0, area_in = 0, area_out = 0;
    PackResult result = progress.run([&](Progress& p) {
        PackResult r = pack_charts(layout, chart_ids, chart_count, scales, options, &p);
        const UvLayout out{r.uvs.data(), layout.uv_count, layout.triangles, layout.triangle_count};
        utilisation_out = utilisation(out, options.width, options.height);
        utilisation_in = utilisation(layout, options.width, options.height);
        area_out = uv_area(out);
        area_in = uv_area(layout);
        return r;
    });

    py::dict report;
    report["utilisation"] = utilisation_out;
    report["utilisation_input"] = utilisation_in;
    report["area_utilisation"] = area_out;
    report["area_utilisation_input"] = area_in;
    report["global_scale"] = result.global_scale;
    report["scale_bound"] = result.scale_bound;
    std::vector<double> chart_scales(scales);
    for (double& s : chart_scales) s *= result.global_scale;
    report["chart_scales"] = py_util::to_numpy(std::move(chart_scales), {py::ssize_t(chart_count)});
    report["rotations"] = py_util::to_numpy(std::move(result.rotations), {py::ssize_t(chart_count)});
    report["transforms"] = py_util::to_numpy(std::move(result.transforms), {py::ssize_t(chart_count), 2, 3});
    report["chart_ids"] = py_util::to_numpy(std::move(chart_ids), {py::ssize_t(layout.triangle_count)});
    report["charts"] = chart_count;
    report["trials"] = result.trials;
    report["footprint_texels"] = result.footprint_texels;
    report["placement"] = result.boxes ? "boxes" : "footprints";
    report["padding"] = padding;
    report["resolution"] = py::make_tuple(options.height, options.width);
    py::array_t<float> uvs_out = py_util::to_numpy(std::move(result.uvs), {py::ssize_t(layout.uv_count), 2});
    report["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return py::make_tuple(uvs_out, report);
}

}  // namespace

void bind_packer(py::module_& m) {
    m.def(
        "_first_fit",
        [](const py::array_t<uint8_t, py::array::c_style | py::array::forcecast>& occupied,
           const py::array_t<uint8_t, py::array::c_style | py::array::forcecast>& chart, double padding,
           int first_row) -> py::object {
            if (occupied.ndim() != 2 || chart.ndim() != 2 || chart.shape(0) < 1 || chart.shape(1) < 1 ||
                occupied.shape(0) < 1 || occupied.shape(1) < 1) {
                throw py::value_error("occupied and chart must be non-empty 2-D masks");
            }
            if (!(padding >= 0.0) || padding > 1e4) throw py::value_error("padding must be in [0, 1e4] texels");
            if (first_row < 0) throw py::value_error("first_row must be >= 0");
            // The kernel's masks hold 0 or 1; any nonzero value here is covered.
            std::vector<uint8_t> atlas(size_t(occupied.size())), bits(size_t(chart.size()));
            std::transform(occupied.data(), occupied.data() + occupied.size(), atlas.begin(),
                           [](uint8_t v) { return uint8_t(v != 0); });
            std::transform(chart.data(), chart.data() + chart.size(), bits.begin(), [](uint8_t v) { return uint8_t(v != 0); });
            int x = 0, y = 0;
            if (!first_fit_position(atlas, int(occupied.shape(1)), int(occupied.shape(0)), bits, int(chart.shape(1)),
                                    int(chart.shape(0)), padding, x, y, first_row)) {
                return py::none();
            }
            return py::make_tuple(x, y);
        },
        py::arg("occupied"), py::arg("chart"), py::arg("padding"), py::arg("first_row") = 0,
        "The packer's placement rule on masks (tests): the first (x, y) in scan order, from row `first_row` "
        "on, where `chart` fits `occupied` with the padding, or None.");
    m.def(
        "_footprint_masks",
        [](const py::array_t<uint8_t, py::array::c_style | py::array::forcecast>& chart, double padding, bool turned) {
            if (chart.ndim() != 2 || chart.shape(0) < 1 || chart.shape(1) < 1) {
                throw py::value_error("chart must be a non-empty 2-D mask");
            }
            if (!(padding >= 0.0) || padding > 64.0) throw py::value_error("padding must be in [0, 64] texels");
            std::vector<uint8_t> bits(size_t(chart.size()));
            std::transform(chart.data(), chart.data() + chart.size(), bits.begin(), [](uint8_t v) { return uint8_t(v != 0); });
            FootprintMasks masks = footprint_masks(bits, int(chart.shape(1)), int(chart.shape(0)), padding, turned);
            const py::ssize_t h = masks.height, w = masks.width, grown = 2 * py::ssize_t(masks.reach);
            return py::make_tuple(py_util::to_numpy(std::move(masks.covered), {h, w}),
                                  py_util::to_numpy(std::move(masks.dilated), {h + grown, w + grown}));
        },
        py::arg("chart"), py::arg("padding"), py::arg("turned") = false,
        "The packer's footprint of a mask (tests): (covered, dilated) as 0/1 uint8 masks, the chart turned a "
        "quarter counter-clockwise when `turned`, the dilation by `padding` with the chart at (reach, reach).");
    m.def("pack_charts", &pack, py::arg("uvs"), py::arg("triangles"), py::arg("resolution"), py::arg("padding") = py::float_(2.0),
          py::kw_only(), py::arg("charts") = py::none(), py::arg("scales") = py::none(),
          py::arg("rotate") = py::bool_(true), py::arg("progress") = py::none(), py::arg("tolerance") = py::float_(1e-5),
          py::arg("subdivision") = py::int_(2), py::arg("boxes") = py::bool_(true), py::arg("fixed_scale") = py::none(),
          R"doc(The atlas packer's native entry; use lmrefine.pack_charts (python/lmrefine/packer.py,
documented there and in docs/packer.md). Returns (uvs, report).)doc");
}

}  // namespace lmrefine::bindings
