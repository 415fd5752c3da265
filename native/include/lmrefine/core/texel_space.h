// The one convention for lightmap arrays and UVs, shared by every stage.
//
// A lightmap is an (H, W[, C]) array in image order: row 0 is the top of the
// image (v = 1), as OpenImageIO, numpy image libraries and image viewers have
// it. Texel (row i, column j) covers
//     u in [j / W, (j + 1) / W],   v in [1 - (i + 1) / H, 1 - i / H],
// and its centre is at u = (j + 0.5) / W, v = 1 - (i + 0.5) / H.
// "Pixel space" is continuous: x runs along columns (0..W), y down rows (0..H).
// (Blender's Image.pixels is bottom-up: the add-on's bridge flips rows.)
#pragma once

#include <glm/vec2.hpp>

namespace lmrefine {

inline glm::dvec2 uv_to_pixel(const glm::dvec2& uv, int width, int height) {
    return {uv.x * width, (1.0 - uv.y) * height};
}

inline glm::dvec2 pixel_to_uv(const glm::dvec2& p, int width, int height) {
    return {p.x / width, 1.0 - p.y / height};
}

inline glm::dvec2 texel_center_uv(int row, int col, int width, int height) {
    return pixel_to_uv({col + 0.5, row + 0.5}, width, height);
}

}  // namespace lmrefine
