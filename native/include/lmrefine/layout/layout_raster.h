// A UV layout rasterized once: the covered texels of every triangle as row
// spans (TriangleCover). Coverage, gutter texels and the overlap test of
// check_layout all read the same texels; rasterizing once and sharing the
// spans is cheaper than rasterizing per use.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine {

class LayoutRaster {
public:
    // Rasterizes the (validated) layout on all cores; the result does not
    // depend on the thread count.
    LayoutRaster(const UvLayout& layout, int width, int height);

    int width() const { return width_; }
    int height() const { return height_; }
    int64_t triangle_count() const { return int64_t(first_row_.size()); }

    // Calls visit(triangle, row, col_begin, col_end) for every non-empty row
    // span, in triangle order, rows top to bottom (for_each_covered_texel's order).
    template <class Visit>
    void for_each_span(Visit&& visit) const {
        for (int64_t t = 0; t < triangle_count(); ++t) for_each_span(t, visit);
    }
    template <class Visit>
    void for_each_span(int64_t t, Visit&& visit) const {
        for (int64_t k = offsets_[size_t(t)]; k < offsets_[size_t(t) + 1]; ++k) {
            const auto [begin, end] = columns_[size_t(k)];
            if (begin < end) visit(t, first_row_[size_t(t)] + int(k - offsets_[size_t(t)]), int(begin), int(end));
        }
    }

    // Row bands of kBandRows rows: disjoint bands can be visited in parallel
    // without sharing a texel. Each band lists the triangles that reach it.
    static constexpr int kBandRows = 64;
    int band_count() const { return int(band_offsets_.size()) - 1; }

    // The spans inside one band, in for_each_span's order.
    template <class Visit>
    void for_each_span_in_band(int band, Visit&& visit) const {
        const int row_begin = band * kBandRows, row_end = row_begin + kBandRows;
        for (int64_t k = band_offsets_[size_t(band)]; k < band_offsets_[size_t(band) + 1]; ++k) {
            const int32_t t = band_triangles_[size_t(k)];
            const int first = first_row_[size_t(t)];
            const int64_t offset = offsets_[size_t(t)];
            const int lo = std::max(row_begin, first);
            const int hi = int(std::min<int64_t>(row_end, first + (offsets_[size_t(t) + 1] - offset)));
            for (int row = lo; row < hi; ++row) {
                const auto [begin, end] = columns_[size_t(offset + (row - first))];
                if (begin < end) visit(int64_t(t), row, int(begin), int(end));
            }
        }
    }

private:
    int width_, height_;
    std::vector<int32_t> first_row_;                     // per triangle
    std::vector<int64_t> offsets_;                       // per triangle, its first row's span; + total
    std::vector<std::pair<int32_t, int32_t>> columns_;   // per row of each triangle: [begin, end)
    std::vector<int64_t> band_offsets_;                  // per band, its first entry in band_triangles_; + total
    std::vector<int32_t> band_triangles_;                // per band, the triangles reaching it, in order
};

// (height * width) bytes, 1 where some triangle covers the texel.
std::vector<uint8_t> coverage_mask(const LayoutRaster& raster);

// Per texel: the chart every covering triangle belongs to, kUncovered, or
// kShared (covered by two charts). Triangles with skip[t] != 0 are left out
// (skip may be null).
constexpr int32_t kUncovered = -1, kShared = -2;
std::vector<int32_t> texel_owners(const LayoutRaster& raster, const std::vector<int32_t>& triangle_chart,
                                  const int8_t* skip = nullptr);

}  // namespace lmrefine
