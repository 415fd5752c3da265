// One level of the automaton's pyramid: its cells, their energies and the
// double-buffered node positions, and the synchronous step (internal to
// automaton*.cpp).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "lmrefine/automaton/automaton.h"
#include "lmrefine/automaton/warp.h"
#include "lmrefine/core/memory.h"

namespace lmrefine::automaton_detail {

enum class CellKind : uint8_t {
    Material,  // holds covered texels: energy, diffusion, free to shrink or grow
    Gutter,    // only uncovered texels: no energy; keeps at least its original area
    Ring,      // the extra ring (BorderMode::ExtraRing): neutral, removed after the level
};

// Cells stay well shaped, not just convex: no corner sharper than about 11.5
// degrees (|sin| >= 0.2), no edge shorter than 1/20 of the longest.
constexpr double kMinQuality = 0.2;

enum class NodeMode : uint8_t { Free, SlideX, SlideY, Fixed };

struct Level {
    // Texels per cell side: 1 at the finest level, 2^k at pyramid level k.
    // Stored, not read off the grid: a map one texel wide has xs = {0, 1} at
    // every level.
    int block = 1;
    NodeGrid grid;                       // current node positions (and original xs, ys)
    LargeVector<glm::dvec2> next_nodes;  // the second buffer
    int channels = 1;
    LargeVector<double> energy, next_energy;  // cells * channels
    LargeVector<CellKind> kind;
    // A cell's area bounds are factors of its area at rest (bounds_of,
    // automaton_cell.h), computed where they are needed instead of stored:
    // per-cell arrays cost more to fault in and read than the products.
    double covered_min_factor = 0, covered_max_factor = 0;  // material cells (min: or rigid_area if larger)
    double ring_min_factor = 0;                             // ring cells
    LargeVector<double> uncovered_area;  // texel area of uncovered texels inside (pressure only)
    LargeVector<double> rigid_area;      // texel area of rigid texels inside: uncovered or on a chart's edge
    LargeVector<NodeMode> node_mode;
    std::array<double, 4> reference_density{};  // covered energy / covered area, per channel
    double initial_total = 0;                   // sum of all energies, for the conservation check

    // Cell shapes derived from the nodes (measure_cells), kept
    // double-buffered like them: a step measures the cells it moved while
    // checking their bounds, so the next step need not measure them again.
    LargeVector<double> area, safe_radius, quality;
    LargeVector<double> next_area, next_safe_radius, next_quality;
    // Scratch, rebuilt every step.
    std::vector<double> row_difference;  // per row of edges, the largest density difference
    std::vector<double> row_moved;       // per row of nodes, the largest squared node move
    LargeVector<uint32_t> suspect_round;  // per cell, the last revert round that queued it
    LargeVector<uint8_t> breaking_cell;   // per cell: breaks a bound (dense revert rounds)
    LargeVector<uint8_t> reverted_node;   // per node: put back in this dense round
    uint32_t revert_round = 0;
    // The nodes at the level's start (after fit_to_bounds), kept for
    // check_invariants only.
    LargeVector<glm::dvec2> start_nodes;

    int rows() const { return grid.rows; }
    int cols() const { return grid.cols; }
    size_t cell(int i, int j) const { return size_t(i) * grid.cols + j; }
    size_t node(int i, int j) const { return size_t(i) * (grid.cols + 1) + j; }
};

// Fills kind, areas, bounds, node modes and the reference density from the
// energies and uncovered areas already in `level` (grid and energy set);
// with `stepping`, also the buffers step() needs (a level only fitted to its
// bounds does without them).
void prepare_level(Level& level, const AutomatonOptions& options, bool ring, bool stepping = true);

// The finest level starts from a grid interpolated from the level above,
// where cells of one coarse cell differ in size: some may start outside
// their bounds (area, a rigid cell's width and height). Smooths the nodes
// around every such cell for a few rounds, then blends them back towards
// rest until every cell is inside, so
// the steps' guards keep every bound from the start.
struct Fit {
    int rounds = 0;
    bool reset = false;  // nodes went straight back to rest after the blending rounds
};
Fit fit_to_bounds(Level& level);

// Measures every cell (area, move radius, quality) from the current nodes;
// run before the first step of a level, after any change to the nodes that
// step() did not make.
void measure_cells(Level& level);

struct StepStats {
    double difference;  // largest neighbour density difference / reference density, before the step
    double moved;       // largest node move made, in cells of this level
};

// One synchronous step (needs measure_cells' state, and keeps it current).
StepStats step(Level& level, const AutomatonOptions& options);

// The rule alone, the first half of step(): new energies into next_energy,
// proposed nodes into next_nodes, no guard. Returns the step's `difference`.
double apply_rule(Level& level, const AutomatonOptions& options);

// Throws lmrefine::Error naming the first broken invariant (tests,
// debugging): a cell neither valid (automaton_cell.h) nor inside a bound it
// broke at the level's start (start_nodes) as far as then, a node outside
// the grid's rectangle, a negative energy, the total energy changed.
void check_invariants(const Level& level, int step_index);

}  // namespace lmrefine::automaton_detail
