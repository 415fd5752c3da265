#include "lmrefine/chart/shape_fit.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include "lmrefine/core/error.h"

namespace lmrefine {
namespace {

// The pull to the current positions, relative to each vertex's own edge
// weights: far below any target's pull, enough to fix a piece's place.
constexpr double kAnchor = 1e-6;

void check_input(const ShapeFitInput& in) {
    for (int64_t k = 0; k < 2 * in.vertices; ++k) {
        if (!std::isfinite(in.uvs[k])) LMREFINE_THROW(InvalidArgument, "uvs[" + std::to_string(k / 2) + "] is NaN or Inf");
    }
    for (int64_t k = 0; k < 3 * in.triangle_count; ++k) {
        if (in.triangles[k] < 0 || in.triangles[k] >= in.vertices) {
            LMREFINE_THROW(InvalidArgument, "triangles[" + std::to_string(k / 3) + "] holds index " +
                                                std::to_string(in.triangles[k]) + ", outside the " +
                                                std::to_string(in.vertices) + " uvs");
        }
    }
    for (int64_t k = 0; k < 4 * in.triangle_count; ++k) {
        if (!std::isfinite(in.targets[k])) {
            LMREFINE_THROW(InvalidArgument, "targets[" + std::to_string(k / 4) + "] is NaN or Inf");
        }
    }
}

}  // namespace

std::vector<glm::dvec2> fit_shapes(const ShapeFitInput& in) {
    check_input(in);
    const int64_t n = in.vertices;
    std::vector<glm::dvec2> uvs(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) uvs[size_t(i)] = {in.uvs[2 * i], in.uvs[2 * i + 1]};
    if (n == 0) return uvs;

    using Triplet = Eigen::Triplet<double>;
    std::vector<Triplet> entries;
    entries.reserve(size_t(in.triangle_count) * 12 + size_t(n));
    Eigen::VectorXd diagonal = Eigen::VectorXd::Zero(n);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, 2);
    for (int64_t t = 0; t < in.triangle_count; ++t) {
        const int32_t* tri = in.triangles + 3 * t;
        const glm::dvec2 a = uvs[size_t(tri[0])], b = uvs[size_t(tri[1])], c = uvs[size_t(tri[2])];
        const double area = 0.5 * std::abs((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x));
        if (!(area > 0.0)) continue;
        const double* d = in.targets + 4 * t;
        for (int k = 0; k < 3; ++k) {
            const int32_t i = tri[k], j = tri[(k + 1) % 3];
            const glm::dvec2 edge = uvs[size_t(j)] - uvs[size_t(i)];
            const double length2 = edge.x * edge.x + edge.y * edge.y;
            if (!(length2 > 0.0)) continue;
            // The edge's residual relative to its length, weighted by the
            // triangle's area: the fit does not depend on the layout's scale.
            const double w = area / length2;
            const glm::dvec2 target{d[0] * edge.x + d[1] * edge.y, d[2] * edge.x + d[3] * edge.y};
            entries.emplace_back(i, j, -w);
            entries.emplace_back(j, i, -w);
            diagonal[i] += w;
            diagonal[j] += w;
            rhs(i, 0) -= w * target.x, rhs(i, 1) -= w * target.y;
            rhs(j, 0) += w * target.x, rhs(j, 1) += w * target.y;
        }
    }
    for (int64_t i = 0; i < n; ++i) {
        // A vertex without edges keeps its place exactly (weight 1 of itself).
        const double anchor = diagonal[i] > 0 ? kAnchor * diagonal[i] : 1.0;
        entries.emplace_back(i, i, diagonal[i] + anchor);
        rhs(i, 0) += anchor * uvs[size_t(i)].x;
        rhs(i, 1) += anchor * uvs[size_t(i)].y;
    }
    Eigen::SparseMatrix<double> system(n, n);
    system.setFromTriplets(entries.begin(), entries.end());  // duplicates are summed
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(system);
    if (solver.info() != Eigen::Success) LMREFINE_THROW(Error, "the shape fit's system could not be factorised");
    const Eigen::MatrixXd solution = solver.solve(rhs);
    if (solver.info() != Eigen::Success || !solution.allFinite()) {
        LMREFINE_THROW(Error, "the shape fit's system could not be solved");
    }
    for (int64_t i = 0; i < n; ++i) uvs[size_t(i)] = {solution(i, 0), solution(i, 1)};
    return uvs;
}

}  // namespace lmrefine
