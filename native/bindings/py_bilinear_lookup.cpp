#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <string>

#include "lmrefine/core/memory.h"
#include "lmrefine/layout/bilinear_lookup.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

template <class T>
py::array_t<double> lookup(const py::array& image_in, const py::array_t<double, py::array::c_style>& uv) {
    auto image = py_util::contiguous<T>(image_in, "image");
    const int64_t height = image.shape(0), width = image.shape(1), channels = image.ndim() == 3 ? image.shape(2) : 1;
    const int64_t count = uv.shape(0);
    require_memory("the bilinear lookup of " + std::to_string(count) + " points",
                   saturating_product({uint64_t(count), uint64_t(channels), 8}), "pass fewer points");
    py::array_t<double> out({py::ssize_t(count), py::ssize_t(channels)});
    const T* pixels = image.data();
    const double* at = uv.data();
    double* values = out.mutable_data();
    {
        py::gil_scoped_release release;
        bilinear_lookup(pixels, width, height, channels, at, count, values);
    }
    return out;
}

}  // namespace

void bind_bilinear_lookup(py::module_& m) {
    m.def(
        "bilinear_lookup",
        [](const py::handle& image_in, const py::handle& uv_in) {
            if (!py::isinstance<py::array>(image_in)) {
                throw py::value_error("image must be a numpy array, got " +
                                      py::str(py::type::of(image_in).attr("__name__")).cast<std::string>());
            }
            const auto image = py::reinterpret_borrow<py::array>(image_in);
            const bool single = image.dtype().equal(py::dtype::of<float>());
            if (!single && !image.dtype().equal(py::dtype::of<double>())) {
                throw py::value_error("image must be float32 or float64, got " + py_util::dtype_name(image) +
                                      "; convert it with image.astype(numpy.float64)");
            }
            if (image.ndim() != 2 && image.ndim() != 3) {
                throw py::value_error("image must have shape (H, W) or (H, W, C), got " +
                                      py_util::shape_string(image));
            }
            for (py::ssize_t i = 0; i < image.ndim(); ++i) {
                if (image.shape(i) == 0) throw py::value_error("image is empty: shape " + py_util::shape_string(image));
            }
            if (!py::isinstance<py::array>(uv_in)) {
                throw py::value_error("uv must be a numpy array, got " +
                                      py::str(py::type::of(uv_in).attr("__name__")).cast<std::string>());
            }
            const auto uv_array = py::reinterpret_borrow<py::array>(uv_in);
            const char kind = uv_array.dtype().kind();
            if (kind != 'f' && kind != 'i' && kind != 'u') {
                throw py::value_error("uv must hold real numbers, got dtype " + py_util::dtype_name(uv_array));
            }
            if (uv_array.ndim() != 2 || uv_array.shape(1) != 2) {
                throw py::value_error("uv must have shape (P, 2), got " + py_util::shape_string(uv_array));
            }
            auto uv = py_util::contiguous<double>(uv_array, "uv");
            for (py::ssize_t k = 0; k < 2 * uv.shape(0); ++k) {
                if (std::isnan(uv.data()[k])) throw py::value_error("uv[" + std::to_string(k / 2) + "] is NaN");
            }
            return single ? lookup<float>(image, uv) : lookup<double>(image, uv);
        },
        py::arg("image"), py::arg("uv"),
        R"doc(Bilinear samples of an image at UVs, as a GPU sampler reads a lightmap.

Args:
    image (numpy.ndarray): (H, W) or (H, W, C) float32 (read in place) or
        float64, row 0 at the top (v = 1).
    uv (numpy.ndarray): (P, 2) UVs, any real dtype (used as float64); not
        NaN (+-Inf clamps to the border).

Returns:
    numpy.ndarray: (P, C) float64 (C = 1 for an (H, W) image): texel centres
    at ((j + .5) / W, 1 - (i + .5) / H), clamped to the border;
    bit-identical to the numpy reference in tests/test_metrics.py.

Raises:
    ValueError: a wrong dtype or shape, an empty image, a NaN UV.
)doc");
}

}  // namespace lmrefine::bindings
