#include "texel_table.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "lmrefine/chart.h"
#include "lmrefine/coverage.h"
#include "lmrefine/scene.h"
#include "lmrefine/texel_space.h"

namespace lmrefine {
namespace {

// The point of segment ab nearest to p.
glm::dvec2 nearest_on_segment(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b) {
    const glm::dvec2 ab = b - a;
    const double length2 = glm::dot(ab, ab);
    const double t = length2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / length2, 0.0, 1.0) : 0.0;
    return a + ab * t;
}

// Barycentrics of p in triangle (a, b, c); the triangle is not degenerate in UV
// (rasterization skipped those).
glm::dvec3 barycentric(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
    const glm::dvec2 e1 = b - a, e2 = c - a, d = p - a;
    const double det = e1.x * e2.y - e1.y * e2.x;
    const double u = (d.x * e2.y - d.y * e2.x) / det, v = (e1.x * d.y - e1.y * d.x) / det;
    return {1.0 - u - v, u, v};
}

}  // namespace

TexelTable build_texel_table(const Scene& scene, const std::vector<int>& meshes, int width, int height) {
    TexelTable table;
    table.width = width;
    table.height = height;
    table.texel_chart.assign(size_t(int64_t(width) * height), -1);
    struct Entry {
        int64_t texel;
        int32_t mesh;
        int64_t triangle;
    };
    std::vector<Entry> entries;
    int32_t chart_base = 0;
    for (int id : meshes) {
        const Mesh& mesh = scene.meshes()[size_t(id)];
        const int64_t count = mesh.triangle_count();
        std::vector<int32_t> corners(size_t(count * 3));
        std::iota(corners.begin(), corners.end(), 0);
        const UvLayout layout{&mesh.uvs[0].x, count * 3, corners.data(), count};
        const Charts charts = find_charts(layout);
        for_each_covered_texel(layout, width, height, [&](int64_t t, int row, int col) {
            if (mesh.degenerate[size_t(t)]) return;
            const int64_t texel = int64_t(row) * width + col;
            entries.push_back({texel, id, t});
            if (table.texel_chart[size_t(texel)] < 0) table.texel_chart[size_t(texel)] = chart_base + charts.triangle_chart[size_t(t)];
        });
        chart_base += charts.count;
    }
    // Stable: candidates keep mesh then triangle order, so the result is deterministic.
    std::stable_sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.texel < b.texel; });
    table.candidate_mesh.reserve(entries.size());
    table.candidate_triangle.reserve(entries.size());
    for (size_t i = 0; i < entries.size(); ++i) {
        if (i == 0 || entries[i].texel != entries[i - 1].texel) {
            table.texels.push_back(entries[i].texel);
            table.offsets.push_back(int64_t(i));
        }
        table.candidate_mesh.push_back(entries[i].mesh);
        table.candidate_triangle.push_back(entries[i].triangle);
    }
    table.offsets.push_back(int64_t(entries.size()));
    return table;
}

SurfacePoint texel_surface_point(const Scene& scene, const TexelTable& table, int64_t k, double px, double py,
                                 float* texel_size) {
    const glm::dvec2 p(px, py);
    int64_t best = -1;
    double best_distance = std::numeric_limits<double>::infinity();
    glm::dvec3 best_weights(1.0 / 3.0);
    glm::dvec2 corner[3];
    for (int64_t c = table.offsets[size_t(k)]; c < table.offsets[size_t(k) + 1]; ++c) {
        const Mesh& mesh = scene.meshes()[size_t(table.candidate_mesh[size_t(c)])];
        const int64_t t = table.candidate_triangle[size_t(c)];
        for (int i = 0; i < 3; ++i) {
            const glm::vec2& uv = mesh.uvs[size_t(3 * t + i)];
            corner[i] = uv_to_pixel(glm::dvec2(uv), table.width, table.height);
        }
        glm::dvec3 w = barycentric(p, corner[0], corner[1], corner[2]);
        double distance = 0.0;
        if (w.x < 0.0 || w.y < 0.0 || w.z < 0.0) {
            glm::dvec2 nearest = nearest_on_segment(p, corner[0], corner[1]);
            for (int e = 1; e < 3; ++e) {
                const glm::dvec2 q = nearest_on_segment(p, corner[e], corner[(e + 1) % 3]);
                if (glm::dot(q - p, q - p) < glm::dot(nearest - p, nearest - p)) nearest = q;
            }
            distance = glm::length(nearest - p);
            w = glm::clamp(barycentric(nearest, corner[0], corner[1], corner[2]), 0.0, 1.0);
            w /= (w.x + w.y + w.z);
        }
        if (distance < best_distance) {
            best_distance = distance;
            best = c;
            best_weights = w;
            if (distance == 0.0) break;
        }
    }
    const Mesh& mesh = scene.meshes()[size_t(table.candidate_mesh[size_t(best)])];
    const int64_t t = table.candidate_triangle[size_t(best)];
    const int32_t* v = &mesh.triangles[size_t(3 * t)];
    const glm::vec3 w(best_weights);
    const glm::vec3 &a = mesh.positions[v[0]], &b = mesh.positions[v[1]], &c = mesh.positions[v[2]];
    SurfacePoint point;
    point.position = a * w.x + b * w.y + c * w.z;
    const glm::vec3 cross = glm::cross(b - a, c - a);
    glm::vec3 ng = glm::normalize(cross);
    glm::vec3 ns = ng;
    if (!mesh.normals.empty()) {
        const glm::vec3* n = &mesh.normals[size_t(3 * t)];
        const glm::vec3 interpolated = n[0] * w.x + n[1] * w.y + n[2] * w.z;
        if (glm::length(interpolated) > 0.0f) {
            ns = glm::normalize(interpolated);
            // The given normals say which side is the front; the winding may disagree.
            if (glm::dot(ns, ng) < 0.0f) ng = -ng;
        }
    }
    point.geometric_normal = ng;
    point.shading_normal = ns;
    if (texel_size) {
        for (int i = 0; i < 3; ++i) corner[i] = uv_to_pixel(glm::dvec2(mesh.uvs[size_t(3 * t + i)]), table.width, table.height);
        const glm::dvec2 e1 = corner[1] - corner[0], e2 = corner[2] - corner[0];
        const double pixel_area = std::abs(e1.x * e2.y - e1.y * e2.x);
        *texel_size = float(std::sqrt(0.5 * double(glm::length(cross)) / std::max(pixel_area, 1e-30)));
    }
    return point;
}

}  // namespace lmrefine
