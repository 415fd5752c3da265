// fit_to_bounds: the finest level's start inside every bound (see
// automaton_level.h).
#include <algorithm>
#include <vector>

#include "automaton_cell.h"
#include "automaton_level.h"

namespace lmrefine::automaton_detail {
namespace {

// fit_to_bounds: nodes this many around an out-of-bounds cell back off with
// it; below kFitSnap of its move a node goes back to rest; after kFitRounds
// rounds every node still lowered goes back to rest.
constexpr int kFitMargin = 1;
constexpr double kFitSnap = 0.05;
constexpr int kFitRounds = 40;
constexpr double kFitFactor = 0.8;
// fit_to_bounds first smooths the nodes around out-of-bounds cells for this
// many rounds, so the fit moves a neighbourhood instead of cascading cell by
// cell (docs/refiner.md, "Constants and how they were chosen").
constexpr int kFitSmoothRounds = 20;

}  // namespace

Fit fit_to_bounds(Level& level) {
    const int rows = level.rows(), cols = level.cols();
    const NodeGrid& grid = level.grid;
    // The bounds of `validity` (automaton_cell.h), except that a convex cell
    // counts as well shaped enough here: requiring |sin| >= kMinQuality too
    // changes results (docs/refiner.md, "Invariants").
    auto out_of_bounds = [&](int i, int j) {
        glm::dvec2 q[4];
        corners(level, grid.nodes, i, j, q);
        const Shape now = shape(q);
        const Validity v = validity(q, now, bounds_of(level, i, j));
        return now.quality2 < 0 || v.too_small || v.too_large || v.too_narrow || v.too_short;
    };
    // Round 0 checks every cell; later rounds only the cells around the
    // nodes moved in the round before (a bad cell's own corners are among
    // them, so every bad cell is checked again). Rounds work on lists: the
    // bad region is small next to the grid, and there can be dozens.
    std::vector<int32_t> checked, bad;
    std::vector<uint8_t> verdicts;
    std::vector<std::vector<int32_t>> row_bad(static_cast<size_t>(rows));
    parallel_for(rows, kRowGrain, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            for (int j = 0; j < cols; ++j) {
                if (out_of_bounds(i, j)) row_bad[size_t(i)].push_back(int32_t(level.cell(i, j)));
            }
        }
    });
    for (const auto& r : row_bad) bad.insert(bad.end(), r.begin(), r.end());
    if (bad.empty()) return {};

    // Blended towards rest from round kFitSmoothRounds on (made then: most
    // fits end before, and a per-node array is costly to fault in).
    LargeVector<glm::dvec2> carried;
    std::vector<double> kept;
    // Nodes marked in this round's `lowered` list (cleared after the round).
    std::vector<uint8_t> is_lowered(grid.nodes.size(), 0);
    std::vector<int32_t> lowered;
    std::vector<glm::dvec2> smoothed;
    bool reset = false;
    for (int round = 0;; ++round) {
        // Halve the move of every node within kFitMargin nodes of a bad
        // cell (once per round), to 0 below kFitSnap: a cell whose nodes
        // are all back at rest is the identity, inside every bound.
        lowered.clear();
        for (int32_t c : bad) {
            const int i = c / cols, j = c % cols;
            for (int ni = std::max(0, i - kFitMargin); ni <= std::min(rows, i + 1 + kFitMargin); ++ni) {
                for (int nj = std::max(0, j - kFitMargin); nj <= std::min(cols, j + 1 + kFitMargin); ++nj) {
                    const size_t n = level.node(ni, nj);
                    if (is_lowered[n]) continue;
                    is_lowered[n] = 1;
                    lowered.push_back(int32_t(n));
                }
            }
        }
        for (int32_t node : lowered) is_lowered[size_t(node)] = 0;
        if (round < kFitSmoothRounds) {
            // First even out the nodes around the bad cells (a Laplacian
            // step, synchronous): cells interpolated from one coarse cell
            // differ in size, and smoothing evens them out without giving
            // up the deformation; blending towards rest (below) cascades
            // through a strongly compressed region and undoes it.
            const LargeVector<glm::dvec2>& before = level.grid.nodes;
            smoothed.resize(lowered.size());
            for (size_t k = 0; k < lowered.size(); ++k) {
                const size_t n = size_t(lowered[k]);
                const int i = int(n / size_t(cols + 1)), j = int(n % size_t(cols + 1));
                const NodeMode mode = level.node_mode[n];
                smoothed[k] = before[n];
                if (mode == NodeMode::Fixed) continue;
                glm::dvec2 sum(0.0);
                int count = 0;
                if (i > 0) sum += before[level.node(i - 1, j)], ++count;
                if (i < rows) sum += before[level.node(i + 1, j)], ++count;
                if (j > 0) sum += before[level.node(i, j - 1)], ++count;
                if (j < cols) sum += before[level.node(i, j + 1)], ++count;
                glm::dvec2 move = 0.5 * (sum / double(count) - before[n]);
                if (mode == NodeMode::SlideX) move.y = 0;
                if (mode == NodeMode::SlideY) move.x = 0;
                smoothed[k] = before[n] + move;
            }
            for (size_t k = 0; k < lowered.size(); ++k) level.grid.nodes[size_t(lowered[k])] = smoothed[k];
        } else {
            if (round == kFitSmoothRounds) {
                carried = level.grid.nodes;
                kept.assign(grid.nodes.size(), 1.0);
            }
            const bool last = round >= kFitRounds + kFitSmoothRounds;
            reset = reset || last;
            for (int32_t node : lowered) {
                const size_t n = size_t(node);
                const int i = int(n / size_t(cols + 1)), j = int(n % size_t(cols + 1));
                kept[n] = last || kept[n] < kFitSnap ? 0.0 : kFitFactor * kept[n];
                const glm::dvec2 rest(grid.xs[j], grid.ys[i]);
                level.grid.nodes[n] = rest + kept[n] * (carried[n] - rest);
            }
        }

        // Check the cells around the moved nodes again.
        const uint32_t stamp = ++level.revert_round;
        checked.clear();
        for (int32_t node : lowered) {
            queue_cells_around(level, int(size_t(node) / size_t(cols + 1)), int(size_t(node) % size_t(cols + 1)),
                               stamp, checked);
        }
        judge_cells(level, checked, out_of_bounds, verdicts, bad);
        if (bad.empty()) return {round + 1, reset};
    }
}

}  // namespace lmrefine::automaton_detail
