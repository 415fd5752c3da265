// The atlas packer: moves whole charts (uniform scale, a rotation by a
// multiple of 90 degrees, a translation) into [0, 1]^2 at a lightmap
// resolution, with at least `padding` texels between charts as check_layout
// measures it, as large as the atlas allows. Charts are fitted by their
// conservative footprint on a grid of (by default) half texels (the cells
// they overlap, rasterized as coverage_mask does), and also as bounding boxes
// at continuous positions (shelves, then a skyline), kept when they reach a
// 1% larger scale. Details and measurements: docs/packer.md.
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine {

class Progress;

struct PackOptions {
    int width = 0, height = 0;  // the target lightmap
    double padding = 2.0;       // texels between charts, >= 0
    bool rotate = true;         // allow 90-degree turns
    double weld_tolerance = 0;  // corners of one chart closer than this (UV) are snapped together
    // Footprints and positions on a grid this many times finer than the
    // texels: charts land on sub-texel positions, so a small chart wastes
    // less than a texel to the grid (docs/packer.md has it measured).
    int subdivision = 2;
    // Also try bounding boxes at continuous positions (shelves, a skyline)
    // and keep them when they reach a 1% larger scale: exact for rectangular
    // charts, which the footprint grid wastes up to a cell per side of.
    bool boxes = true;
    // > 0: no search; the charts are placed at this global scale only (the
    // footprints, then the boxes where they fail; InvalidArgument when
    // neither fits). What the atlas fill asks: does a chart grown by this
    // much still fit beside the others at their sizes?
    double fixed_scale = 0;
};

struct PackResult {
    std::vector<float> uvs;          // (uv_count, 2), the input's where no triangle uses a UV
    double global_scale = 0;         // each chart's linear scale is global_scale * scales[c]
    double scale_bound = 0;          // bound on global_scale: chart area = atlas, every box inside it
    std::vector<int32_t> rotations;  // per chart, quarter turns counter-clockwise on the image (0 or 1)
    // Per chart, a 2 x 3 row-major affine map: a (welded) corner uv moves to
    // M[:, :2] uv + M[:, 2]. Quarter turns are turns in texel space.
    std::vector<double> transforms;
    int trials = 0;                  // placements tried by the scale search (both placements)
    bool boxes = false;              // the charts were placed as bounding boxes (else as footprints)
    double footprint_texels = 0;     // texels of the placed footprints (undilated; sub-texels / subdivision^2)
};

// triangle_chart: chart id per triangle in [0, chart_count); a UV index used
// by two charts, bad scales or a bad resolution throw InvalidArgument. The
// layout must be valid (validate_layout). Deterministic: the result does not
// depend on the thread count.
PackResult pack_charts(const UvLayout& layout, const std::vector<int32_t>& triangle_chart, int32_t chart_count,
                       const std::vector<double>& scales, const PackOptions& options, Progress* progress = nullptr);

// A footprint as bitmaps (a test's window on the kernel): `chart`
// ((height * width) bytes, nonzero = covered), turned a quarter
// counter-clockwise when `turned`, as the packer sees it (`covered`), and
// its dilation by `padding` (`dilated`: every cell closer than that to a
// covered one, texel-square distance), (height + 2 reach) rows of (width +
// 2 reach) with `covered`'s corner at (reach, reach). Masks are row-major, 0 or 1.
struct FootprintMasks {
    std::vector<uint8_t> covered, dilated;
    int width = 0, height = 0, reach = 0;  // `covered`'s size; the dilation's margin
};
FootprintMasks footprint_masks(const std::vector<uint8_t>& chart, int width, int height, double padding, bool turned);

// The placement rule alone, on bitmaps (a test's window on the kernel):
// the first (x, y) in scan order where `chart` ((chart_height * chart_width)
// bytes, nonzero = covered) fits inside the atlas with no covered texel
// closer than `padding` (texel-square distance) to a texel of `occupied`
// ((height * width) bytes), in rows from first_row on. False if none.
bool first_fit_position(const std::vector<uint8_t>& occupied, int width, int height,
                        const std::vector<uint8_t>& chart, int chart_width, int chart_height, double padding, int& x,
                        int& y, int first_row = 0);

}  // namespace lmrefine
