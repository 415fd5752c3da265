#include "lmrefine/layout/chart.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <unordered_map>

#include "lmrefine/core/error.h"

namespace lmrefine {
namespace {

struct DisjointSets {
    explicit DisjointSets(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
    int64_t find(int64_t x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    }
    void join(int64_t a, int64_t b) {
        a = find(a);
        b = find(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
    std::vector<int64_t> parent;
};

uint64_t uv_key(const float* uv) {
    uint32_t u, v;
    std::memcpy(&u, &uv[0], 4);
    std::memcpy(&v, &uv[1], 4);
    return (uint64_t(u) << 32) | v;
}

uint64_t cell_key(int64_t i, int64_t j) { return (uint64_t(uint32_t(i)) << 32) | uint32_t(j); }

bool close_corners(const UvLayout& layout, int64_t a, int64_t b, double tolerance2) {
    const double du = double(layout.uvs[2 * a]) - layout.uvs[2 * b];
    const double dv = double(layout.uvs[2 * a + 1]) - layout.uvs[2 * b + 1];
    return du * du + dv * dv < tolerance2 || (du == 0.0 && dv == 0.0);
}

// Every pair of `points` closer than `tolerance`, looked for in a hash grid of
// cells of the tolerance's size (each point meets the points of its 3 x 3
// cells). Quadratic in the points one cell holds: the fallback of
// join_by_cells.
void join_by_pairs(const UvLayout& layout, double tolerance, const std::vector<int64_t>& points,
                   DisjointSets& sets) {
    std::unordered_map<uint64_t, std::vector<int64_t>> cells;
    cells.reserve(points.size());
    const double tolerance2 = tolerance * tolerance;
    for (int64_t i : points) {
        const double u = layout.uvs[2 * i], v = layout.uvs[2 * i + 1];
        // Clamped so a huge UV cannot overflow the cast (a shared cell only costs a distance test).
        const int64_t ci = int64_t(std::clamp(std::floor(u / tolerance), -1e15, 1e15));
        const int64_t cj = int64_t(std::clamp(std::floor(v / tolerance), -1e15, 1e15));
        for (int64_t di = -1; di <= 1; ++di) {
            for (int64_t dj = -1; dj <= 1; ++dj) {
                const auto it = cells.find(cell_key(ci + di, cj + dj));
                if (it == cells.end()) continue;
                for (int64_t other : it->second) {
                    if (close_corners(layout, other, i, tolerance2)) sets.join(other, i);
                }
            }
        }
        cells[cell_key(ci, cj)].push_back(i);
    }
}

// An open-addressing table from 64-bit keys to indices >= 0: the weld looks
// up many cells that hold nothing, where std::unordered_map costs a division
// and a cache miss per bucket.
class KeyIndex {
public:
    explicit KeyIndex(size_t count) {
        int bits = 4;
        while ((size_t(1) << bits) < 2 * count) ++bits;
        shift_ = 64 - bits;
        keys_.resize(size_t(1) << bits);
        values_.assign(size_t(1) << bits, -1);
    }
    // The index stored for `key`, or -1.
    int64_t find(uint64_t key) const {
        for (size_t s = slot(key);; s = (s + 1) & (values_.size() - 1)) {
            if (values_[s] < 0 || keys_[s] == key) return values_[s];
        }
    }
    // Stores `value` for `key` unless the key has one; returns the key's index.
    // At most `count` keys (the table is never full).
    int64_t insert(uint64_t key, int64_t value) {
        for (size_t s = slot(key);; s = (s + 1) & (values_.size() - 1)) {
            if (values_[s] < 0) {
                keys_[s] = key;
                return values_[s] = value;
            }
            if (keys_[s] == key) return values_[s];
        }
    }

private:
    size_t slot(uint64_t key) const { return size_t((key * 0x9E3779B97F4A7C15ull) >> shift_); }
    int shift_;
    std::vector<uint64_t> keys_;
    std::vector<int64_t> values_;
};

// Joins the first pair of here x there closer than the tolerance, if any.
void join_first_close_pair(const UvLayout& layout, const int64_t* here, const int64_t* here_end, const int64_t* there,
                           const int64_t* there_end, double tolerance2, DisjointSets& sets) {
    for (const int64_t* p = here; p != here_end; ++p) {
        for (const int64_t* q = there; q != there_end; ++q) {
            if (close_corners(layout, *p, *q, tolerance2)) {
                sets.join(*p, *q);
                return;
            }
        }
    }
}

// join_by_pairs' result in near-linear time, however many points crowd
// together. Cells are half the tolerance wide, so two points of one cell are
// less than 0.71 tolerance apart: a cell's points join its first without a
// test. Two cells need only one pair closer than the tolerance, found or ruled
// out once (the test stops at the first; only points spread so that no pair
// of two crowded cells is close cost the product of their counts). Cells up
// to 3 apart are paired, all a pair closer than the tolerance can lie in when
// the cell coordinates are rounded. Those are exact to 2^-23 of a cell below
// 2^30 cells from 0; beyond that, or with a tolerance whose square leaves the
// normal doubles, false and nothing joined: the caller falls back.
bool join_by_cells(const UvLayout& layout, double tolerance, const std::vector<int64_t>& points,
                   DisjointSets& sets) {
    if (!(tolerance >= 1e-140 && tolerance <= 1e140)) return false;
    const double size = 0.5 * tolerance;
    constexpr double kExact = 1073741824.0;  // 2^30
    const size_t n = points.size();
    std::vector<int32_t> cell_i(n), cell_j(n);
    for (size_t p = 0; p < n; ++p) {
        const double ci = std::floor(layout.uvs[2 * points[p]] / size);
        const double cj = std::floor(layout.uvs[2 * points[p] + 1] / size);
        if (!(std::abs(ci) < kExact && std::abs(cj) < kExact)) return false;
        cell_i[p] = int32_t(ci), cell_j[p] = int32_t(cj);
    }
    // Cells numbered in order of their first point; their points listed
    // together (start[c] .. start[c + 1]), in index order.
    KeyIndex index(n);
    std::vector<int64_t> cell_of(n), first_point;
    for (size_t p = 0; p < n; ++p) {
        cell_of[p] = index.insert(cell_key(cell_i[p], cell_j[p]), int64_t(first_point.size()));
        if (cell_of[p] == int64_t(first_point.size())) first_point.push_back(int64_t(p));
    }
    const size_t cells = first_point.size();
    std::vector<int64_t> start(cells + 1, 0), members(n);
    for (size_t p = 0; p < n; ++p) ++start[size_t(cell_of[p]) + 1];
    for (size_t c = 0; c < cells; ++c) start[c + 1] += start[c];
    std::vector<int64_t> next(start.begin(), start.end() - 1);
    for (size_t p = 0; p < n; ++p) {
        const size_t c = size_t(cell_of[p]);
        if (next[c] > start[c]) sets.join(members[size_t(start[c])], points[p]);
        members[size_t(next[c]++)] = points[p];
    }
    // Each unordered pair of cells once: offsets after (0, 0) in (di, dj) order,
    // within 3 cells and at most a tolerance (2 cells) apart across the gap.
    std::vector<std::pair<int32_t, int32_t>> offsets;
    for (int32_t di = 0; di <= 3; ++di) {
        for (int32_t dj = -3; dj <= 3; ++dj) {
            if (di == 0 && dj <= 0) continue;
            const int32_t gi = std::max(di - 1, 0), gj = std::max(std::abs(dj) - 1, 0);
            if (gi * gi + gj * gj <= 4) offsets.emplace_back(di, dj);
        }
    }
    const double tolerance2 = tolerance * tolerance;
    const int64_t* m = members.data();
    for (size_t a = 0; a < cells; ++a) {
        const size_t p = size_t(first_point[a]);
        for (const auto& [di, dj] : offsets) {
            const int64_t b = index.find(cell_key(cell_i[p] + di, cell_j[p] + dj));
            if (b < 0 || sets.find(m[start[a]]) == sets.find(m[start[size_t(b)]])) continue;
            const int64_t* there = m + start[size_t(b)];
            join_first_close_pair(layout, m + start[a], m + start[a + 1], there, m + start[size_t(b) + 1], tolerance2,
                                  sets);
        }
    }
    return true;
}

// Joins the used UV indices whose values are bit-identical or closer than
// `tolerance`. Bit-identical values first: one point per value (its first
// index), so thousands of corners at one UV (a collapsed chart, UVs left at 0)
// are one point to the distance tests. The components do not depend on the
// order of the joins, and the sets keep the smallest index as root:
// deterministic.
void join_close_corners(const UvLayout& layout, double tolerance, DisjointSets& sets) {
    std::vector<uint8_t> used(size_t(layout.uv_count), 0);
    for (int64_t k = 0; k < 3 * layout.triangle_count; ++k) used[size_t(layout.triangles[k])] = 1;
    KeyIndex first_with_value(size_t(std::count(used.begin(), used.end(), uint8_t(1))));
    std::vector<int64_t> points;
    for (int64_t i = 0; i < layout.uv_count; ++i) {
        if (!used[size_t(i)]) continue;
        const int64_t first = first_with_value.insert(uv_key(layout.uvs + 2 * i), i);
        if (first == i) {
            points.push_back(i);
        } else {
            sets.join(first, i);
        }
    }
    if (!(tolerance > 0.0) || points.size() < 2) return;
    if (!join_by_cells(layout, tolerance, points, sets)) join_by_pairs(layout, tolerance, points, sets);
}

void check_tolerance(double tolerance) {
    if (!(tolerance >= 0.0) || !std::isfinite(tolerance)) {
        LMREFINE_THROW(InvalidArgument, "tolerance must be a finite UV distance >= 0 (got " +
                                            std::to_string(tolerance) + "); pass 0 to join bit-identical corners only");
    }
}

}  // namespace

std::vector<int64_t> weld_corners(const UvLayout& layout, double tolerance) {
    check_tolerance(tolerance);
    DisjointSets sets(size_t(layout.uv_count));
    join_close_corners(layout, tolerance, sets);
    std::vector<int64_t> weld(size_t(layout.uv_count));
    for (int64_t i = 0; i < layout.uv_count; ++i) weld[size_t(i)] = sets.find(i);
    return weld;
}

Charts find_charts(const UvLayout& layout, double tolerance) {
    check_tolerance(tolerance);
    // Union-find over UV indices: every corner of a triangle joins its first
    // corner, and close (or equal) UV values join their indices.
    DisjointSets sets(size_t(layout.uv_count));
    join_close_corners(layout, tolerance, sets);
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        const int32_t* tri = layout.triangles + 3 * t;
        sets.join(tri[0], tri[1]);
        sets.join(tri[0], tri[2]);
    }
    Charts charts;
    charts.triangle_chart.resize(size_t(layout.triangle_count));
    std::unordered_map<int64_t, int32_t> chart_of_root;
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        const int64_t root = sets.find(layout.triangles[3 * t]);
        const auto [it, inserted] = chart_of_root.emplace(root, charts.count);
        if (inserted) ++charts.count;
        charts.triangle_chart[size_t(t)] = it->second;
    }
    return charts;
}

}  // namespace lmrefine
