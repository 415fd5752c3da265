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

// Joins the used UV indices whose values are bit-identical or closer than
// `tolerance`: a hash grid of cells of the tolerance's size, so each corner
// only meets the corners of its 3 x 3 cells. Corners are visited in index
// order and the sets keep the smallest index as root: deterministic.
void join_close_corners(const UvLayout& layout, double tolerance, DisjointSets& sets) {
    std::vector<uint8_t> used(size_t(layout.uv_count), 0);
    for (int64_t k = 0; k < 3 * layout.triangle_count; ++k) used[size_t(layout.triangles[k])] = 1;
    if (!(tolerance > 0.0)) {
        std::unordered_map<uint64_t, int64_t> first_with_value;
        first_with_value.reserve(size_t(layout.uv_count));
        for (int64_t i = 0; i < layout.uv_count; ++i) {
            if (!used[size_t(i)]) continue;
            const auto [it, inserted] = first_with_value.emplace(uv_key(layout.uvs + 2 * i), i);
            if (!inserted) sets.join(it->second, i);
        }
        return;
    }
    std::unordered_map<uint64_t, std::vector<int64_t>> cells;
    cells.reserve(size_t(layout.uv_count));
    const double tolerance2 = tolerance * tolerance;
    for (int64_t i = 0; i < layout.uv_count; ++i) {
        if (!used[size_t(i)]) continue;
        const double u = layout.uvs[2 * i], v = layout.uvs[2 * i + 1];
        // Clamped so a huge UV cannot overflow the cast (a shared cell only costs a distance test).
        const int64_t ci = int64_t(std::clamp(std::floor(u / tolerance), -1e15, 1e15));
        const int64_t cj = int64_t(std::clamp(std::floor(v / tolerance), -1e15, 1e15));
        for (int64_t di = -1; di <= 1; ++di) {
            for (int64_t dj = -1; dj <= 1; ++dj) {
                const auto it = cells.find(cell_key(ci + di, cj + dj));
                if (it == cells.end()) continue;
                for (int64_t other : it->second) {
                    const double du = layout.uvs[2 * other] - u, dv = layout.uvs[2 * other + 1] - v;
                    if (du * du + dv * dv < tolerance2 || (du == 0.0 && dv == 0.0)) sets.join(other, i);
                }
            }
        }
        cells[cell_key(ci, cj)].push_back(i);
    }
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
