#include "lmrefine/layout/layout_raster.h"

#include <algorithm>
#include <string>

#include "lmrefine/core/memory.h"
#include "lmrefine/core/parallel.h"

namespace lmrefine {

LayoutRaster::LayoutRaster(const UvLayout& layout, int width, int height)
    : width_(width), height_(height), first_row_(size_t(layout.triangle_count)),
      offsets_(size_t(layout.triangle_count) + 1, 0) {
    // Rows per triangle (a cheap pass), then the spans of every triangle in
    // parallel into its own slots: no ordering depends on the threads.
    const int64_t T = layout.triangle_count;
    parallel_for(T, 4096, [&](int64_t begin, int64_t end) {
        for (int64_t t = begin; t < end; ++t) {
            const TriangleCover cover(layout, t, width, height);
            first_row_[size_t(t)] = cover.row_begin();
            offsets_[size_t(t) + 1] = cover.row_end() - cover.row_begin();
        }
    });
    for (int64_t t = 0; t < T; ++t) offsets_[size_t(t) + 1] += offsets_[size_t(t)];
    // A span per triangle and row: rows x depth for faces stacked over the map.
    require_memory("rasterizing " + std::to_string(T) + " triangles at " + std::to_string(height) + "x" +
                       std::to_string(width) + " (" + std::to_string(offsets_.back()) + " triangle rows)",
                   saturating_product({uint64_t(offsets_.back()), sizeof(columns_[0]) + sizeof(band_triangles_[0])}),
                   "give stacked faces their own places in the map, use fewer triangles, or a lower resolution");
    columns_.resize(size_t(offsets_.back()));
    // Triangles per row band (counted, then listed in triangle order).
    const int bands = (height + kBandRows - 1) / kBandRows;
    band_offsets_.assign(size_t(bands) + 1, 0);
    auto for_each_band = [&](int64_t t, auto&& use) {
        const int64_t rows = offsets_[size_t(t) + 1] - offsets_[size_t(t)];
        if (rows == 0) return;
        const int first = first_row_[size_t(t)];
        for (int band = first / kBandRows; band <= int((first + rows - 1) / kBandRows); ++band) use(band);
    };
    for (int64_t t = 0; t < T; ++t) for_each_band(t, [&](int band) { ++band_offsets_[size_t(band) + 1]; });
    for (int band = 0; band < bands; ++band) band_offsets_[size_t(band) + 1] += band_offsets_[size_t(band)];
    band_triangles_.resize(size_t(band_offsets_.back()));
    std::vector<int64_t> next(band_offsets_.begin(), band_offsets_.end() - 1);
    for (int64_t t = 0; t < T; ++t) {
        for_each_band(t, [&](int band) { band_triangles_[size_t(next[size_t(band)]++)] = int32_t(t); });
    }
    parallel_for(T, 1024, [&](int64_t begin, int64_t end) {
        for (int64_t t = begin; t < end; ++t) {
            const TriangleCover cover(layout, t, width, height);
            for (int row = cover.row_begin(); row < cover.row_end(); ++row) {
                const auto [b, e] = cover.columns(row);
                columns_[size_t(offsets_[size_t(t)] + (row - cover.row_begin()))] = {b, e};
            }
        }
    });
}

std::vector<uint8_t> coverage_mask(const LayoutRaster& raster) {
    std::vector<uint8_t> mask = large_vector<uint8_t>(size_t(raster.width()) * raster.height(), 0);
    parallel_for(raster.band_count(), 1, [&](int64_t bands_begin, int64_t bands_end) {
        for (int64_t band = bands_begin; band < bands_end; ++band) {
            raster.for_each_span_in_band(int(band), [&](int64_t, int row, int begin, int end) {
                std::fill_n(mask.data() + size_t(row) * raster.width() + begin, end - begin, uint8_t(1));
            });
        }
    });
    return mask;
}

std::vector<int32_t> texel_owners(const LayoutRaster& raster, const std::vector<int32_t>& triangle_chart,
                                  const int8_t* skip) {
    std::vector<int32_t> owner = large_vector<int32_t>(size_t(raster.width()) * raster.height(), kUncovered);
    // Which triangle reaches a texel first does not matter: the owner is a
    // function of the set of charts that cover it.
    parallel_for(raster.band_count(), 1, [&](int64_t bands_begin, int64_t bands_end) {
        for (int64_t band = bands_begin; band < bands_end; ++band) {
            raster.for_each_span_in_band(int(band), [&](int64_t t, int row, int begin, int end) {
                if (skip && skip[t]) return;
                const int32_t chart = triangle_chart[size_t(t)];
                int32_t* o = owner.data() + size_t(row) * raster.width();
                for (int col = begin; col < end; ++col) {
                    o[col] = o[col] == kUncovered || o[col] == chart ? chart : kShared;
                }
            });
        }
    });
    return owner;
}

}  // namespace lmrefine
