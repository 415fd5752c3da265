// Reading and writing lightmaps through OpenImageIO (the only file that
// includes it is src/image_io.cpp). Arrays are float32, (H, W, C), row 0 at
// the top (see texel_space.h), linear light.
#pragma once

#include <string>
#include <vector>

namespace lmrefine {

struct ImageBuffer {
    int height = 0;
    int width = 0;
    int channels = 0;
    std::vector<float> pixels;  // height * width * channels, row-major, interleaved
};

// Storage type in the file. Auto: float for EXR and TIFF, RGBE for HDR,
// 8-bit for PNG and JPEG.
enum class PixelFormat { Auto, Half, Float, UInt8, UInt16 };

struct WriteOptions {
    PixelFormat format = PixelFormat::Auto;
    // Encode colour channels with the sRGB transfer curve. Default: on for
    // integer formats (PNG, 8/16-bit TIFF), off for float formats. Alpha is
    // never encoded.
    enum class Srgb { Auto, On, Off } srgb = Srgb::Auto;
};

// Reads the first subimage as float32. Integer files tagged (or defaulting
// to) sRGB are decoded to linear light, so a PNG written by write_image reads
// back as the values that went in (up to quantization).
// Throws IoError naming the file if it is missing or unreadable.
ImageBuffer read_image(const std::string& path);

// Writes `pixels` (height * width * channels floats). The format follows the
// extension (.exr .hdr .png .tif/.tiff .jpg); the file is written to a
// temporary name first and renamed, so a failed write never leaves a
// truncated image over an existing one.
// Throws InvalidArgument for a combination the format cannot store, IoError
// for anything the file system or OpenImageIO refuses.
void write_image(const std::string& path, const float* pixels, int height, int width,
                 int channels, const WriteOptions& options = {});

}  // namespace lmrefine
