// A cell of the automaton's grid as its rule and guards see it: corners,
// area, shape (move radius, quality), thickness, and the lists the guards
// re-judge cells from (internal to automaton*.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <glm/geometric.hpp>

#include "automaton_level.h"
#include "lmrefine/core/parallel.h"

namespace lmrefine::automaton_detail {

constexpr int64_t kRowGrain = 8;
constexpr int64_t kSuspectGrain = 256;  // cells judged again after a revert, per chunk

inline double cross(const glm::dvec2& a, const glm::dvec2& b) { return a.x * b.y - a.y * b.x; }

// Corners of cell (i, j) in order around it.
inline void corners(const Level& level, const LargeVector<glm::dvec2>& nodes, int i, int j, glm::dvec2 q[4]) {
    q[0] = nodes[level.node(i, j)];
    q[1] = nodes[level.node(i, j + 1)];
    q[2] = nodes[level.node(i + 1, j + 1)];
    q[3] = nodes[level.node(i + 1, j)];
}

inline double quad_area(const glm::dvec2 q[4]) { return 0.5 * (cross(q[2] - q[0], q[3] - q[1])); }

// Appends the cells around node (ni, nj) that this round (a stamp in
// level.suspect_round) has not queued yet: each cell once per round.
inline void queue_cells_around(Level& level, int ni, int nj, uint32_t round, std::vector<int32_t>& queue) {
    for (int ci = std::max(0, ni - 1); ci <= std::min(level.rows() - 1, ni); ++ci) {
        for (int cj = std::max(0, nj - 1); cj <= std::min(level.cols() - 1, nj); ++cj) {
            const size_t c = level.cell(ci, cj);
            if (level.suspect_round[c] == round) continue;
            level.suspect_round[c] = round;
            queue.push_back(int32_t(c));
        }
    }
}

// The cells of `cells` (each listed once) for which fails(i, j) holds,
// judged in parallel, in list order; `verdicts` is scratch.
template <typename Fails>
void judge_cells(const Level& level, const std::vector<int32_t>& cells, const Fails& fails,
                 std::vector<uint8_t>& verdicts, std::vector<int32_t>& failing) {
    const int cols = level.cols();
    verdicts.assign(cells.size(), 0);
    parallel_for(int64_t(cells.size()), kSuspectGrain, [&](int64_t begin, int64_t end) {
        for (int64_t k = begin; k < end; ++k) {
            verdicts[size_t(k)] = fails(cells[size_t(k)] / cols, cells[size_t(k)] % cols);
        }
    });
    failing.clear();
    for (size_t k = 0; k < cells.size(); ++k) {
        if (verdicts[k]) failing.push_back(cells[k]);
    }
}

struct Shape {
    double area;
    // How far a corner may move in one step: c / (2 (|a| + |b|)) with c the
    // cross product of the edges a, b at a corner (bounded through
    // |a| + |b| <= sqrt(2 (|a|^2 + |b|^2))); a quarter cell for a square.
    // Moves this size can still spoil a cell when all its corners move
    // against it; the guards put those moves back, so validity never rests on
    // the radius, which only keeps such reverts rare.
    double radius;
    // How well shaped, squared and signed (negative if inverted): the
    // smallest sin^2 of the corner angles, or 16 (shortest / longest edge)^2
    // if smaller (a convex cell can still collapse an edge into a triangle);
    // kQualityExactBelow for every cell at least that well shaped.
    double quality2;
};

// A cell's quality is only ever compared with kMinQuality^2 and, below
// that, with its previous quality, so any value at or above this bound
// gives the same decisions: a well-shaped cell reports the bound itself and
// skips the quality's divisions.
constexpr double kQualityExactBelow = 0.25;
static_assert(kQualityExactBelow > kMinQuality * kMinQuality, "the bound must lie above every decision");

// The quality of a cell that is not well shaped (the rare case, kept out of
// shape() so that it stays small): c2 and l2 as there.
double exact_quality2(const double c2[4], const double l2[4], double shortest, double longest);

inline Shape shape(const glm::dvec2 q[4]) {
    glm::dvec2 e[4];
    double l2[4];
    for (int k = 0; k < 4; ++k) {
        e[k] = q[(k + 1) % 4] - q[k];
        l2[k] = glm::dot(e[k], e[k]);
    }
    // At corner k, between edge p before it and edge k: c^2 = (e_p x e_k)^2.
    double c2[4];
    for (int k = 0; k < 4; ++k) {
        const double c = cross(e[(k + 3) % 4], e[k]);
        if (!(c > 0)) return {quad_area(q), 0.0, -1.0};
        c2[k] = c * c;
    }
    // All four divisions in one loop over contiguous arrays, so a compiler
    // may pair them into SIMD divisions (IEEE division rounds the same
    // either way; gcc 12 keeps them scalar, docs/refiner.md).
    const double over[4] = {8 * (l2[3] + l2[0]), 8 * (l2[0] + l2[1]), 8 * (l2[1] + l2[2]), 8 * (l2[2] + l2[3])};
    double radius2[4];
    for (int k = 0; k < 4; ++k) radius2[k] = c2[k] / over[k];
    const double r2 = std::min(std::min(radius2[0], radius2[1]), std::min(radius2[2], radius2[3]));
    const double shortest = std::min({l2[0], l2[1], l2[2], l2[3]});
    const double longest = std::max({l2[0], l2[1], l2[2], l2[3]});
    bool well_shaped = 16 * shortest >= kQualityExactBelow * longest;
    for (int k = 0; k < 4; ++k) well_shaped = well_shaped && c2[k] >= kQualityExactBelow * l2[(k + 3) % 4] * l2[k];
    if (well_shaped) return {quad_area(q), std::sqrt(r2), kQualityExactBelow};
    return {quad_area(q), std::sqrt(r2), exact_quality2(c2, l2, shortest, longest)};
}

// Distance across the cell between its left and right edges, and between
// its top and bottom edges (exact for parallelograms, a lower bound otherwise).
inline glm::dvec2 thickness(const glm::dvec2 q[4], double area) {
    return {area / std::max(glm::length(q[3] - q[0]), glm::length(q[2] - q[1])),
            area / std::max(glm::length(q[1] - q[0]), glm::length(q[2] - q[3]))};
}

// What a cell must keep (docs/refiner.md "Invariants"): its area within
// [min_area, max_area] and, a cell of rigid texels only, at least its width
// and height at rest.
struct CellBounds {
    double min_area = 0;
    double max_area = std::numeric_limits<double>::infinity();
    bool rigid = false;
    double width = 0, height = 0;  // at rest (rigid cells)
};

// From the cell's kind, rigid area and size at rest (the factors set by
// prepare_level): a ring cell keeps min_shrink of its area, a gutter cell
// all of it, a material cell the covered factor's share or its rigid area
// if larger, and at most the covered maximum's share.
inline CellBounds bounds_of(const Level& level, int i, int j) {
    const size_t c = level.cell(i, j);
    CellBounds bounds;
    bounds.width = level.grid.xs[j + 1] - level.grid.xs[j];
    bounds.height = level.grid.ys[i + 1] - level.grid.ys[i];
    const double rest = bounds.width * bounds.height;
    const double rigid_area = level.rigid_area[c];
    bounds.rigid = !(rigid_area < rest);
    switch (level.kind[c]) {
        case CellKind::Ring: bounds.min_area = level.ring_min_factor * rest; break;
        case CellKind::Gutter: bounds.min_area = rest; break;  // gutter texels shift but are never compressed
        case CellKind::Material:
            bounds.min_area = std::max(level.covered_min_factor * rest, rigid_area);
            bounds.max_area = level.covered_max_factor * rest;
            break;
    }
    return bounds;
}

// The validity of a cell: the one definition the step guard, fit_to_bounds
// and check_invariants use. A valid cell is well shaped (quality2 >=
// kMinQuality^2: every corner's |sin| >= 0.2 and its shortest edge at least
// 1/20 of its longest, so convex and not inverted), has its area within its
// bounds and, if rigid, is at least as wide and as tall as at rest. Each
// flag names one bound the cell breaks.
struct Validity {
    bool ill_shaped = false;
    bool too_small = false, too_large = false;
    bool too_narrow = false, too_short = false;  // rigid cells: thinner than at rest across x, across y
    glm::dvec2 thickness{0.0};                   // computed for rigid cells only

    bool valid() const { return !(ill_shaped || too_small || too_large || too_narrow || too_short); }
};

inline Validity validity(const glm::dvec2 q[4], const Shape& shape, const CellBounds& bounds) {
    Validity v;
    v.ill_shaped = shape.quality2 < kMinQuality * kMinQuality;
    v.too_small = shape.area < bounds.min_area;
    v.too_large = shape.area > bounds.max_area;
    if (bounds.rigid) {
        v.thickness = thickness(q, shape.area);
        v.too_narrow = v.thickness.x < bounds.width;
        v.too_short = v.thickness.y < bounds.height;
    }
    return v;
}

// The step guard's second rule, for a cell that is not valid: it may not
// break a bound further than it did before (a cell interpolated from a
// coarser level may start outside one). `now` and `v` are the cell's shape
// and validity, `before` its earlier shape; thickness_before() gives its
// earlier thickness (computed only when a thickness bound is broken).
template <class ThicknessBefore>
bool breaks_further(const Validity& v, const Shape& now, const Shape& before, const ThicknessBefore& thickness_before) {
    if ((v.too_small && now.area < before.area) || (v.too_large && now.area > before.area)) return true;
    if (v.ill_shaped && now.quality2 < before.quality2) return true;
    if (!v.too_narrow && !v.too_short) return false;
    const glm::dvec2 was = thickness_before();
    return (v.too_narrow && v.thickness.x < was.x) || (v.too_short && v.thickness.y < was.y);
}

}  // namespace lmrefine::automaton_detail
