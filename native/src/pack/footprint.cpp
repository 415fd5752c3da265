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
    rows.spans.reserve(size_t(height));  // a span a row, as most charts have
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
// the dilated chart cost more in fresh memory than the placement. Each
// source row's grown spans are already in order, so they are merged into
// the row's running union one source row at a time (a sort of every
// interval of the row cost more than the merges).
SpanRows dilate(const SpanRows& covered, int reach, const std::vector<int>& half, FootprintScratch& scratch) {
    SpanRows out;
    out.width = covered.width + 2 * reach;
    out.height = covered.height + 2 * reach;
    out.offsets.reserve(size_t(out.height) + 1);
    out.spans.reserve(covered.spans.size() + 2 * size_t(reach));  // a convex chart's spans
    // Rows a and b of `covered` hold the same spans.
    const auto same_row = [&covered](int a, int b) {
        const Span* spans = covered.spans.data();
        const int32_t* at = covered.offsets.data();
        return at[a + 1] - at[a] == at[b + 1] - at[b] && std::equal(spans + at[a], spans + at[a + 1], spans + at[b]);
    };
    std::vector<Span>& row = scratch.row;
    std::vector<Span>& merged = scratch.merged;
    for (int r = 0; r < out.height; ++r) {
        row.clear();
        for (int di = -reach; di <= reach; ++di) {
            int h = half[size_t(di + reach)];
            int source = r - reach - di;
            if (h < 0 || source < 0 || source >= covered.height) continue;
            // The window's next rows, while equal to this one (a rectangle's
            // are): a row grown by h and by h' is the row grown by the
            // larger, so they take one merge.
            while (di < reach && source > 0 && half[size_t(di + 1 + reach)] >= 0 && same_row(source, source - 1)) {
                h = std::max(h, half[size_t(++di + reach)]);
                --source;
            }
            const Span* next = covered.spans.data() + covered.offsets[size_t(source)];
            const Span* const end = covered.spans.data() + covered.offsets[size_t(source) + 1];
            if (next == end) continue;
            // The union of `row` and this source row's spans grown by h:
            // take whichever starts first, joining it to the last run kept
            // where they meet or touch.
            merged.clear();
            size_t k = 0;
            const int shift = reach - h, grow = reach + h;
            while (k < row.size() || next != end) {
                Span span;
                if (next == end || (k < row.size() && row[k].first <= next->first + shift)) {
                    span = row[k++];
                } else {
                    span = {next->first + shift, next->second + grow};
                    ++next;
                }
                if (!merged.empty() && span.first <= merged.back().second) {
                    merged.back().second = std::max(merged.back().second, span.second);
                } else {
                    merged.push_back(span);
                }
            }
            row.swap(merged);
        }
        out.offsets.push_back(int32_t(out.spans.size()));
        out.spans.insert(out.spans.end(), row.begin(), row.end());
    }
    out.offsets.push_back(int32_t(out.spans.size()));
    return out;
}

// The spans of the bitmap turned a quarter (texel (column c, row r) to
// (column r, row width - 1 - c)), from the spans, not the bitmap: turned
// row width - 1 - c holds upright column c's vertical runs. Sweeping the
// rows, a run starts at the columns covered in a row and not in the one
// above, and ends where the reverse holds, so the work follows the
// footprint's outline, not its area.
SpanRows turned_spans(const SpanRows& upright, FootprintScratch& scratch) {
    const int width = upright.width, height = upright.height;
    std::vector<FootprintScratch::Run>& runs = scratch.runs;  // in the order they end (per column: rows ascending)
    std::vector<int32_t>& start = scratch.start;
    std::vector<int32_t>& count = scratch.count;
    runs.clear();
    start.assign(size_t(width), 0);
    count.assign(size_t(width), 0);
    // Calls f(lo, hi) for each maximal column range in spans [a, a_end) and
    // not in [b, b_end) (both sorted, disjoint).
    const auto for_each_difference = [](const Span* a, const Span* a_end, const Span* b, const Span* b_end, auto f) {
        for (; a != a_end; ++a) {
            int x = a->first;
            while (b != b_end && b->second <= x) ++b;
            for (const Span* k = b; x < a->second; ++k) {
                if (k == b_end || k->first >= a->second) {
                    f(x, a->second);
                    break;
                }
                if (k->first > x) f(x, k->first);
                x = std::max(x, k->second);
            }
        }
    };
    // Row r's spans are [first(r), first(r + 1)); rows outside the bitmap are empty.
    const auto first = [&](int r) { return upright.spans.data() + upright.offsets[size_t(std::clamp(r, 0, height))]; };
    for (int r = 0; r <= height; ++r) {  // row `height` is empty: every run still open ends there
        for_each_difference(first(r - 1), first(r), first(r), first(r + 1), [&](int lo, int hi) {
            for (int c = lo; c < hi; ++c) {
                runs.push_back({c, start[size_t(c)], r});
                ++count[size_t(c)];
            }
        });
        for_each_difference(first(r), first(r + 1), first(r - 1), first(r), [&](int lo, int hi) {
            for (int c = lo; c < hi; ++c) start[size_t(c)] = r;
        });
    }
    SpanRows turned;
    turned.width = height;
    turned.height = width;
    turned.offsets.resize(size_t(width) + 1);
    turned.offsets[0] = 0;
    for (int t = 0; t < width; ++t) {
        turned.offsets[size_t(t) + 1] = turned.offsets[size_t(t)] + count[size_t(width - 1 - t)];
    }
    // A column's runs arrive in row order: placed in turn, each turned row's spans ascend.
    turned.spans.resize(runs.size());
    std::vector<int32_t>& next = count;  // reused: per column, where its next run goes
    for (int c = 0; c < width; ++c) next[size_t(c)] = turned.offsets[size_t(width - 1 - c)];
    for (const FootprintScratch::Run& run : runs) {
        turned.spans[size_t(next[size_t(run.column)]++)] = {run.first, run.end};
    }
    return turned;
}

// The covered spans' longest per row, texels and tightest row.
void measure_rows(Footprint& fp) {
    const int height = fp.covered.height;
    fp.longest.assign(size_t(height), 0);
    for (int r = 0; r < height; ++r) {
        for (int k = fp.covered.offsets[r]; k < fp.covered.offsets[r + 1]; ++k) {
            const int length = fp.covered.spans[k].second - fp.covered.spans[k].first;
            fp.texels += length;
            fp.longest[size_t(r)] = std::max(fp.longest[size_t(r)], length);
        }
        if (fp.longest[size_t(r)] > fp.longest[size_t(fp.tightest)]) fp.tightest = r;
    }
}

Footprint footprint_of_spans(SpanRows covered, double padding, FootprintScratch& scratch) {
    Footprint fp;
    fp.covered = std::move(covered);
    measure_rows(fp);

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
    fp.dilated = dilate(fp.covered, fp.reach, half, scratch);
    return fp;
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
                         double padding, std::vector<uint8_t>& bits, FootprintScratch& scratch) {
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
    return footprint_of_spans(to_spans(bits, width, height), padding, scratch);
}

glm::ivec2 footprint_size(const std::vector<glm::dvec2>& local) {
    glm::dvec2 high(0.0);
    for (const auto& p : local) high = glm::max(high, p);
    return {std::max(1, int(std::ceil(high.x + kInset))), std::max(1, int(std::ceil(high.y + kInset)))};
}

Footprint turned_footprint(const Footprint& fp, FootprintScratch& scratch) {
    // The dilation's offsets (the distance rule) are the same turned a
    // quarter, so the turned footprint's dilation is the dilation turned:
    // no second dilation.
    Footprint turned;
    turned.covered = turned_spans(fp.covered, scratch);
    turned.dilated = turned_spans(fp.dilated, scratch);
    turned.reach = fp.reach;
    measure_rows(turned);
    return turned;
}

Footprint footprint_of_bits(const std::vector<uint8_t>& bits, int width, int height, double padding) {
    FootprintScratch scratch;
    return footprint_of_spans(to_spans(bits, width, height), padding, scratch);
}

}  // namespace lmrefine::pack
