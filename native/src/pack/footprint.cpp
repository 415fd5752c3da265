#include "footprint.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <glm/common.hpp>

namespace lmrefine::pack {
namespace {

SpanRows to_spans(const std::vector<uint8_t>& bits, int width, int height) {
    SpanRows rows;
    rows.width = width;
    rows.height = height;
    rows.offsets.reserve(size_t(height) + 1);
    for (int r = 0; r < height; ++r) {
        rows.offsets.push_back(int32_t(rows.spans.size()));
        // Bits are 0 or 1, so memchr (vectorised in the C library) finds
        // where each run begins and ends.
        const uint8_t* row = bits.data() + size_t(r) * size_t(width);
        const uint8_t* end = row + width;
        for (const uint8_t* p = row; p < end;) {
            const auto* begin = static_cast<const uint8_t*>(std::memchr(p, 1, size_t(end - p)));
            if (!begin) break;
            const auto* stop = static_cast<const uint8_t*>(std::memchr(begin, 0, size_t(end - begin)));
            if (!stop) stop = end;
            rows.spans.push_back({int32_t(begin - row), int32_t(stop - row)});
            p = stop;
        }
    }
    rows.offsets.push_back(int32_t(rows.spans.size()));
    return rows;
}

// The covered spans dilated: output row R holds covered row R - reach - di
// grown by half[di + reach] on each side, for every di with a reach; the
// union of those intervals, merged where they meet or touch (as maximal runs
// of a bitmap holding them). Built from the spans, not a bitmap: the packer
// makes two footprints per chart in every trial, and a bitmap the size of
// the dilated chart cost more in fresh memory than the placement.
SpanRows dilate(const SpanRows& covered, int reach, const std::vector<int>& half) {
    SpanRows out;
    out.width = covered.width + 2 * reach;
    out.height = covered.height + 2 * reach;
    out.offsets.reserve(size_t(out.height) + 1);
    out.spans.reserve(covered.spans.size());
    std::vector<Span> row;
    for (int r = 0; r < out.height; ++r) {
        const size_t first = out.spans.size();
        out.offsets.push_back(int32_t(first));
        row.clear();
        for (int di = -reach; di <= reach; ++di) {
            const int h = half[size_t(di + reach)];
            const int source = r - reach - di;
            if (h < 0 || source < 0 || source >= covered.height) continue;
            for (int k = covered.offsets[size_t(source)]; k < covered.offsets[size_t(source) + 1]; ++k) {
                const Span& span = covered.spans[size_t(k)];
                row.push_back({span.first + reach - h, span.second + reach + h});
            }
        }
        std::sort(row.begin(), row.end());
        for (const Span& span : row) {
            if (out.spans.size() > first && span.first <= out.spans.back().second) {
                out.spans.back().second = std::max(out.spans.back().second, span.second);
            } else {
                out.spans.push_back(span);
            }
        }
    }
    out.offsets.push_back(int32_t(out.spans.size()));
    return out;
}

}  // namespace

std::vector<glm::dvec2> local_pixels(const ChartPiece& piece, const std::vector<glm::dvec2>& uvs, double scale,
                                     int width, int height) {
    std::vector<glm::dvec2> local(piece.corners.size());
    glm::dvec2 low(INFINITY);
    for (size_t k = 0; k < piece.corners.size(); ++k) {
        const glm::dvec2 uv = uvs[size_t(piece.corners[k])] * scale;
        local[k] = glm::dvec2(uv.x * width, -uv.y * height);
        low = glm::min(low, local[k]);
    }
    for (auto& p : local) p += glm::dvec2(kInset) - low;
    return local;
}

glm::dvec2 turn_local(const glm::dvec2& p, double width) { return {p.y, width - p.x}; }

Footprint make_footprint(const ChartPiece& piece, const UvLayout& layout, const std::vector<glm::dvec2>& local,
                         double padding, std::vector<uint8_t>& bits) {
    const glm::ivec2 size = footprint_size(local);
    const int width = size.x, height = size.y;
    bits.assign(size_t(width) * size_t(height), 0);
    // A point grown by kInset: the up to four texels its square meets.
    auto set_point = [&](const glm::dvec2& p) {
        const int c0 = std::max(0, int(std::floor(p.x - kInset))), c1 = std::min(width - 1, int(std::floor(p.x + kInset)));
        const int r0 = std::max(0, int(std::floor(p.y - kInset))), r1 = std::min(height - 1, int(std::floor(p.y + kInset)));
        for (int r = r0; r <= r1; ++r)
            for (int c = c0; c <= c1; ++c) bits[size_t(r) * size_t(width) + size_t(c)] = 1;
    };
    auto local_of = [&](int32_t uv_index) {
        const auto it = std::lower_bound(piece.corners.begin(), piece.corners.end(), int64_t(uv_index));
        return local[size_t(it - piece.corners.begin())];
    };
    for (int64_t t : piece.triangles) {
        glm::dvec2 p[3];
        for (int k = 0; k < 3; ++k) p[k] = local_of(layout.triangles[3 * t + k]);
        const TriangleCover cover(p, width, height, kInset);
        for (int r = cover.row_begin(); r < cover.row_end(); ++r) {
            const auto [begin, end] = cover.columns(r);
            std::fill(bits.begin() + r * width + begin, bits.begin() + r * width + end, uint8_t(1));
        }
        // Slivers (and zero-area triangles, which cover nothing) still occupy
        // the texels their corners and edges pass through.
        const double twice_area = std::abs((p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x));
        if (twice_area < 1.0) {
            for (int e = 0; e < 3; ++e) {
                const glm::dvec2 a = p[e], b = p[(e + 1) % 3];
                const int steps = 1 + int(std::ceil(4.0 * std::max(std::abs(b.x - a.x), std::abs(b.y - a.y))));
                for (int s = 0; s <= steps; ++s) set_point(a + (b - a) * (double(s) / steps));
            }
        }
    }
    for (const auto& p : local) set_point(p);
    return footprint_of_bits(bits, width, height, padding);
}

glm::ivec2 footprint_size(const std::vector<glm::dvec2>& local) {
    glm::dvec2 high(0.0);
    for (const auto& p : local) high = glm::max(high, p);
    return {std::max(1, int(std::ceil(high.x + kInset))), std::max(1, int(std::ceil(high.y + kInset)))};
}

Footprint turned_footprint(const Footprint& fp, const std::vector<uint8_t>& bits, double padding,
                           std::vector<uint8_t>& turned) {
    const int width = fp.covered.width, height = fp.covered.height;
    // Texel (column c, row r) goes to (column r, row width - 1 - c).
    turned.assign(size_t(width) * size_t(height), 0);
    for (int r = 0; r < height; ++r) {
        for (int c = 0; c < width; ++c) turned[size_t(width - 1 - c) * size_t(height) + size_t(r)] = bits[size_t(r) * size_t(width) + size_t(c)];
    }
    return footprint_of_bits(turned, height, width, padding);
}

Footprint footprint_of_bits(const std::vector<uint8_t>& bits, int width, int height, double padding) {
    Footprint fp;
    fp.covered = to_spans(bits, width, height);
    fp.longest.assign(size_t(height), 0);
    for (int r = 0; r < height; ++r) {
        for (int k = fp.covered.offsets[r]; k < fp.covered.offsets[r + 1]; ++k) {
            const int length = fp.covered.spans[k].second - fp.covered.spans[k].first;
            fp.texels += length;
            fp.longest[size_t(r)] = std::max(fp.longest[size_t(r)], length);
        }
        if (fp.longest[size_t(r)] > fp.longest[size_t(fp.tightest)]) fp.tightest = r;
    }

    // Texel squares (di, dj) apart are hypot(max(0, |di| - 1), max(0, |dj| - 1))
    // texels apart; the dilation holds every offset closer than the padding.
    fp.reach = int(std::ceil(padding));
    std::vector<int> half(size_t(2 * fp.reach + 1), -1);  // per row offset, the horizontal reach
    for (int di = -fp.reach; di <= fp.reach; ++di) {
        const double gy = std::max(0, std::abs(di) - 1);
        for (int dj = 0; dj <= fp.reach; ++dj) {
            const double gx = std::max(0, dj - 1);
            if (gx * gx + gy * gy < padding * padding || (di == 0 && dj == 0)) half[size_t(di + fp.reach)] = dj;
        }
    }
    fp.dilated = dilate(fp.covered, fp.reach, half);
    return fp;
}

}  // namespace lmrefine::pack
