#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/core/image_io.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

PixelFormat parse_format(const std::optional<std::string>& format) {
    if (!format) return PixelFormat::Auto;
    if (*format == "half") return PixelFormat::Half;
    if (*format == "float") return PixelFormat::Float;
    if (*format == "uint8") return PixelFormat::UInt8;
    if (*format == "uint16") return PixelFormat::UInt16;
    throw py::value_error("format must be None, 'half', 'float', 'uint8' or 'uint16', got '" + *format + "'");
}

py::object read(const py::object& path) {
    const std::string file = py_util::path_param(path, "path");
    ImageBuffer image;
    {
        py::gil_scoped_release release;
        image = read_image(file);
    }
    return py_util::to_numpy(std::move(image.pixels), {image.height, image.width, image.channels});
}

void write(const py::object& path, const py::handle& array, const py::handle& format_in,
           const py::handle& srgb_in) {
    std::optional<std::string> format;
    if (!format_in.is_none()) format = py_util::string_param(format_in, "format");
    std::optional<bool> srgb;
    if (!srgb_in.is_none()) srgb = py_util::bool_param(srgb_in, "srgb");
    const std::string file = py_util::path_param(path, "path");
    auto pixels = py_util::require_float32(array, "array", {2, 3});
    WriteOptions options;
    options.format = parse_format(format);
    if (srgb) options.srgb = *srgb ? WriteOptions::Srgb::On : WriteOptions::Srgb::Off;
    const int height = int(pixels.shape(0)), width = int(pixels.shape(1));
    const int channels = pixels.ndim() == 3 ? int(pixels.shape(2)) : 1;
    const float* data = pixels.data();
    py::gil_scoped_release release;
    write_image(file, data, height, width, channels, options);
}

}  // namespace

void bind_image_io(py::module_& m) {
    m.def("read_image", &read, py::arg("path"),
          R"doc(Read an image file into a float32 array.

Args:
    path (str | os.PathLike): an OpenEXR, Radiance HDR, PNG, TIFF or JPEG file.

Returns:
    numpy.ndarray: float32 of shape (H, W, C), row 0 at the top of the image,
    linear light. 8/16-bit files tagged sRGB (the default for PNG and JPEG)
    are decoded to linear values; float files are returned as stored.

Raises:
    OSError: the file is missing or not a readable image (the message names it).
)doc");
    m.def("write_image", &write, py::arg("path"), py::arg("array"), py::kw_only(),
          py::arg("format") = py::none(), py::arg("srgb") = py::none(),
          R"doc(Write a float32 array as an image file; the format follows the extension.

Args:
    path (str | os.PathLike): .exr, .hdr, .png, .tif/.tiff or .jpg.
    array (numpy.ndarray): float32 of shape (H, W) or (H, W, C), C in 1..4,
        row 0 at the top, linear light. 2 and 4 channels carry alpha last.
    format (str | None): 'half' or 'float' (EXR, TIFF), 'uint8' or 'uint16'
        (PNG, TIFF). Default: float for EXR and TIFF, RGBE for HDR, uint8 for
        PNG and JPEG.
    srgb (bool | None): encode colour channels with the sRGB curve. Default:
        on for integer formats, off for float ones. Alpha is never encoded.

The image is written under a temporary name and renamed, so an existing file
is never left half-written.

Raises:
    ValueError: the array or the combination of format and channels is not
        storable (for example alpha in an .hdr, NaN in a PNG).
    OSError: the file cannot be written (the message names it).
)doc");
}

}  // namespace lmrefine::bindings
