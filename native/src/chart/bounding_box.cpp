#include "lmrefine/chart/bounding_box.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>

namespace lmrefine::chart {
namespace {

double cross(const glm::dvec2& o, const glm::dvec2& a, const glm::dvec2& b) {
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

// Andrew's monotone chain, counter-clockwise, collinear points dropped.
std::vector<glm::dvec2> convex_hull(std::vector<glm::dvec2> points) {
    std::sort(points.begin(), points.end(), [](const glm::dvec2& a, const glm::dvec2& b) {
        return a.x < b.x || (a.x == b.x && a.y < b.y);
    });
    points.erase(std::unique(points.begin(), points.end()), points.end());
    if (points.size() < 3) return points;
    std::vector<glm::dvec2> hull(2 * points.size());
    size_t k = 0;
    for (size_t i = 0; i < points.size(); ++i) {
        while (k >= 2 && cross(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
        hull[k++] = points[i];
    }
    for (size_t i = points.size() - 1, lower = k + 1; i > 0; --i) {
        while (k >= lower && cross(hull[k - 2], hull[k - 1], points[i - 1]) <= 0) --k;
        hull[k++] = points[i - 1];
    }
    hull.resize(k - 1);
    return hull;
}

}  // namespace

glm::dvec2 smallest_box_turn(const std::vector<glm::dvec2>& points) {
    const std::vector<glm::dvec2> hull = convex_hull(points);
    glm::dvec2 best(1.0, 0.0);
    if (hull.size() < 3) return best;
    double best_area = 1e300;
    // Long hulls (a finely tessellated round chart): every edge tried up to
    // a budget, then evenly spaced ones; the box is within a few percent.
    const size_t step = std::max<size_t>(1, hull.size() / 1024);
    for (size_t i = 0; i < hull.size(); i += step) {
        const glm::dvec2 edge = hull[(i + 1) % hull.size()] - hull[i];
        const double length = glm::length(edge);
        if (!(length > 0.0)) continue;
        const glm::dvec2 along = edge / length, across(-along.y, along.x);
        double a0 = 1e300, a1 = -1e300, b0 = 1e300, b1 = -1e300;
        for (const glm::dvec2& p : hull) {
            const double a = glm::dot(p, along), b = glm::dot(p, across);
            a0 = std::min(a0, a), a1 = std::max(a1, a), b0 = std::min(b0, b), b1 = std::max(b1, b);
        }
        const double area = (a1 - a0) * (b1 - b0);
        if (area < best_area * (1.0 - 1e-9)) best_area = area, best = along;
    }
    // Turning by -angle(best) puts that edge along the u axis.
    return {best.x, -best.y};
}

std::vector<glm::dvec2> smallest_box_turns(const UvLayout& layout, const std::vector<int32_t>& triangle_chart,
                                           int32_t chart_count) {
    std::vector<std::vector<glm::dvec2>> points(size_t(std::max(chart_count, 0)));
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        std::vector<glm::dvec2>& chart = points[size_t(triangle_chart[size_t(t)])];
        for (int k = 0; k < 3; ++k) {
            const float* uv = layout.uvs + 2 * int64_t(layout.triangles[3 * t + k]);
            chart.emplace_back(uv[0], uv[1]);
        }
    }
    std::vector<glm::dvec2> turns;
    turns.reserve(points.size());
    for (const std::vector<glm::dvec2>& chart : points) turns.push_back(smallest_box_turn(chart));
    return turns;
}

}  // namespace lmrefine::chart
