#include "lmrefine/layout/chart.h"

#include <cstring>
#include <numeric>
#include <unordered_map>

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

}  // namespace

Charts find_charts(const UvLayout& layout) {
    // Union-find over UV indices: every corner of a triangle joins its first
    // corner, and equal UV values join through one representative index.
    DisjointSets sets(size_t(layout.uv_count));
    std::unordered_map<uint64_t, int64_t> first_with_value;
    first_with_value.reserve(size_t(layout.uv_count));
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        const int32_t* tri = layout.triangles + 3 * t;
        for (int k = 0; k < 3; ++k) {
            sets.join(tri[0], tri[k]);
            const auto [it, inserted] = first_with_value.emplace(uv_key(layout.uvs + 2 * tri[k]), tri[k]);
            if (!inserted) sets.join(it->second, tri[k]);
        }
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
