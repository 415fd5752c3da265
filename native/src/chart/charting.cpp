#include "lmrefine/chart/charting.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <functional>
#include <numeric>
#include <string>
#include <unordered_map>

#include <glm/geometric.hpp>

#include "lmrefine/core/error.h"

namespace lmrefine {
namespace {

// A face is degenerate when its area is below this fraction of its longest
// edge squared (a sliver no unwrap can give a shape).
constexpr double kSliver = 1e-10;
// Shading normals this close (cosine of about 0.8 degrees) at an edge's
// ends are one normal: the edge is smooth-shaded (float rounding of an
// exported normal stays far below).
constexpr double kSmoothCos = 0.9999;

glm::dvec3 position(const SurfaceMesh& mesh, int64_t v) {
    const float* p = mesh.positions + 3 * v;
    return {p[0], p[1], p[2]};
}

// Whether the shading normals of two corners agree; a zero, non-finite or
// absurd normal agrees with nothing (the edge stays hard).
bool same_normal(const SurfaceMesh& mesh, int64_t corner_a, int64_t corner_b) {
    const float* a = mesh.corner_normals + 3 * corner_a;
    const float* b = mesh.corner_normals + 3 * corner_b;
    const glm::dvec3 na(a[0], a[1], a[2]), nb(b[0], b[1], b[2]);
    const double lengths = std::sqrt(glm::dot(na, na) * glm::dot(nb, nb));
    if (!std::isfinite(lengths) || !(lengths > 0.0)) return false;
    return glm::dot(na, nb) >= kSmoothCos * lengths;
}

int64_t find_root(std::vector<int32_t>& parent, int64_t x) {
    while (parent[size_t(x)] != x) x = parent[size_t(x)] = parent[size_t(parent[size_t(x)])];
    return x;
}

uint64_t cell_key(int64_t i, int64_t j, int64_t k) {
    // 21 bits per axis: a collision only costs a distance test.
    return (uint64_t(i) & 0x1FFFFF) | ((uint64_t(j) & 0x1FFFFF) << 21) | ((uint64_t(k) & 0x1FFFFF) << 42);
}

}  // namespace

void validate_surface(const SurfaceMesh& mesh) {
    LMREFINE_REQUIRE(mesh.triangle_count > 0, "triangles is empty: give at least one triangle");
    for (int64_t i = 0; i < 3 * mesh.triangle_count; ++i) {
        const int64_t v = mesh.triangles[i];
        if (v < 0 || v >= mesh.vertex_count) {
            LMREFINE_THROW(InvalidArgument, "triangles[" + std::to_string(i / 3) + ", " + std::to_string(i % 3) +
                                                "] is " + std::to_string(v) + ", outside the " +
                                                std::to_string(mesh.vertex_count) + " positions");
        }
        const float* p = mesh.positions + 3 * v;
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
            LMREFINE_THROW(InvalidArgument, "positions[" + std::to_string(v) +
                                                "] is not finite (NaN or Inf): fix or remove that vertex");
        }
    }
}

std::vector<int32_t> weld_positions(const SurfaceMesh& mesh, double tolerance) {
    std::vector<int32_t> parent(size_t(mesh.vertex_count));
    std::iota(parent.begin(), parent.end(), 0);
    const auto join = [&](int64_t a, int64_t b) {
        a = find_root(parent, a), b = find_root(parent, b);
        if (a != b) parent[size_t(std::max(a, b))] = int32_t(std::min(a, b));
    };
    std::vector<uint8_t> used(size_t(mesh.vertex_count), 0);
    for (int64_t i = 0; i < 3 * mesh.triangle_count; ++i) used[size_t(mesh.triangles[i])] = 1;
    // Equal positions first (by value: -0 is 0), so only distinct positions
    // meet in the grid below and a pile of copies costs nothing.
    std::unordered_map<uint64_t, std::vector<int32_t>> exact;
    exact.reserve(size_t(mesh.vertex_count));
    std::vector<int32_t> distinct;
    for (int64_t v = 0; v < mesh.vertex_count; ++v) {
        if (!used[size_t(v)]) continue;
        const float* p = mesh.positions + 3 * v;
        uint64_t hash = 1469598103934665603ull;
        for (int k = 0; k < 3; ++k) hash = (hash ^ std::hash<float>{}(p[k] + 0.0f)) * 1099511628211ull;
        bool found = false;
        for (int32_t w : exact[hash]) {
            const float* q = mesh.positions + 3 * int64_t(w);
            if (q[0] == p[0] && q[1] == p[1] && q[2] == p[2]) {
                join(w, v);
                found = true;
                break;
            }
        }
        if (!found) exact[hash].push_back(int32_t(v)), distinct.push_back(int32_t(v));
    }
    if (!(tolerance > 0.0)) {
        for (int64_t v = 0; v < mesh.vertex_count; ++v) parent[size_t(v)] = int32_t(find_root(parent, v));
        return parent;
    }
    // A hash grid of cells of the tolerance's size: each position meets the
    // positions of its 3 x 3 x 3 cells. Visited in index order, roots are
    // the smallest index.
    const double tolerance2 = tolerance * tolerance;
    std::unordered_map<uint64_t, std::vector<int32_t>> cells;
    cells.reserve(distinct.size());
    for (int32_t v : distinct) {
        const glm::dvec3 p = position(mesh, v);
        // Clamped so a huge coordinate cannot overflow the cast.
        const auto index = [&](double x) { return int64_t(std::floor(std::clamp(x / tolerance, -1e15, 1e15))); };
        const int64_t ci = index(p.x), cj = index(p.y), ck = index(p.z);
        for (int64_t di = -1; di <= 1; ++di) {
            for (int64_t dj = -1; dj <= 1; ++dj) {
                for (int64_t dk = -1; dk <= 1; ++dk) {
                    const auto found = cells.find(cell_key(ci + di, cj + dj, ck + dk));
                    if (found == cells.end()) continue;
                    for (int32_t w : found->second) {
                        const glm::dvec3 d = position(mesh, w) - p;
                        if (glm::dot(d, d) <= tolerance2) join(w, v);
                    }
                }
            }
        }
        cells[cell_key(ci, cj, ck)].push_back(v);
    }
    for (int64_t v = 0; v < mesh.vertex_count; ++v) parent[size_t(v)] = int32_t(find_root(parent, v));
    return parent;
}

SurfaceFaces surface_faces(const SurfaceMesh& mesh, const std::vector<int32_t>& welded) {
    const int64_t count = mesh.triangle_count;
    SurfaceFaces faces;
    faces.normal.assign(size_t(count), glm::dvec3(0.0));
    faces.area.assign(size_t(count), 0.0);
    faces.degenerate.assign(size_t(count), 0);
    faces.neighbour.assign(size_t(3 * count), -1);
    faces.smooth.assign(size_t(3 * count), 0);
    for (int64_t t = 0; t < count; ++t) {
        const int32_t* tri = mesh.triangles + 3 * t;
        const glm::dvec3 a = position(mesh, tri[0]), b = position(mesh, tri[1]), c = position(mesh, tri[2]);
        const glm::dvec3 cross = glm::cross(b - a, c - a);
        const double twice_area = glm::length(cross);
        const double longest2 = std::max({glm::dot(b - a, b - a), glm::dot(c - a, c - a), glm::dot(c - b, c - b)});
        const int32_t wa = welded[size_t(tri[0])], wb = welded[size_t(tri[1])], wc = welded[size_t(tri[2])];
        const bool collapsed = wa == wb || wb == wc || wa == wc;
        if (collapsed || !(twice_area > kSliver * longest2) || !std::isfinite(twice_area)) {
            faces.degenerate[size_t(t)] = 1;
            continue;
        }
        faces.normal[size_t(t)] = cross / twice_area;
        faces.area[size_t(t)] = 0.5 * twice_area;
    }
    // Welded edges: two faces are neighbours across an edge only they use,
    // wound in opposite directions (a consistently oriented manifold).
    struct Edge {
        int64_t face_edge[2] = {-1, -1};  // 3 * face + k of its first two uses
        bool forward[2] = {true, true};   // wound from the smaller welded index to the larger
        int uses = 0;
    };
    std::unordered_map<uint64_t, Edge> edges;
    edges.reserve(size_t(3 * count));
    for (int64_t t = 0; t < count; ++t) {
        if (faces.degenerate[size_t(t)]) continue;
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = uint32_t(welded[size_t(mesh.triangles[3 * t + k])]);
            const uint32_t b = uint32_t(welded[size_t(mesh.triangles[3 * t + (k + 1) % 3])]);
            Edge& edge = edges[(uint64_t(std::min(a, b)) << 32) | std::max(a, b)];
            if (edge.uses < 2) {
                edge.face_edge[edge.uses] = 3 * t + k;
                edge.forward[edge.uses] = a < b;
            }
            ++edge.uses;
        }
    }
    for (const auto& entry : edges) {
        const Edge& edge = entry.second;
        if (edge.uses != 2 || edge.forward[0] == edge.forward[1]) continue;
        faces.neighbour[size_t(edge.face_edge[0])] = edge.face_edge[1] / 3;
        faces.neighbour[size_t(edge.face_edge[1])] = edge.face_edge[0] / 3;
        if (!mesh.corner_normals) continue;
        // Wound in opposite directions: the first face's edge start is the
        // second's edge end, and the other way round.
        const int64_t f = edge.face_edge[0], g = edge.face_edge[1];
        const int64_t f_start = f, f_end = 3 * (f / 3) + (f % 3 + 1) % 3;
        const int64_t g_start = g, g_end = 3 * (g / 3) + (g % 3 + 1) % 3;
        const uint8_t smooth = same_normal(mesh, f_start, g_end) && same_normal(mesh, f_end, g_start);
        faces.smooth[size_t(f)] = faces.smooth[size_t(g)] = smooth;
    }
    faces.polygon_next.resize(size_t(count));
    std::iota(faces.polygon_next.begin(), faces.polygon_next.end(), int64_t(0));
    faces.polygon_root = faces.polygon_next;
    if (mesh.polygons) {
        // Each polygon's faces linked into a cycle, in index order.
        std::unordered_map<int32_t, std::pair<int64_t, int64_t>> ends;  // polygon -> (first, last) face
        for (int64_t t = 0; t < count; ++t) {
            const auto [it, inserted] = ends.emplace(mesh.polygons[t], std::make_pair(t, t));
            faces.polygon_root[size_t(t)] = it->second.first;
            if (inserted) continue;
            faces.polygon_next[size_t(it->second.second)] = t;
            faces.polygon_next[size_t(t)] = it->second.first;
            it->second.second = t;
        }
    }
    return faces;
}

std::vector<std::vector<int64_t>> grow_charts(const SurfaceFaces& faces, const std::vector<int64_t>& face_ids,
                                              double angle_radians, double smooth_angle_radians) {
    // -2: not offered; -1: offered, not yet in a chart; >= 0: its chart.
    std::vector<int64_t> state(faces.area.size(), -2);
    for (int64_t f : face_ids) state[size_t(f)] = -1;
    // Larger faces seed first, by area classes 1.1% wide (log2 in 64ths):
    // faces of (nearly) one size, which rounding alone tells apart, seed in
    // index order, so a regular mesh charts as its indices say.
    std::vector<std::pair<int64_t, int64_t>> seeds;  // (-area class, face)
    seeds.reserve(face_ids.size());
    for (int64_t f : face_ids) seeds.emplace_back(-int64_t(std::floor(std::log2(faces.area[size_t(f)]) * 64.0)), f);
    std::sort(seeds.begin(), seeds.end());
    const double min_cos = std::cos(angle_radians);
    const double smooth_min_cos = std::cos(smooth_angle_radians);
    std::vector<std::vector<int64_t>> charts;
    std::deque<int64_t> queue;
    // f joins chart `id`, and the offered faces of its polygon with it.
    const auto join = [&](int64_t f, int64_t id) {
        for (int64_t g = f;;) {
            if (state[size_t(g)] == -1) {
                state[size_t(g)] = id;
                queue.push_back(g);
            }
            g = faces.polygon_next[size_t(g)];
            if (g == f) break;
        }
    };
    for (const auto& [size_class, seed] : seeds) {
        if (state[size_t(seed)] != -1) continue;
        const int64_t id = int64_t(charts.size());
        const glm::dvec3 axis = faces.normal[size_t(seed)];
        std::vector<int64_t> members;
        join(seed, id);
        while (!queue.empty()) {
            const int64_t f = queue.front();
            queue.pop_front();
            members.push_back(f);
            for (int k = 0; k < 3; ++k) {
                const int64_t g = faces.neighbour[size_t(3 * f + k)];
                if (g < 0 || state[size_t(g)] != -1) continue;
                const double limit = faces.smooth[size_t(3 * f + k)] ? smooth_min_cos : min_cos;
                if (glm::dot(faces.normal[size_t(g)], axis) < limit) continue;
                join(g, id);
            }
        }
        std::sort(members.begin(), members.end());
        charts.push_back(std::move(members));
    }
    return charts;
}

std::vector<std::vector<int64_t>> bisect_chart(const SurfaceMesh& mesh, const SurfaceFaces& faces,
                                               const std::vector<int64_t>& chart) {
    std::vector<glm::dvec3> centroid(chart.size());
    glm::dvec3 lo(1e300), hi(-1e300);
    for (size_t i = 0; i < chart.size(); ++i) {
        const int32_t* tri = mesh.triangles + 3 * chart[i];
        centroid[i] = (position(mesh, tri[0]) + position(mesh, tri[1]) + position(mesh, tri[2])) / 3.0;
        lo = glm::min(lo, centroid[i]), hi = glm::max(hi, centroid[i]);
    }
    const glm::dvec3 extent = hi - lo;
    const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
    // A face sorts at the mean centroid of its polygon's faces in the chart,
    // then by polygon, so a polygon's faces are neighbours in the order.
    std::unordered_map<int64_t, std::pair<double, int>> polygon_sum;  // polygon root -> (sum, count)
    for (size_t i = 0; i < chart.size(); ++i) {
        auto& entry = polygon_sum[faces.polygon_root[size_t(chart[i])]];
        entry.first += centroid[i][axis], ++entry.second;
    }
    std::vector<double> key(chart.size());
    std::vector<int64_t> polygon(chart.size());
    for (size_t i = 0; i < chart.size(); ++i) {
        polygon[i] = faces.polygon_root[size_t(chart[i])];
        const auto& entry = polygon_sum[polygon[i]];
        key[i] = entry.first / entry.second;
    }
    std::vector<size_t> order(chart.size());
    std::iota(order.begin(), order.end(), size_t(0));
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
        if (key[a] != key[b]) return key[a] < key[b];
        if (polygon[a] != polygon[b]) return polygon[a] < polygon[b];
        return chart[a] < chart[b];
    });
    // The cut at the median, moved past the polygon it falls in (back to its
    // start when that polygon reaches the end).
    size_t cut = order.size() / 2;
    while (cut < order.size() && polygon[order[cut]] == polygon[order[cut - 1]]) ++cut;
    if (cut == order.size()) {
        cut = order.size() / 2;
        while (cut > 0 && polygon[order[cut]] == polygon[order[cut - 1]]) --cut;
        if (cut == 0) cut = order.size() / 2;  // one polygon: cut it
    }
    // Each half grown with no angle limit: its edge-connected parts.
    std::vector<std::vector<int64_t>> parts;
    for (int half = 0; half < 2; ++half) {
        std::vector<int64_t> ids;
        const size_t begin = half == 0 ? 0 : cut, end = half == 0 ? cut : order.size();
        for (size_t k = begin; k < end; ++k) ids.push_back(chart[order[k]]);
        for (auto& part : grow_charts(faces, ids, 4.0, 4.0)) parts.push_back(std::move(part));
    }
    return parts;
}

}  // namespace lmrefine
