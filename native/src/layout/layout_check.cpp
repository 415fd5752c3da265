#include "lmrefine/layout/layout_check.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include <glm/geometric.hpp>

#include "lmrefine/layout/chart.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/texel_space.h"

namespace lmrefine {
namespace {

// Below this relative area (twice the area over the longest edge squared) a
// triangle is degenerate: its corners are collinear to float precision.
constexpr double kFlat = 1e-7;
// Triangles whose projections overlap by less than this (texels) only touch.
constexpr double kTouch = 1e-6;
// A chart pair may end this much (texels) closer than required: float32 UV
// rounding, about 1e-4 texel at 4k.
constexpr double kGutterTolerance = 1e-4;

using Triangle = std::array<glm::dvec2, 3>;

double cross(const glm::dvec2& a, const glm::dvec2& b) { return a.x * b.y - a.y * b.x; }

Triangle pixel_triangle(const UvLayout& layout, const float* uvs, int64_t t, int width, int height) {
    Triangle p;
    for (int k = 0; k < 3; ++k) {
        const int32_t index = layout.triangles[3 * t + k];
        p[k] = uv_to_pixel({uvs[2 * index], uvs[2 * index + 1]}, width, height);
    }
    return p;
}

// +1 / -1 by orientation, 0 when degenerate.
int orientation(const Triangle& p) {
    const double c = cross(p[1] - p[0], p[2] - p[0]);
    const double longest = std::max({glm::dot(p[1] - p[0], p[1] - p[0]), glm::dot(p[2] - p[1], p[2] - p[1]),
                                     glm::dot(p[0] - p[2], p[0] - p[2])});
    if (!(std::abs(c) > kFlat * longest)) return 0;
    return c > 0 ? 1 : -1;
}

// Separating-axis test: do the triangles share an area (more than touching)?
bool triangles_overlap(const Triangle& a, const Triangle& b) {
    for (const Triangle* t : {&a, &b}) {
        for (int e = 0; e < 3; ++e) {
            const glm::dvec2 edge = (*t)[(e + 1) % 3] - (*t)[e];
            const double length = glm::length(edge);
            if (length == 0) continue;
            const glm::dvec2 axis = glm::dvec2(-edge.y, edge.x) / length;
            double amin = std::numeric_limits<double>::infinity(), amax = -amin, bmin = amin, bmax = -amin;
            for (int k = 0; k < 3; ++k) {
                amin = std::min(amin, glm::dot(axis, a[k]));
                amax = std::max(amax, glm::dot(axis, a[k]));
                bmin = std::min(bmin, glm::dot(axis, b[k]));
                bmax = std::max(bmax, glm::dot(axis, b[k]));
            }
            if (amax <= bmin + kTouch || bmax <= amin + kTouch) return false;
        }
    }
    return true;
}

// Is the point inside the triangle or on its boundary (within kTouch texels)?
bool contains(const Triangle& p, const glm::dvec2& x) {
    const double area = cross(p[1] - p[0], p[2] - p[0]);
    const double sign = area >= 0 ? 1.0 : -1.0;
    for (int e = 0; e < 3; ++e) {
        const glm::dvec2 edge = p[(e + 1) % 3] - p[e];
        const double length = glm::length(edge);
        if (sign * cross(edge, x - p[e]) < -kTouch * length) return false;
    }
    return true;
}

// Triangles of one chart that share an area: stacked faces (identical corner
// UVs join them into one chart), or a chart folded onto itself. Candidates
// are texel centres inside two of the chart's triangles; the separating-axis
// test confirms them. Pairs of different charts are left to the caller.
void mark_overlaps_inside_charts(const UvLayout& layout, const LayoutRaster& raster, const Charts& charts,
                                 const std::vector<int8_t>& skip, std::vector<uint8_t>& overlapping) {
    const int width = raster.width(), height = raster.height();
    std::vector<std::vector<std::pair<int32_t, int32_t>>> stacked_in_band(size_t(raster.band_count()));
    parallel_for(raster.band_count(), 1, [&](int64_t band_begin, int64_t band_end) {
        std::vector<uint8_t> count;
        for (int64_t band = band_begin; band < band_end; ++band) {
            const int row0 = int(band) * LayoutRaster::kBandRows;
            count.assign(size_t(LayoutRaster::kBandRows) * size_t(width), 0);
            auto centres = [&](int64_t t, int row, int begin, int end, auto&& at_centre) {
                if (skip[size_t(t)]) return;
                const Triangle p = pixel_triangle(layout, layout.uvs, t, width, height);
                for (int col = begin; col < end; ++col) {
                    if (contains(p, {col + 0.5, row + 0.5})) at_centre(size_t(row - row0) * width + col);
                }
            };
            raster.for_each_span_in_band(int(band), [&](int64_t t, int row, int begin, int end) {
                centres(t, row, begin, end, [&](size_t k) { count[k] = uint8_t(std::min(count[k] + 1, 2)); });
            });
            auto& found = stacked_in_band[size_t(band)];
            raster.for_each_span_in_band(int(band), [&](int64_t t, int row, int begin, int end) {
                centres(t, row, begin, end, [&](size_t k) {
                    if (count[k] > 1) found.emplace_back(int32_t(size_t(row0) * width + k), int32_t(t));
                });
            });
        }
    });
    std::vector<std::pair<int32_t, int32_t>> stacked;  // (texel, triangle)
    for (const auto& found : stacked_in_band) stacked.insert(stacked.end(), found.begin(), found.end());
    std::sort(stacked.begin(), stacked.end());
    for (size_t begin = 0; begin < stacked.size();) {
        size_t end = begin;
        while (end < stacked.size() && stacked[end].first == stacked[begin].first) ++end;
        // Each triangle not known to overlap yet looks for one partner: the same
        // triangles end up marked as by testing every pair, but a texel under n
        // stacked faces (a texture map taken for a lightmap) costs about n tests,
        // not n^2.
        for (size_t p = begin; p < end; ++p) {
            const int32_t a = stacked[p].second;
            if (overlapping[size_t(a)]) continue;
            for (size_t q = begin; q < end; ++q) {
                const int32_t b = stacked[q].second;
                if (q == p || charts.triangle_chart[size_t(a)] != charts.triangle_chart[size_t(b)]) continue;
                if (triangles_overlap(pixel_triangle(layout, layout.uvs, a, width, height),
                                      pixel_triangle(layout, layout.uvs, b, width, height))) {
                    overlapping[size_t(a)] = overlapping[size_t(b)] = 1;
                    break;
                }
            }
        }
        begin = end;
    }
}

// check_against gathers a (texel, triangle) pair for every texel centre two
// or more triangles hold (mark_overlaps_inside_charts): 8 bytes in a band's
// list and 8 in the sorted whole (measured: 0.68 GiB for 10 quads stacked at
// 2048^2; twice that where the stacked faces are separate charts, whose
// shared texels are gathered once more). A stack of faces (a texture map taken for a
// lightmap: every face over the whole square) makes them texels x depth, so
// they are estimated from below first (a texel under one triangle holds at
// most one pair, the rest are gathered) and refused before the raster and the
// lists are made, instead of a MemoryError (or the OOM killer) part way.
void require_overlap_memory(const UvLayout& layout, int width, int height) {
    const double texels = double(width) * height;
    const double centres = texel_pairs_at_least(layout, width, height);
    if (!(centres > texels)) return;
    const double bytes = std::min(16.0 * (centres - texels), 1e19);
    char depth[32];
    std::snprintf(depth, sizeof depth, "%.3g", centres / texels);
    require_memory("checking the layout at " + std::to_string(height) + "x" + std::to_string(width) +
                       " (its faces are stacked, at least " + depth + " deep on average)",
                   uint64_t(bytes),
                   "give the faces their own places in the map (a lightmap layout: Lightmap Pack or Smart UV "
                   "Project), fewer stacked faces, or a lower resolution");
}

double point_segment_distance(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b) {
    const glm::dvec2 ab = b - a;
    const double length2 = glm::dot(ab, ab);
    const double t = length2 > 0 ? std::clamp(glm::dot(p - a, ab) / length2, 0.0, 1.0) : 0.0;
    return glm::length(p - (a + t * ab));
}

double segment_distance(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c, const glm::dvec2& d) {
    const double d1 = cross(b - a, c - a), d2 = cross(b - a, d - a);
    const double d3 = cross(d - c, a - c), d4 = cross(d - c, b - c);
    if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return 0.0;
    return std::min({point_segment_distance(a, c, d), point_segment_distance(b, c, d),
                     point_segment_distance(c, a, b), point_segment_distance(d, a, b)});
}

uint64_t uv_key(const float* uv) {
    uint32_t u, v;
    std::memcpy(&u, &uv[0], 4);
    std::memcpy(&v, &uv[1], 4);
    return (uint64_t(u) << 32) | v;
}

struct Edge {
    glm::dvec2 a, b;
    int32_t chart;
};

// Edges used once within their chart (keyed by UV values, since per-corner
// layouts repeat a shared vertex once per corner).
std::vector<Edge> boundary_edges(const UvLayout& layout, const Charts& charts, int width, int height) {
    struct Key {
        uint64_t lo, hi;
        int32_t chart;
        bool operator==(const Key& o) const { return lo == o.lo && hi == o.hi && chart == o.chart; }
    };
    struct Hash {
        size_t operator()(const Key& k) const {
            return std::hash<uint64_t>()(k.lo * 0x9E3779B97F4A7C15ull ^ k.hi) ^ size_t(k.chart);
        }
    };
    std::unordered_map<Key, std::pair<int64_t, int>, Hash> uses;  // first (triangle*3 + edge), count
    uses.reserve(size_t(layout.triangle_count) * 2);
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        for (int e = 0; e < 3; ++e) {
            uint64_t a = uv_key(layout.uvs + 2 * layout.triangles[3 * t + e]);
            uint64_t b = uv_key(layout.uvs + 2 * layout.triangles[3 * t + (e + 1) % 3]);
            if (a > b) std::swap(a, b);
            auto [it, inserted] = uses.emplace(Key{a, b, charts.triangle_chart[size_t(t)]}, std::make_pair(3 * t + e, 0));
            ++it->second.second;
        }
    }
    std::vector<Edge> edges;
    for (const auto& [key, use] : uses) {
        if (use.second != 1) continue;
        const int64_t t = use.first / 3;
        const int e = int(use.first % 3);
        const Triangle p = pixel_triangle(layout, layout.uvs, t, width, height);
        edges.push_back({p[e], p[(e + 1) % 3], key.chart});
    }
    // Hash order is arbitrary; sort for a reproducible pass order.
    std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) {
        return std::tie(x.chart, x.a.x, x.a.y, x.b.x, x.b.y) < std::tie(y.chart, y.a.x, y.a.y, y.b.x, y.b.y);
    });
    return edges;
}

// Chart pair (smaller id first) -> smallest distance between the two charts.
using PairDistances = std::unordered_map<uint64_t, double>;

uint64_t pair_key(int32_t a, int32_t b) {
    return (uint64_t(uint32_t(std::min(a, b))) << 32) | uint32_t(std::max(a, b));
}

// Smallest distance between edges of different charts. Edges go into square
// buckets `radius` wide, each widened by radius / 2: two edges closer than
// `radius` share the bucket of their closest points' midpoint, so a result
// below `radius` is exact; otherwise the radius doubles. With `close`, every
// chart closer than `threshold` to another is marked in it; with `pairs`,
// every chart pair closer than `threshold` gets its smallest distance (all
// such pairs are found in the first round: threshold <= radius).
double min_gutter(const std::vector<Edge>& edges, int width, int height, double threshold,
                  std::vector<uint8_t>* close, PairDistances* pairs = nullptr) {
    double best = std::numeric_limits<double>::infinity();
    const double limit = 2.0 * std::max(width, height);
    for (double radius = std::max(4.0, 2 * threshold);; radius *= 2) {
        const int bx = int(std::ceil(width / radius)) + 2, by = int(std::ceil(height / radius)) + 2;
        std::vector<std::vector<int32_t>> buckets(size_t(bx) * by);
        for (size_t k = 0; k < edges.size(); ++k) {
            const Edge& e = edges[k];
            const double h = radius / 2;
            const int x0 = std::clamp(int(std::floor((std::min(e.a.x, e.b.x) - h) / radius)) + 1, 0, bx - 1);
            const int x1 = std::clamp(int(std::floor((std::max(e.a.x, e.b.x) + h) / radius)) + 1, 0, bx - 1);
            const int y0 = std::clamp(int(std::floor((std::min(e.a.y, e.b.y) - h) / radius)) + 1, 0, by - 1);
            const int y1 = std::clamp(int(std::floor((std::max(e.a.y, e.b.y) + h) / radius)) + 1, 0, by - 1);
            for (int y = y0; y <= y1; ++y) {
                for (int x = x0; x <= x1; ++x) buckets[size_t(y) * bx + x].push_back(int32_t(k));
            }
        }
        for (const auto& bucket : buckets) {
            for (size_t p = 0; p < bucket.size(); ++p) {
                const Edge& e = edges[size_t(bucket[p])];
                for (size_t q = p + 1; q < bucket.size(); ++q) {
                    const Edge& f = edges[size_t(bucket[q])];
                    if (e.chart == f.chart) continue;
                    // Bounding boxes already farther apart than the best: skip.
                    const double gx = std::max({0.0, std::min(f.a.x, f.b.x) - std::max(e.a.x, e.b.x),
                                                std::min(e.a.x, e.b.x) - std::max(f.a.x, f.b.x)});
                    const double gy = std::max({0.0, std::min(f.a.y, f.b.y) - std::max(e.a.y, e.b.y),
                                                std::min(e.a.y, e.b.y) - std::max(f.a.y, f.b.y)});
                    const double cutoff = close || pairs ? std::max(best, threshold) : best;
                    if (gx >= cutoff || gy >= cutoff) continue;
                    const double d = segment_distance(e.a, e.b, f.a, f.b);
                    best = std::min(best, d);
                    if (close && d < threshold) (*close)[size_t(e.chart)] = (*close)[size_t(f.chart)] = 1;
                    if (pairs && d < threshold) {
                        const auto [it, inserted] = pairs->emplace(pair_key(e.chart, f.chart), d);
                        if (!inserted) it->second = std::min(it->second, d);
                    }
                }
            }
        }
        if (best < radius || radius > limit) return best;
    }
}

}  // namespace

// The original's smallest chart distance and every chart pair closer than
// the padding, with its distance: one min_gutter pass serves the original's
// own report and every relative check.
struct LayoutChecker::Gutter {
    double best = std::numeric_limits<double>::infinity();
    PairDistances pairs;
};

LayoutChecker::LayoutChecker(const UvLayout& original, int width, int height, double padding, double chart_tolerance)
    : original_(original), width_(width), height_(height), padding_(padding) {
    LMREFINE_REQUIRE(width > 0 && height > 0, "resolution must be positive, got " + std::to_string(height) +
                                                  "x" + std::to_string(width));
    LMREFINE_REQUIRE(padding >= 0, "padding must be >= 0 texels");
    validate_layout(original);
    charts_ = find_charts(original, chart_tolerance);
    orientation_.resize(size_t(original.triangle_count));
    for (int64_t t = 0; t < original.triangle_count; ++t) {
        orientation_[size_t(t)] = int8_t(orientation(pixel_triangle(original, original.uvs, t, width, height)));
    }
}

LayoutChecker::~LayoutChecker() = default;

const LayoutRaster& LayoutChecker::raster() const {
    std::call_once(raster_once_, [&] { raster_ = std::make_unique<LayoutRaster>(original_, width_, height_); });
    return *raster_;
}

const std::vector<int32_t>& LayoutChecker::owners() const {
    std::call_once(owners_once_, [&] { owners_ = texel_owners(raster(), charts_.triangle_chart); });
    return owners_;
}

const LayoutChecker::Gutter& LayoutChecker::original_gutter() const {
    std::call_once(gutter_once_, [&] {
        auto gutter = std::make_unique<Gutter>();
        if (charts_.count >= 2) {
            gutter->best = min_gutter(boundary_edges(original_, charts_, width_, height_), width_, height_, padding_,
                                      nullptr, &gutter->pairs);
        }
        gutter_ = std::move(gutter);
    });
    return *gutter_;
}

LayoutReport LayoutChecker::check_original(bool list_failing_charts) const {
    require_overlap_memory(original_, width_, height_);
    return check_against(original_, raster(), false, list_failing_charts, false);
}

LayoutReport LayoutChecker::check(const float* uvs, bool list_failing_charts, bool relative_gutter) const {
    const UvLayout layout{uvs, original_.uv_count, original_.triangles, original_.triangle_count};
    require_overlap_memory(layout, width_, height_);
    return check_against(layout, LayoutRaster(layout, width_, height_), true, list_failing_charts, relative_gutter);
}

// check_layout's body. Without a reference `layout` is the original itself.
LayoutReport LayoutChecker::check_against(const UvLayout& layout, const LayoutRaster& raster, bool with_reference,
                                          bool list_failing_charts, bool relative_gutter) const {
    const int width = width_, height = height_;
    const double padding = padding_;
    const Charts& charts = charts_;
    LayoutReport report;
    report.charts = charts.count;

    for (int64_t k = 0; k < layout.uv_count; ++k) {
        const float u = layout.uvs[2 * k], v = layout.uvs[2 * k + 1];
        if (u < 0 || u > 1 || v < 0 || v > 1) ++report.out_of_bounds;
    }

    // Orientation and degeneracy.
    const size_t T = size_t(layout.triangle_count);
    std::vector<int8_t> sign(T), skip(T);
    std::vector<uint8_t> failing(size_t(charts.count), 0);
    std::vector<int64_t> chart_balance(size_t(charts.count), 0);
    for (size_t t = 0; t < T; ++t) {
        sign[t] = with_reference ? int8_t(orientation(pixel_triangle(layout, layout.uvs, int64_t(t), width, height)))
                                 : orientation_[t];
        skip[t] = sign[t] == 0;
        if (sign[t] == 0) {
            ++report.degenerate;
            const bool was_degenerate = with_reference && orientation_[t] == 0;
            if (!was_degenerate) failing[size_t(charts.triangle_chart[t])] = 1;
        }
        chart_balance[size_t(charts.triangle_chart[t])] += sign[t];
    }
    for (size_t t = 0; t < T; ++t) {
        if (sign[t] == 0) continue;
        int expected;
        if (with_reference) {
            expected = orientation_[t];
            if (expected == 0) continue;  // a degenerate original has no orientation to keep
        } else {
            // Ties count the chart as counter-clockwise in UV (clockwise in pixel space, y down).
            expected = chart_balance[size_t(charts.triangle_chart[t])] >= 0 ? 1 : -1;
        }
        if (sign[t] != expected) {
            ++report.flipped;
            failing[size_t(charts.triangle_chart[t])] = 1;
        }
    }

    // Overlap: first mark texels reached by more than one chart, then test
    // the triangle pairs of different charts inside those texels only.
    // The original's owners (every triangle) serve when no triangle is skipped.
    std::vector<int32_t> own_owner;
    if (with_reference || report.degenerate) own_owner = texel_owners(raster, charts.triangle_chart, skip.data());
    const std::vector<int32_t>& owner = with_reference || report.degenerate ? own_owner : owners();
    // (texel, triangle) for every shared texel, gathered per row band in
    // parallel; sorting makes the order independent of the bands.
    std::vector<std::vector<std::pair<int32_t, int32_t>>> shared_in_band(static_cast<size_t>(raster.band_count()));
    parallel_for(raster.band_count(), 1, [&](int64_t band_begin, int64_t band_end) {
        for (int64_t band = band_begin; band < band_end; ++band) {
            // Most bands have no texel of two charts (charts a gutter apart): skip them.
            const int row0 = int(band) * LayoutRaster::kBandRows;
            const auto first = owner.begin() + ptrdiff_t(row0) * width;
            const auto last = owner.begin() + ptrdiff_t(std::min(height, row0 + LayoutRaster::kBandRows)) * width;
            if (std::find(first, last, kShared) == last) continue;
            auto& found = shared_in_band[size_t(band)];
            raster.for_each_span_in_band(int(band), [&](int64_t t, int row, int begin, int end) {
                if (skip[size_t(t)]) return;
                for (int col = begin; col < end; ++col) {
                    const size_t texel = size_t(row) * width + col;
                    if (owner[texel] == kShared) found.emplace_back(int32_t(texel), int32_t(t));
                }
            });
        }
    });
    std::vector<std::pair<int32_t, int32_t>> shared;  // (texel, triangle)
    for (const auto& found : shared_in_band) shared.insert(shared.end(), found.begin(), found.end());
    std::sort(shared.begin(), shared.end());
    std::vector<uint8_t> overlapping(T, 0);
    for (size_t begin = 0; begin < shared.size();) {
        size_t end = begin;
        while (end < shared.size() && shared[end].first == shared[begin].first) ++end;
        // One partner per triangle not known to overlap yet (as inside charts, below).
        for (size_t p = begin; p < end; ++p) {
            const int32_t a = shared[p].second;
            if (overlapping[size_t(a)]) continue;
            for (size_t q = begin; q < end; ++q) {
                const int32_t b = shared[q].second;
                if (q == p || charts.triangle_chart[size_t(a)] == charts.triangle_chart[size_t(b)]) continue;
                if (triangles_overlap(pixel_triangle(layout, layout.uvs, a, width, height),
                                      pixel_triangle(layout, layout.uvs, b, width, height))) {
                    overlapping[size_t(a)] = overlapping[size_t(b)] = 1;
                    break;
                }
            }
        }
        begin = end;
    }
    mark_overlaps_inside_charts(layout, raster, charts, skip, overlapping);
    std::vector<uint8_t> chart_overlaps(size_t(charts.count), 0);
    for (size_t t = 0; t < T; ++t) {
        report.overlapping += overlapping[t];
        if (!overlapping[t]) continue;
        const size_t chart = size_t(charts.triangle_chart[t]);
        failing[chart] = chart_overlaps[chart] = 1;
    }

    if (charts.count < 2) {
        report.min_gutter_texels = std::numeric_limits<double>::infinity();
    } else if (!with_reference) {
        // The pairs closer than the padding are exactly the ones min_gutter
        // would mark as close.
        const Gutter& gutter = original_gutter();
        report.min_gutter_texels = gutter.best;
        if (list_failing_charts) {
            for (const auto& [key, distance] : gutter.pairs) {
                failing[size_t(key >> 32)] = failing[size_t(key & 0xffffffffu)] = 1;
            }
        }
    } else if (!relative_gutter) {
        report.min_gutter_texels = min_gutter(boundary_edges(layout, charts, width, height), width, height, padding,
                                              list_failing_charts ? &failing : nullptr);
    } else {
        // Every chart pair must stay at least min(padding, its original
        // distance) apart: a pair the original packed tighter than the
        // padding keeps its own gutter, without holding back all the others.
        const PairDistances& before = original_gutter().pairs;
        PairDistances after;
        report.min_gutter_texels =
            min_gutter(boundary_edges(layout, charts, width, height), width, height, padding, nullptr, &after);
        std::vector<std::pair<uint64_t, double>> close(after.begin(), after.end());
        std::sort(close.begin(), close.end());  // hash order is arbitrary
        for (const auto& [key, distance] : close) {
            const auto original = before.find(key);
            const double required = original == before.end() ? padding : std::min(padding, original->second);
            if (distance < required - kGutterTolerance) {
                ++report.gutter_violations;
                failing[size_t(key >> 32)] = failing[size_t(key & 0xffffffffu)] = 1;
            }
        }
    }
    if (list_failing_charts) {
        for (int32_t c = 0; c < charts.count; ++c) {
            if (failing[size_t(c)]) report.failing_charts.push_back(c);
            if (chart_overlaps[size_t(c)]) report.overlapping_charts.push_back(c);
        }
    }
    report.valid = report.flipped == 0 && report.degenerate == 0 && report.overlapping == 0 &&
                   report.out_of_bounds == 0 && report.min_gutter_texels >= padding - 1e-6;
    return report;
}

LayoutReport check_layout(const UvLayout& layout, int width, int height, double padding,
                          const float* reference_uvs, bool list_failing_charts, bool relative_gutter,
                          double chart_tolerance) {
    LMREFINE_REQUIRE(!relative_gutter || reference_uvs,
                     "relative_gutter compares with the original layout: pass reference_uvs");
    LMREFINE_REQUIRE(width > 0 && height > 0, "resolution must be positive, got " + std::to_string(height) +
                                                  "x" + std::to_string(width));
    LMREFINE_REQUIRE(padding >= 0, "padding must be >= 0 texels");
    validate_layout(layout);
    if (!reference_uvs) {
        return LayoutChecker(layout, width, height, padding, chart_tolerance).check_original(list_failing_charts);
    }
    const LayoutChecker checker({reference_uvs, layout.uv_count, layout.triangles, layout.triangle_count}, width,
                                height, padding, chart_tolerance);
    return checker.check(layout.uvs, list_failing_charts, relative_gutter);
}

}  // namespace lmrefine
