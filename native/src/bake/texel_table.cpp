#include "texel_table.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "lmrefine/bake/dilation.h"
#include "lmrefine/layout/chart.h"
#include "lmrefine/layout/coverage.h"
#include "lmrefine/bake/scene.h"
#include "lmrefine/core/nearest_point.h"
#include "lmrefine/core/texel_space.h"

namespace lmrefine {

TexelTable build_texel_table(const Scene& scene, const std::vector<int>& meshes, int width, int height) {
    TexelTable table;
    table.width = width;
    table.height = height;
    table.texel_chart.assign(size_t(int64_t(width) * height), -1);
    NearCharts near(width, height);
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
        near.add(layout, charts.triangle_chart.data(), chart_base, mesh.degenerate.data(), table.texel_chart);
        chart_base += charts.count;
    }
    table.near_chart = near.take(table.texel_chart);
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

void TexelGeometry::load(const Scene& scene, const TexelTable& table, int64_t k) {
    candidates_.clear();
    for (int64_t i = table.offsets[size_t(k)]; i < table.offsets[size_t(k) + 1]; ++i) {
        const Mesh& mesh = scene.meshes()[size_t(table.candidate_mesh[size_t(i)])];
        const int64_t t = table.candidate_triangle[size_t(i)];
        Candidate c;
        for (int j = 0; j < 3; ++j) {
            c.corner[j] = uv_to_pixel(glm::dvec2(mesh.uvs[size_t(3 * t + j)]), table.width, table.height);
            c.position[j] = mesh.positions[size_t(mesh.triangles[size_t(3 * t + j)])];
        }
        // Rasterization skipped triangles of zero UV area, so det != 0.
        const glm::dvec2 e1 = c.corner[1] - c.corner[0], e2 = c.corner[2] - c.corner[0];
        const double inv = 1.0 / (e1.x * e2.y - e1.y * e2.x);
        const double u_x = e2.y * inv, u_y = -e2.x * inv, v_x = -e1.y * inv, v_y = e1.x * inv;
        const double u_0 = -(u_x * c.corner[0].x + u_y * c.corner[0].y), v_0 = -(v_x * c.corner[0].x + v_y * c.corner[0].y);
        c.wx = {-u_x - v_x, u_x, v_x};
        c.wy = {-u_y - v_y, u_y, v_y};
        c.w0 = {1.0 - u_0 - v_0, u_0, v_0};
        const glm::vec3 cross = glm::cross(c.position[1] - c.position[0], c.position[2] - c.position[0]);
        c.geometric_normal = glm::normalize(cross);
        c.smooth = !mesh.normals.empty();
        for (int j = 0; j < 3; ++j) c.normal[j] = c.smooth ? mesh.normals[size_t(3 * t + j)] : c.geometric_normal;
        if (candidates_.empty()) {
            texel_size_ = float(std::sqrt(0.5 * double(glm::length(cross)) * std::abs(inv)));
        }
        candidates_.push_back(c);
    }
}

SurfacePoint TexelGeometry::point_on(const Candidate& c, const glm::dvec3& weights) const {
    const glm::vec3 w(weights);
    SurfacePoint point;
    point.position = c.position[0] * w.x + c.position[1] * w.y + c.position[2] * w.z;
    point.geometric_normal = c.geometric_normal;
    point.shading_normal = c.geometric_normal;
    if (c.smooth) {
        const glm::vec3 n = c.normal[0] * w.x + c.normal[1] * w.y + c.normal[2] * w.z;
        const float length = glm::length(n);
        if (length > 0.0f) {
            point.shading_normal = n / length;
            // The given normals say which side is the front; the winding may disagree.
            if (glm::dot(point.shading_normal, point.geometric_normal) < 0.0f) point.geometric_normal = -point.geometric_normal;
        }
    }
    return point;
}

SurfacePoint TexelGeometry::at(double px, double py) const {
    for (const Candidate& c : candidates_) {
        const glm::dvec3 w = c.wx * px + c.wy * py + c.w0;
        if (w.x >= 0.0 && w.y >= 0.0 && w.z >= 0.0) return point_on(c, w);
    }
    // Outside every candidate (a texel the chart covers only partly): the
    // nearest point of the nearest triangle, moved a little towards the
    // triangle's centre. A point on the border line itself reads a contact
    // line as shadow: where a wall stands on a floor, a ray from the wall's
    // bottom edge starts in the floor's plane and finds the floor.
    const glm::dvec2 p(px, py);
    const Candidate* best = &candidates_.front();
    glm::dvec2 best_point = p;
    double best_distance = std::numeric_limits<double>::infinity();
    for (const Candidate& c : candidates_) {
        for (int e = 0; e < 3; ++e) {
            const glm::dvec2 q = nearest_on_segment(p, c.corner[e], c.corner[(e + 1) % 3]);
            const double distance = glm::dot(q - p, q - p);
            if (distance < best_distance) {
                best_distance = distance;
                best = &c;
                best_point = q;
            }
        }
    }
    const glm::dvec2 centre = (best->corner[0] + best->corner[1] + best->corner[2]) / 3.0;
    const double to_centre = glm::length(centre - best_point);
    if (to_centre > 0.0) best_point += (centre - best_point) * (std::min(kInset, 0.5 * to_centre) / to_centre);
    glm::dvec3 w = glm::clamp(best->wx * best_point.x + best->wy * best_point.y + best->w0, 0.0, 1.0);
    return point_on(*best, w / (w.x + w.y + w.z));
}

}  // namespace lmrefine
