#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "lmrefine/core/error.h"
#include "lmrefine/gradient/wavelet.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

using py_util::FloatArray;

std::vector<FloatArray> unpack_bands(const py::handle& coeffs, size_t count, const char* names,
                                     std::initializer_list<int> ndims) {
    if (!py::isinstance<py::sequence>(coeffs) || py::isinstance<py::str>(coeffs) ||
        py::len(coeffs) != count) {
        throw py::value_error(std::string("coeffs must be a tuple ") + names + " of float32 arrays");
    }
    auto sequence = py::reinterpret_borrow<py::sequence>(coeffs);
    static const char* kLabels[] = {"coeffs[0]", "coeffs[1]", "coeffs[2]", "coeffs[3]"};
    std::vector<FloatArray> bands;
    for (size_t i = 0; i < count; ++i) {
        bands.push_back(py_util::require_float32(sequence[i], kLabels[i], ndims));
        if (i && py_util::shape_string(bands[i]) != py_util::shape_string(bands[0])) {
            throw py::value_error(std::string("all sub-bands ") + names + " must have one shape, got " +
                                  py_util::shape_string(bands[0]) + " and " + py_util::shape_string(bands[i]));
        }
    }
    return bands;
}

py::tuple dwt_1d(const py::handle& signal_in, const py::handle& wavelet_in, const py::handle& mode_in) {
    const Wavelet wavelet = parse_wavelet(py_util::string_param(wavelet_in, "wavelet"));
    const BoundaryMode mode = parse_boundary_mode(py_util::string_param(mode_in, "mode"));
    auto signal = py_util::require_float32(signal_in, "signal", {1});
    const int64_t length = signal.shape(0);
    std::vector<float> approx(size_t(length / 2)), detail(size_t(length / 2));
    {
        py::gil_scoped_release release;
        dwt(signal.data(), length, wavelet, mode, approx.data(), detail.data());
    }
    return py::make_tuple(py_util::to_numpy(std::move(approx), {length / 2}),
                          py_util::to_numpy(std::move(detail), {length / 2}));
}

py::array_t<float> idwt_1d(const py::handle& coeffs, const py::handle& wavelet_in, const py::handle& mode_in) {
    const Wavelet wavelet = parse_wavelet(py_util::string_param(wavelet_in, "wavelet"));
    const BoundaryMode mode = parse_boundary_mode(py_util::string_param(mode_in, "mode"));
    auto bands = unpack_bands(coeffs, 2, "(approx, detail)", {1});
    const int64_t half = bands[0].shape(0);
    std::vector<float> signal(size_t(2 * half));
    {
        py::gil_scoped_release release;
        idwt(bands[0].data(), bands[1].data(), half, wavelet, mode, signal.data());
    }
    return py_util::to_numpy(std::move(signal), {2 * half});
}

py::tuple dwt_2d(const py::handle& image_in, const py::handle& wavelet_in, const py::handle& mode_in,
                 const py::object& callback) {
    const Wavelet wavelet = parse_wavelet(py_util::string_param(wavelet_in, "wavelet"));
    const BoundaryMode mode = parse_boundary_mode(py_util::string_param(mode_in, "mode"));
    auto image = py_util::require_float32(image_in, "image", {2});
    const int64_t height = image.shape(0), width = image.shape(1);
    const py::ssize_t hh = height / 2, hw = width / 2;
    // numpy's own buffers, left uninitialized: dwt2 writes every value
    // (and checks the sizes before it starts).
    py::array_t<float> ll({hh, hw}), lh({hh, hw}), hl({hh, hw}), hhb({hh, hw});
    float *pll = ll.mutable_data(), *plh = lh.mutable_data(), *phl = hl.mutable_data(), *phh = hhb.mutable_data();
    py_util::PythonProgress progress(callback);
    progress.run([&](Progress& p) {
        dwt2(image.data(), height, width, wavelet, mode, pll, plh, phl, phh, &p);
        return 0;
    });
    return py::make_tuple(ll, lh, hl, hhb);
}

py::array_t<float> idwt_2d(const py::handle& coeffs, const py::handle& wavelet_in, const py::handle& mode_in,
                           const py::object& callback) {
    const Wavelet wavelet = parse_wavelet(py_util::string_param(wavelet_in, "wavelet"));
    const BoundaryMode mode = parse_boundary_mode(py_util::string_param(mode_in, "mode"));
    auto bands = unpack_bands(coeffs, 4, "(LL, LH, HL, HH)", {2});
    const py::ssize_t hh = bands[0].shape(0), hw = bands[0].shape(1);
    py::array_t<float> image({2 * hh, 2 * hw});  // uninitialized: idwt2 writes every value
    float* out = image.mutable_data();
    py_util::PythonProgress progress(callback);
    progress.run([&](Progress& p) {
        idwt2(bands[0].data(), bands[1].data(), bands[2].data(), bands[3].data(), hh, hw, wavelet, mode, out, &p);
        return 0;
    });
    return image;
}

}  // namespace

void bind_wavelet(py::module_& m) {
    m.def("dwt", &dwt_1d, py::arg("signal"), py::arg("wavelet") = "d4", py::arg("mode") = "periodic",
          R"doc(One-level 1-D wavelet transform by lifting.

Args:
    signal (numpy.ndarray): float32 of shape (N,), N even and >= 2.
    wavelet (str): 'haar', 'd4', 'd12', 'd20', 'cdf53' or 'cdf97'.
    mode (str): 'periodic' (the signal wraps) or 'symmetric' (mirrored about
        its end samples, x[-k] = x[k]).

Returns:
    tuple[numpy.ndarray, numpy.ndarray]: (approx, detail), float32 (N/2,) each.
    For 'd4' with 'periodic', approx[n] = sum_k h[k] x[2n+k] with
    h = (1+sqrt3, 3+sqrt3, 3-sqrt3, 1-sqrt3)/(4 sqrt2); relation to
    PyWavelets: see docs/wavelets.md.

Raises:
    ValueError: not float32, not 1-D, odd or too short, unknown name.
)doc");
    m.def("idwt", &idwt_1d, py::arg("coeffs"), py::arg("wavelet") = "d4", py::arg("mode") = "periodic",
          R"doc(Inverse of dwt: (approx, detail) -> float32 signal of shape (2 * len(approx),).

Args:
    coeffs (tuple[numpy.ndarray, numpy.ndarray]): float32 (M,) each, as dwt returns.
    wavelet (str), mode (str): as given to dwt.
)doc");
    m.def("dwt2", &dwt_2d, py::arg("image"), py::arg("wavelet") = "d4", py::arg("mode") = "periodic",
          py::arg("progress") = py::none(),
          R"doc(One-level separable 2-D wavelet packet decomposition by lifting.

Rows are filtered along x (axis 1), then columns along y (axis 0). The first
letter of a sub-band is its filter along x, the second along y:
LL = low x, low y; LH = low x, high y (light changing along y, horizontal
edges; PyWavelets' cH); HL = high x, low y (vertical edges; cV); HH = both
high (cD).

Args:
    image (numpy.ndarray): float32 of shape (H, W), H and W even and >= 2
        (each level halves both sizes, so odd sizes are refused).
    wavelet (str): 'haar', 'd4', 'd12', 'd20', 'cdf53' or 'cdf97'.
    mode (str): 'periodic' or 'symmetric' (see dwt).
    progress (callable | None): progress(fraction, stage) -> bool; False cancels.

Returns:
    tuple: (LL, LH, HL, HH), float32 arrays of shape (H/2, W/2).

Raises:
    ValueError: not float32, not 2-D, empty, odd sizes, unknown name.
    lmrefine.CancelledError: the progress callback returned False.
)doc");
    m.def("idwt2", &idwt_2d, py::arg("coeffs"), py::arg("wavelet") = "d4", py::arg("mode") = "periodic",
          py::arg("progress") = py::none(),
          R"doc(Inverse of dwt2: (LL, LH, HL, HH) -> float32 image of shape (2h, 2w).

Args:
    coeffs (tuple): four float32 arrays of one shape (h, w), as dwt2 returns
        (they are not modified).
    wavelet (str), mode (str): as given to dwt2.
    progress (callable | None): progress(fraction, stage) -> bool; False cancels.
)doc");
}

}  // namespace lmrefine::bindings
