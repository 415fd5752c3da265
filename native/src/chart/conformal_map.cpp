#include "lmrefine/chart/conformal_map.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <glm/geometric.hpp>

namespace lmrefine {
namespace {

// The two pinned vertices: far apart, so the pins do not amplify rounding
// (the farthest vertex from the first, then the farthest from that).
std::pair<int32_t, int32_t> pick_pins(const std::vector<glm::dvec3>& positions) {
    const auto farthest = [&](const glm::dvec3& from) {
        int32_t best = 0;
        double best_d = -1.0;
        for (size_t i = 0; i < positions.size(); ++i) {
            const glm::dvec3 d = positions[i] - from;
            if (glm::dot(d, d) > best_d) best_d = glm::dot(d, d), best = int32_t(i);
        }
        return best;
    };
    const int32_t a = farthest(positions[0]);
    return {a, farthest(positions[size_t(a)])};
}

double signed_area(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
    return 0.5 * ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x));
}

// Separating-axis test on the six edge normals: do the interiors of two
// triangles (both counter-clockwise) intersect by more than `slack`?
bool interiors_intersect(const glm::dvec2* p, const glm::dvec2* q, double slack) {
    const glm::dvec2* shapes[2] = {p, q};
    for (const glm::dvec2* s : shapes) {
        for (int k = 0; k < 3; ++k) {
            const glm::dvec2 e = s[(k + 1) % 3] - s[k];
            const glm::dvec2 axis(-e.y, e.x);
            const double length = glm::length(axis);
            double p0 = 1e300, p1 = -1e300, q0 = 1e300, q1 = -1e300;
            for (int i = 0; i < 3; ++i) {
                p0 = std::min(p0, glm::dot(axis, p[i])), p1 = std::max(p1, glm::dot(axis, p[i]));
                q0 = std::min(q0, glm::dot(axis, q[i])), q1 = std::max(q1, glm::dot(axis, q[i]));
            }
            if (std::min(p1, q1) - std::max(p0, q0) <= slack * length) return false;
        }
    }
    return true;
}

}  // namespace

std::vector<glm::dvec2> conformal_map(const ChartMesh& chart) {
    const int64_t n = int64_t(chart.positions.size());
    if (n < 3 || chart.triangles.empty()) return {};
    const auto [pin_a, pin_b] = pick_pins(chart.positions);
    if (pin_a == pin_b) return {};
    // Unknowns: u and v of every free vertex (u of free vertex i at column
    // 2 * free_index, v at 2 * free_index + 1); the pins hold (0, 0) and (d, 0).
    std::vector<int64_t> column(size_t(n), -1);
    int64_t free_count = 0;
    for (int64_t i = 0; i < n; ++i) {
        if (i != pin_a && i != pin_b) column[size_t(i)] = 2 * free_count++;
    }
    std::vector<glm::dvec2> pinned(size_t(n), glm::dvec2(0.0));
    pinned[size_t(pin_b)] = {glm::length(chart.positions[size_t(pin_b)] - chart.positions[size_t(pin_a)]), 0.0};

    // Per triangle, in its own plane: u_x - v_y = 0 and u_y + v_x = 0
    // (Cauchy-Riemann), each row weighted by sqrt(area). With barycentric
    // gradients g_k, u_x = sum g_k.x u_k and so on.
    using Triplet = Eigen::Triplet<double>;
    std::vector<Triplet> entries;
    entries.reserve(chart.triangles.size() * 12);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(int64_t(2 * chart.triangles.size()));
    int64_t row = 0;
    for (const auto& tri : chart.triangles) {
        const glm::dvec3 p0 = chart.positions[size_t(tri[0])];
        const glm::dvec3 e1 = chart.positions[size_t(tri[1])] - p0, e2 = chart.positions[size_t(tri[2])] - p0;
        const glm::dvec3 normal = glm::cross(e1, e2);
        const double twice_area = glm::length(normal);
        if (!(twice_area > 0.0)) return {};
        const glm::dvec3 x_axis = glm::normalize(e1), y_axis = glm::normalize(glm::cross(normal, e1));
        const glm::dvec2 q[3] = {{0.0, 0.0}, {glm::length(e1), 0.0}, {glm::dot(e2, x_axis), glm::dot(e2, y_axis)}};
        const double weight = std::sqrt(0.5 * twice_area);
        for (int k = 0; k < 3; ++k) {
            const glm::dvec2 edge = q[(k + 2) % 3] - q[(k + 1) % 3];
            const glm::dvec2 g = glm::dvec2(-edge.y, edge.x) * (weight / twice_area);
            const int32_t v = tri[size_t(k)];
            const int64_t c = column[size_t(v)];
            if (c >= 0) {
                entries.emplace_back(row, c, g.x);
                entries.emplace_back(row, c + 1, -g.y);
                entries.emplace_back(row + 1, c, g.y);
                entries.emplace_back(row + 1, c + 1, g.x);
            } else {
                const glm::dvec2 uv = pinned[size_t(v)];
                rhs[row] -= g.x * uv.x - g.y * uv.y;
                rhs[row + 1] -= g.y * uv.x + g.x * uv.y;
            }
        }
        row += 2;
    }
    std::vector<glm::dvec2> uvs(pinned);
    if (free_count > 0) {
        Eigen::SparseMatrix<double> system(row, 2 * free_count);
        system.setFromTriplets(entries.begin(), entries.end());
        const Eigen::SparseMatrix<double> normal = system.transpose() * system;
        Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
        if (solver.info() != Eigen::Success) return {};
        const Eigen::VectorXd solution = solver.solve(system.transpose() * rhs);
        if (solver.info() != Eigen::Success || !solution.allFinite()) return {};
        for (int64_t i = 0; i < n; ++i) {
            const int64_t c = column[size_t(i)];
            if (c >= 0) uvs[size_t(i)] = {solution[c], solution[c + 1]};
        }
    }
    return uvs;
}

bool chart_overlaps_itself(const std::vector<glm::dvec2>& uvs, const std::vector<std::array<int32_t, 3>>& triangles) {
    if (triangles.empty()) return false;
    glm::dvec2 lo(1e300), hi(-1e300);
    for (const glm::dvec2& p : uvs) lo = glm::min(lo, p), hi = glm::max(hi, p);
    const glm::dvec2 size = hi - lo;
    const double extent = std::max(size.x, size.y);
    if (!(extent > 0.0) || !std::isfinite(extent)) return true;
    // Orientation: every triangle counter-clockwise with an area above
    // rounding (a fold turns triangles over).
    double total = 0.0;
    for (const auto& t : triangles) {
        const double a = signed_area(uvs[size_t(t[0])], uvs[size_t(t[1])], uvs[size_t(t[2])]);
        if (!(a > 1e-12 * extent * extent)) return true;
        total += a;
    }
    // Overlap without a fold (a fan turning more than once around a
    // vertex, two arms of a chart crossing): pairs of triangles in the same
    // cell of a grid of about one triangle per cell.
    const double cell = std::max(std::sqrt(total / double(triangles.size())), extent / 512.0);
    const int64_t cols = int64_t(size.x / cell) + 1, rows = int64_t(size.y / cell) + 1;
    std::unordered_map<int64_t, std::vector<int32_t>> cells;
    const auto box = [&](const std::array<int32_t, 3>& t, int64_t* range) {
        glm::dvec2 a = glm::min(glm::min(uvs[size_t(t[0])], uvs[size_t(t[1])]), uvs[size_t(t[2])]) - lo;
        glm::dvec2 b = glm::max(glm::max(uvs[size_t(t[0])], uvs[size_t(t[1])]), uvs[size_t(t[2])]) - lo;
        range[0] = std::min(cols - 1, int64_t(a.x / cell)), range[1] = std::min(cols - 1, int64_t(b.x / cell));
        range[2] = std::min(rows - 1, int64_t(a.y / cell)), range[3] = std::min(rows - 1, int64_t(b.y / cell));
    };
    for (size_t i = 0; i < triangles.size(); ++i) {
        int64_t r[4];
        box(triangles[i], r);
        for (int64_t y = r[2]; y <= r[3]; ++y) {
            for (int64_t x = r[0]; x <= r[1]; ++x) cells[y * cols + x].push_back(int32_t(i));
        }
    }
    const double slack = 1e-9 * extent;
    for (const auto& entry : cells) {
        const std::vector<int32_t>& members = entry.second;
        for (size_t i = 0; i < members.size(); ++i) {
            int64_t ri[4];
            box(triangles[size_t(members[i])], ri);
            for (size_t j = i + 1; j < members.size(); ++j) {
                int64_t rj[4];
                box(triangles[size_t(members[j])], rj);
                // Test each pair once: in the first cell both boxes share.
                if (entry.first != std::max(ri[2], rj[2]) * cols + std::max(ri[0], rj[0])) continue;
                const auto& a = triangles[size_t(members[i])];
                const auto& b = triangles[size_t(members[j])];
                const glm::dvec2 p[3] = {uvs[size_t(a[0])], uvs[size_t(a[1])], uvs[size_t(a[2])]};
                const glm::dvec2 q[3] = {uvs[size_t(b[0])], uvs[size_t(b[1])], uvs[size_t(b[2])]};
                if (interiors_intersect(p, q, slack)) return true;
            }
        }
    }
    return false;
}

}  // namespace lmrefine
