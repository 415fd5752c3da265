#include "lmrefine/core/image_io.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <system_error>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"

namespace lmrefine {
namespace {

std::string lower_extension(const std::string& path) {
    const auto slash = path.find_last_of('/');
    const auto dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot);
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

float srgb_to_linear(float c) {
    return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

float linear_to_srgb(float c) {
    c = std::clamp(c, 0.0f, 1.0f);
    return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

bool is_colour_channel(int c, int channels) {
    // Gray, RGB: all colour. Gray+alpha, RGBA: the last one is alpha.
    return !((channels == 2 || channels == 4) && c == channels - 1);
}

const char* supported_list() { return ".exr, .hdr, .png, .tif/.tiff or .jpg"; }

void require_path(const std::string& path) {
    LMREFINE_REQUIRE(!path.empty(), "the image path is empty; pass a file name");
    LMREFINE_REQUIRE(path.find('\0') == std::string::npos,
                     "the image path contains a NUL character; a file name cannot hold one");
}

// Only regular files are read: a device (/dev/zero), a FIFO or a directory
// would make the decoder read forever or fail obscurely.
void require_regular_file(const std::string& path) {
    std::error_code error;
    const std::filesystem::file_status status = std::filesystem::status(path, error);  // follows links, as open does
    if (error || !std::filesystem::exists(status)) {
        LMREFINE_THROW(IoError, "cannot read image '" + path + "': no such file (check the path)");
    }
    if (!std::filesystem::is_regular_file(status)) {
        LMREFINE_THROW(IoError, "cannot read image '" + path + "': not a regular file (a directory, device or pipe); "
                                "pass an image file");
    }
}

}  // namespace

ImageBuffer read_image(const std::string& path) {
    // Lightmap alpha is coverage, not opacity: keep colour unassociated
    // (OpenImageIO would otherwise premultiply PNG colour by alpha).
    require_path(path);
    require_regular_file(path);
    OIIO::ImageSpec config;
    config.attribute("oiio:UnassociatedAlpha", 1);
    auto input = OIIO::ImageInput::open(path, &config);
    if (!input) {
        LMREFINE_THROW(IoError, "cannot read image '" + path + "': " + OIIO::geterror() +
                                    " (check that the file exists and is an image in " +
                                    supported_list() + ")");
    }
    const OIIO::ImageSpec& spec = input->spec();
    ImageBuffer image;
    image.height = spec.height;
    image.width = spec.width;
    image.channels = spec.nchannels;
    if (image.height <= 0 || image.width <= 0 || image.channels <= 0) {
        LMREFINE_THROW(IoError, "image '" + path + "' is empty");
    }
    // The header's size is checked before anything is allocated: a corrupt
    // or hostile header can declare 100000^2 pixels.
    require_memory("reading '" + path + "' (" + std::to_string(image.width) + "x" + std::to_string(image.height) +
                       ", " + std::to_string(image.channels) + " channels as float32)",
                   saturating_product({uint64_t(image.height), uint64_t(image.width), uint64_t(image.channels), 4}),
                   "the file's header declares an image too large to read");
    image.pixels.resize(size_t(image.height) * image.width * image.channels);
    if (!input->read_image(0, 0, 0, image.channels, OIIO::TypeDesc::FLOAT, image.pixels.data())) {
        LMREFINE_THROW(IoError, "cannot read pixels of '" + path + "': " + input->geterror());
    }
    const bool integer = !spec.format.is_floating_point();
    const std::string colorspace = spec.get_string_attribute("oiio:ColorSpace", "");
    const bool srgb = integer && (colorspace.empty() || colorspace == "sRGB");
    if (srgb) {
        for (size_t i = 0; i < image.pixels.size(); ++i) {
            if (is_colour_channel(int(i % image.channels), image.channels))
                image.pixels[i] = srgb_to_linear(image.pixels[i]);
        }
    }
    input->close();
    return image;
}

void write_image(const std::string& path, const float* pixels, int height, int width,
                 int channels, const WriteOptions& options) {
    require_path(path);
    LMREFINE_REQUIRE(height > 0 && width > 0, "cannot write an empty image to '" + path + "'");
    LMREFINE_REQUIRE(channels >= 1 && channels <= 4,
                     "cannot write '" + path + "': expected 1 to 4 channels, got " +
                         std::to_string(channels));
    const std::string ext = lower_extension(path);
    const bool is_exr = ext == ".exr", is_hdr = ext == ".hdr", is_png = ext == ".png";
    const bool is_tiff = ext == ".tif" || ext == ".tiff", is_jpeg = ext == ".jpg" || ext == ".jpeg";
    if (!(is_exr || is_hdr || is_png || is_tiff || is_jpeg)) {
        LMREFINE_THROW(InvalidArgument, "cannot write '" + path + "': unknown image extension '" +
                                            ext + "' (use " + supported_list() + ")");
    }

    PixelFormat format = options.format;
    if (format == PixelFormat::Auto)
        format = (is_exr || is_tiff || is_hdr) ? PixelFormat::Float : PixelFormat::UInt8;
    const bool float_format = format == PixelFormat::Half || format == PixelFormat::Float;
    if (is_hdr) {
        LMREFINE_REQUIRE(format == PixelFormat::Float,
                         "'" + path + "': Radiance HDR stores RGBE floats only; use .exr or .png for another format");
        LMREFINE_REQUIRE(channels == 1 || channels == 3,
                         "'" + path + "': Radiance HDR stores RGB only, got " + std::to_string(channels) +
                             " channels; write .exr to keep alpha");
    }
    if (is_png || is_jpeg) {
        LMREFINE_REQUIRE(!float_format, "'" + path + "': PNG and JPEG store 8 or 16 bits; use .exr for float data");
    }
    if (is_jpeg) {
        LMREFINE_REQUIRE(format == PixelFormat::UInt8 && channels != 2 && channels != 4,
                         "'" + path + "': JPEG stores 8-bit gray or RGB only");
    }
    if (is_exr) {
        LMREFINE_REQUIRE(float_format, "'" + path + "': OpenEXR stores half or float; use .png for 8/16-bit");
    }

    bool srgb = !float_format;
    if (options.srgb == WriteOptions::Srgb::On) srgb = true;
    if (options.srgb == WriteOptions::Srgb::Off) srgb = false;

    const size_t count = size_t(height) * width * channels;
    for (size_t i = 0; i < count; ++i) {
        if (!std::isfinite(pixels[i]) && !float_format) {
            LMREFINE_THROW(InvalidArgument, "cannot write '" + path + "': the image holds NaN or Inf, "
                                            "which an integer format cannot store; use .exr");
        }
    }

    // HDR has no single-channel form: a gray image is written as gray RGB.
    const int file_channels = (is_hdr && channels == 1) ? 3 : channels;
    std::vector<float> encoded(size_t(height) * width * file_channels);
    for (size_t p = 0; p < size_t(height) * width; ++p) {
        for (int c = 0; c < file_channels; ++c) {
            const int src = channels == file_channels ? c : 0;
            float v = pixels[p * channels + src];
            if (srgb && is_colour_channel(c, file_channels)) v = linear_to_srgb(v);
            encoded[p * file_channels + c] = v;
        }
    }

    OIIO::TypeDesc type = OIIO::TypeDesc::FLOAT;
    if (format == PixelFormat::Half) type = OIIO::TypeDesc::HALF;
    if (format == PixelFormat::UInt8) type = OIIO::TypeDesc::UINT8;
    if (format == PixelFormat::UInt16) type = OIIO::TypeDesc::UINT16;

    OIIO::ImageSpec spec(width, height, file_channels, type);
    if (file_channels == 4 || file_channels == 2) spec.alpha_channel = file_channels - 1;
    spec.attribute("oiio:ColorSpace", srgb ? "sRGB" : "Linear");
    spec.attribute("oiio:UnassociatedAlpha", 1);
    if (is_exr) spec.attribute("compression", "zip");

    // Keep the extension so OpenImageIO picks the same format for the temporary.
    const std::string temporary = path.substr(0, path.size() - ext.size()) + ".lmrefine-tmp" + ext;
    auto output = OIIO::ImageOutput::create(temporary);
    if (!output) {
        LMREFINE_THROW(IoError, "cannot write '" + path + "': " + OIIO::geterror());
    }
    if (!output->open(temporary, spec)) {
        LMREFINE_THROW(IoError, "cannot open '" + path + "' for writing: " + output->geterror() +
                                    " (check that the folder exists and is writable)");
    }
    const bool ok = output->write_image(OIIO::TypeDesc::FLOAT, encoded.data());
    const std::string error = ok ? "" : output->geterror();
    output->close();
    if (!ok) {
        std::remove(temporary.c_str());
        LMREFINE_THROW(IoError, "cannot write pixels of '" + path + "': " + error);
    }
    if (std::rename(temporary.c_str(), path.c_str()) != 0) {
        std::remove(temporary.c_str());
        LMREFINE_THROW(IoError, "cannot move the written image into place at '" + path + "'");
    }
}

}  // namespace lmrefine
