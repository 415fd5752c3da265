#include <pybind11/pybind11.h>

#include <optional>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/gradient/gradient_map.h"
#include "lmrefine/gradient/wavelet.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

using BoolArray = py::array_t<bool, py::array::c_style>;

py::array_t<float> compute(const py::handle& image_in, const py::handle& mask_in, const py::handle& wavelet_in,
                           const py::object& callback) {
    const Wavelet wavelet = parse_wavelet(py_util::string_param(wavelet_in, "wavelet"));
    auto image = py_util::require_float32(image_in, "image", {2, 3});
    const int64_t height = image.shape(0), width = image.shape(1);
    const int channels = image.ndim() == 3 ? int(image.shape(2)) : 1;
    if (image.ndim() == 3 && channels != 1 && channels != 3 && channels != 4) {
        throw py::value_error("image must be (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got shape " +
                              py_util::shape_string(image));
    }
    std::optional<BoolArray> mask;
    if (!mask_in.is_none()) {
        if (!py::isinstance<py::array>(mask_in)) throw py::value_error("mask must be a numpy bool array or None");
        auto raw = py::reinterpret_borrow<py::array>(mask_in);
        if (!raw.dtype().equal(py::dtype::of<bool>())) {  // equal: unpickled arrays have their own dtype
            throw py::value_error("mask must be bool (True = covered), got " + py_util::dtype_name(raw) +
                                  "; use lmrefine.coverage_mask(uvs, triangles, resolution) or mask.astype(bool)");
        }
        if (raw.ndim() != 2 || raw.shape(0) != height || raw.shape(1) != width) {
            throw py::value_error("mask must have the image's shape (" + std::to_string(height) + ", " +
                                  std::to_string(width) + "), got " + py_util::shape_string(raw));
        }
        mask = py_util::contiguous<bool>(raw, "mask");
    }
    // bool and uint8 share a layout.
    const uint8_t* mask_data = mask ? reinterpret_cast<const uint8_t*>(mask->data()) : nullptr;
    // numpy's own buffer, left uninitialized: gradient_map writes every value.
    py::array_t<float> out({py::ssize_t(height), py::ssize_t(width), py::ssize_t(4)});
    float* out_data = out.mutable_data();
    py_util::PythonProgress progress(callback);
    progress.run([&](Progress& p) {
        gradient_map(image.data(), height, width, channels, mask_data, wavelet, out_data, &p);
        return 0;
    });
    return out;
}

}  // namespace

void bind_gradient_map(py::module_& m) {
    m.def("gradient_map", &compute, py::arg("image"), py::arg("mask") = py::none(), py::arg("wavelet") = "d4",
          py::arg("progress") = py::none(),
          R"doc(The thesis' gradient map: how fast the light changes at every texel, per direction.

The magnitude of the wavelet detail (the modified, absolute-value predict)
evaluated at every texel (undecimated: a one-texel shift of the image
shifts the map and changes nothing else).

Args:
    image (numpy.ndarray): float32 lightmap (H, W) or (H, W, 1|3|4), linear
        light, any range (HDR is fine). RGB(A) is reduced to Rec.709
        luminance 0.2126 R + 0.7152 G + 0.0722 B; alpha is ignored (coverage
        comes from ``mask``). Any size >= 1x1, odd sizes included; a line of
        one covered texel has no neighbours and gives 0.
    mask (numpy.ndarray | None): bool (H, W), True = covered by a chart, as
        lmrefine.coverage_mask returns; None = every texel covered.
    wavelet (str): 'd4' (the thesis' choice), 'haar', 'd12', 'd20', 'cdf53'
        or 'cdf97': its detail (high-pass) filter is used.
    progress (callable | None): progress(fraction, stage) -> bool; False cancels.

Returns:
    numpy.ndarray: float32 (H, W, 4).
    r (0): light changing along y, filter scanning down the columns;
    g (1): along x, scanning along the rows (left to right);
    b (2): along y, scanning up; a (3): along x, scanning right to left.
    Uncovered texels are 0 in every channel and are never read for a
    covered one; each run of covered texels is extended point-symmetrically
    past its ends (a linear ramp continues exactly), at mask borders and at
    the image border alike (no wrap-around).

Raises:
    ValueError: wrong dtype or shape, empty image, mask of another shape or
        dtype, a mask that covers nothing, NaN/Inf inside the covered area
        (the message names how many and the first one), unknown wavelet.
    lmrefine.CancelledError: the progress callback returned False.
)doc");
}

}  // namespace lmrefine::bindings
