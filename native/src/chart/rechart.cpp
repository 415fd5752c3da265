#include "lmrefine/chart/rechart.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <unordered_map>
#include <utility>

#include <glm/geometric.hpp>

#include "lmrefine/chart/bounding_box.h"
#include "lmrefine/chart/conformal_map.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/progress.h"

namespace lmrefine {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Below this angle a chart that still folds is no longer grown again with
// a smaller angle but cut in halves (bisect_chart).
constexpr double kMinSplitAngle = 0.5 * kPi / 180.0;
// A degenerate face's stand-in triangle: legs of this fraction of the
// median face's side (it has no area to light, but the baker and
// check_layout need a real triangle).
constexpr double kDegenerateSide = 0.05;
// The largest weld tolerance accepted, relative to the mesh's size.
constexpr double kMaxRelativeWeld = 1e-2;

struct Unwrapped {
    std::vector<int64_t> faces;
    std::vector<std::array<glm::dvec2, 3>> corners;  // per face
};

// The chart's faces as a ChartMesh over its welded vertices, unwrapped;
// false if the conformal map failed or folds.
bool unwrap(const SurfaceMesh& mesh, const std::vector<int32_t>& welded, const std::vector<int64_t>& faces,
            Unwrapped& out) {
    ChartMesh chart;
    std::unordered_map<int32_t, int32_t> local;
    chart.triangles.reserve(faces.size());
    for (int64_t f : faces) {
        std::array<int32_t, 3> tri{};
        for (int k = 0; k < 3; ++k) {
            const int32_t v = welded[size_t(mesh.triangles[3 * f + k])];
            const auto [it, inserted] = local.emplace(v, int32_t(chart.positions.size()));
            if (inserted) {
                const float* p = mesh.positions + 3 * int64_t(v);
                chart.positions.emplace_back(p[0], p[1], p[2]);
            }
            tri[size_t(k)] = it->second;
        }
        chart.triangles.push_back(tri);
    }
    const std::vector<glm::dvec2> uvs = conformal_map(chart);
    if (uvs.empty() || chart_overlaps_itself(uvs, chart.triangles)) return false;
    out.faces = faces;
    out.corners.resize(faces.size());
    for (size_t i = 0; i < faces.size(); ++i) {
        for (int k = 0; k < 3; ++k) out.corners[i][size_t(k)] = uvs[size_t(chart.triangles[i][size_t(k)])];
    }
    return true;
}

}  // namespace

RechartResult rechart(const SurfaceMesh& mesh, const RechartOptions& options, Progress* progress) {
    LMREFINE_REQUIRE(options.angle_degrees > 0.0 && options.angle_degrees < 90.0,
                     "angle must be in (0, 90) degrees (got " + std::to_string(options.angle_degrees) +
                         "): the largest angle between a chart's face normals and its first face's");
    LMREFINE_REQUIRE(options.smooth_angle_degrees > 0.0 && options.smooth_angle_degrees < 90.0,
                     "smooth_angle must be in (0, 90) degrees (got " + std::to_string(options.smooth_angle_degrees) +
                         "): the largest angle between a chart's normals and its first face's across "
                         "smooth-shaded edges");
    LMREFINE_REQUIRE(std::isfinite(options.weld_tolerance),
                     "weld_tolerance must be a finite distance (got " + std::to_string(options.weld_tolerance) + ")");
    validate_surface(mesh);
    glm::dvec3 lo(1e300), hi(-1e300);
    for (int64_t i = 0; i < 3 * mesh.triangle_count; ++i) {
        const float* p = mesh.positions + 3 * int64_t(mesh.triangles[i]);
        lo = glm::min(lo, glm::dvec3(p[0], p[1], p[2])), hi = glm::max(hi, glm::dvec3(p[0], p[1], p[2]));
    }
    const double size = glm::length(hi - lo);
    // Every corner at one point (a mesh scaled to zero) was blamed on any weld tolerance given.
    LMREFINE_REQUIRE(size > 0.0, "every one of the " + std::to_string(mesh.triangle_count) +
                                     " triangles is degenerate, all corners at one position: the mesh has no "
                                     "extent (give the object a non-zero scale), so there is no surface to chart");
    double tolerance = options.weld_tolerance;
    if (tolerance < 0.0) tolerance = kRelativeWeld * size;
    // A tolerance near the mesh's size would merge distinct vertices (and
    // make the weld's grid one cell, quadratic in the vertices).
    if (!(tolerance <= kMaxRelativeWeld * size)) {
        char text[160];
        std::snprintf(text, sizeof text, "weld_tolerance %.3g is more than 1%% of the mesh's size (%.3g across)",
                      tolerance, size);
        LMREFINE_THROW(InvalidArgument, std::string(text) + ": it would merge distinct vertices; give a distance "
                                        "far below the smallest modelled detail, or None (1e-6 of the mesh's size)");
    }
    const std::vector<int32_t> welded = weld_positions(mesh, tolerance);
    const SurfaceFaces faces = surface_faces(mesh, welded);

    RechartResult result;
    for (int64_t v = 0; v < mesh.vertex_count; ++v) result.welded_vertices += welded[size_t(v)] != v;
    std::vector<int64_t> good, bad;
    for (int64_t t = 0; t < mesh.triangle_count; ++t) (faces.degenerate[size_t(t)] ? bad : good).push_back(t);
    LMREFINE_REQUIRE(!good.empty(), "every one of the " + std::to_string(mesh.triangle_count) +
                                        " triangles is degenerate (zero area or two corners at one position): "
                                        "there is no surface to chart");

    // Charts to unwrap, each with the angles it was grown with; a chart
    // whose unwrap folds goes back on the list, grown again with half the
    // angles or cut in halves.
    struct Pending {
        std::vector<int64_t> faces;
        double angle, smooth_angle;
    };
    const double angle = options.angle_degrees * kPi / 180.0;
    const double smooth_angle = options.smooth_angle_degrees * kPi / 180.0;
    std::vector<Pending> pending;
    for (auto& chart : grow_charts(faces, good, angle, smooth_angle)) pending.push_back({std::move(chart), angle, smooth_angle});
    result.grown_charts = int32_t(pending.size());
    if (progress) progress->begin("rechart: unwrap charts", uint64_t(good.size()));
    std::vector<Unwrapped> charts;
    while (!pending.empty()) {
        Pending chart = std::move(pending.back());
        pending.pop_back();
        const std::vector<int64_t>& chart_faces = chart.faces;
        if (progress) progress->check();
        Unwrapped unwrapped;
        if (unwrap(mesh, welded, chart_faces, unwrapped)) {
            if (progress) progress->advance(chart_faces.size());
            charts.push_back(std::move(unwrapped));
            continue;
        }
        if (chart_faces.size() == 1) {  // no shape to keep (a face on the sliver limit): a stand-in triangle
            bad.push_back(chart_faces[0]);
            if (progress) progress->advance(1);
            continue;
        }
        ++result.split_charts;
        // Curvature folds: a smaller angle. A chart that still folds within
        // a small angle (a folded input): cut in halves until the fold is isolated.
        const double half = 0.5 * chart.angle, smooth_half = 0.5 * chart.smooth_angle;
        auto parts = std::max(half, smooth_half) >= kMinSplitAngle
                         ? grow_charts(faces, chart_faces, half, smooth_half)
                         : std::vector<std::vector<int64_t>>{chart_faces};
        if (parts.size() == 1) parts = bisect_chart(mesh, faces, chart_faces);
        for (auto& part : parts) pending.push_back({std::move(part), half, smooth_half});
    }
    // Charts in order of their smallest face: ids do not depend on the order of splits.
    std::sort(charts.begin(), charts.end(), [](const Unwrapped& a, const Unwrapped& b) { return a.faces[0] < b.faces[0]; });

    result.uvs.assign(size_t(6 * mesh.triangle_count), 0.0f);
    result.triangle_chart.assign(size_t(mesh.triangle_count), -1);
    for (const Unwrapped& chart : charts) {
        // Turned to its smallest box, scaled to its world-space area
        // (uniform texel density), the box's lower-left corner at the origin.
        double uv_area = 0.0, world_area = 0.0;
        std::vector<glm::dvec2> points;
        for (size_t i = 0; i < chart.faces.size(); ++i) {
            const auto& c = chart.corners[i];
            uv_area += 0.5 * ((c[1].x - c[0].x) * (c[2].y - c[0].y) - (c[1].y - c[0].y) * (c[2].x - c[0].x));
            world_area += faces.area[size_t(chart.faces[i])];
            points.insert(points.end(), c.begin(), c.end());
        }
        const glm::dvec2 turn = chart::smallest_box_turn(points);
        const auto turned = [&](const glm::dvec2& p) {
            return glm::dvec2(turn.x * p.x - turn.y * p.y, turn.y * p.x + turn.x * p.y);
        };
        glm::dvec2 lo(1e300);
        for (const glm::dvec2& p : points) lo = glm::min(lo, turned(p));
        const double scale = std::sqrt(world_area / uv_area);
        const int32_t id = result.chart_count++;
        for (size_t i = 0; i < chart.faces.size(); ++i) {
            const int64_t f = chart.faces[i];
            result.triangle_chart[size_t(f)] = id;
            for (int k = 0; k < 3; ++k) {
                const glm::dvec2 uv = (turned(chart.corners[i][size_t(k)]) - lo) * scale;
                result.uvs[size_t(6 * f + 2 * k)] = float(uv.x);
                result.uvs[size_t(6 * f + 2 * k + 1)] = float(uv.y);
            }
        }
    }
    result.degenerate = int64_t(bad.size());
    if (!bad.empty()) {
        std::vector<double> areas;
        for (int64_t f : good) areas.push_back(faces.area[size_t(f)]);
        std::nth_element(areas.begin(), areas.begin() + int64_t(areas.size() / 2), areas.end());
        const float side = float(kDegenerateSide * std::sqrt(2.0 * areas[areas.size() / 2]));
        for (int64_t f : bad) {
            result.triangle_chart[size_t(f)] = result.chart_count++;
            const float corner[6] = {0.0f, 0.0f, side, 0.0f, 0.0f, side};
            std::copy(corner, corner + 6, result.uvs.begin() + 6 * f);
        }
    }
    if (progress) progress->finish();
    return result;
}

}  // namespace lmrefine
