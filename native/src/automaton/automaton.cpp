// The automaton's driver: builds the pyramid of levels, runs each to
// convergence (or its step cap) and hands its grid down to the next finer
// level.
#include "lmrefine/automaton/automaton.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "automaton_level.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"

namespace lmrefine {
namespace {

using automaton_detail::Level;

// Coarsen until the grid is at most this many cells across: room moves
// across a level that small within its few steps.
constexpr int kCoarsestCells = 8;
// A level whose nodes all moved less than this (in its cells) in a step has settled.
constexpr double kSettledMove = 1e-3;
// Levels with blocks of at least kManyStepsBlock texels get kCoarseStepFactor
// x max_steps: they cost 1/64 of the finest level per step or less, and room
// moves across the map there (how the values were chosen: docs/refiner.md,
// "Constants and how they were chosen").
constexpr int kManyStepsBlock = 8;
constexpr int kCoarseStepFactor = 4;

// Levels until the coarsest is at most kCoarsestCells cells across.
int level_count(int width, int height, bool coarse_to_fine) {
    if (!coarse_to_fine) return 1;
    int levels = 1;
    for (int block = 1; (std::max(width, height) + block - 1) / block > kCoarsestCells; block *= 2) ++levels;
    return levels;
}

// Texel kinds of rigid_texels(): free, a chart's edge facing the gutter, rigid.
constexpr uint8_t kFreeTexel = 0, kEdgeTexel = 1, kRigidTexel = 2;

// Makes `level` a level of `block`-texel cells: energies summed over the
// block, the uncovered texels counted, the rigid area (a chart edge texel
// counting edge_shrink), nodes carried from the coarser grid (or at rest).
// With a ring, one extra ring of cells (one block wide) surrounds the grid,
// its outer nodes one block outside the inner border nodes. The level's
// arrays keep their storage (reserve_levels); prepare_level sets the rest.
void make_level(Level& level, const AutomatonInput& input, const LargeVector<uint8_t>& rigid, double edge_shrink,
                int block, const NodeGrid* coarser, bool ring) {
    const double texel_rigid_area[3] = {0.0, edge_shrink, 1.0};
    const NodeGrid inner = grid_axes(input.width, input.height, block);
    const int pad = ring ? 1 : 0;
    level.block = block;
    level.channels = input.channels;
    level.reference_density = {};
    NodeGrid& grid = level.grid;
    grid.rows = inner.rows + 2 * pad;
    grid.cols = inner.cols + 2 * pad;
    grid.xs.clear();
    grid.ys.clear();
    if (ring) grid.xs.push_back(-block);
    grid.xs.insert(grid.xs.end(), inner.xs.begin(), inner.xs.end());
    if (ring) grid.xs.push_back(input.width + block);
    if (ring) grid.ys.push_back(-block);
    grid.ys.insert(grid.ys.end(), inner.ys.begin(), inner.ys.end());
    if (ring) grid.ys.push_back(input.height + block);
    grid.nodes.resize(size_t(grid.rows + 1) * (grid.cols + 1));

    parallel_for(inner.rows + 1, 16, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            for (int j = 0; j <= inner.cols; ++j) {
                const glm::dvec2 rest(inner.xs[j], inner.ys[i]);
                grid.node(i + pad, j + pad) = coarser ? warp_point(*coarser, rest) : rest;
            }
        }
    });
    if (ring) {
        // Outer ring nodes: the inner border node pushed one block outwards,
        // so ring cells start as parallelograms.
        const int R = grid.rows, C = grid.cols;
        for (int j = 1; j < C; ++j) {
            grid.node(0, j) = grid.node(1, j) - glm::dvec2(0, block);
            grid.node(R, j) = grid.node(R - 1, j) + glm::dvec2(0, block);
        }
        for (int i = 1; i < R; ++i) {
            grid.node(i, 0) = grid.node(i, 1) - glm::dvec2(block, 0);
            grid.node(i, C) = grid.node(i, C - 1) + glm::dvec2(block, 0);
        }
        grid.node(0, 0) = grid.node(1, 1) - glm::dvec2(block, block);
        grid.node(0, C) = grid.node(1, C - 1) + glm::dvec2(block, -block);
        grid.node(R, 0) = grid.node(R - 1, 1) + glm::dvec2(-block, block);
        grid.node(R, C) = grid.node(R - 1, C - 1) + glm::dvec2(block, block);
    }

    const size_t cells = size_t(grid.rows) * grid.cols;
    level.energy.assign(cells * input.channels, 0.0);
    level.uncovered_area.assign(cells, 0.0);
    level.rigid_area.assign(cells, 0.0);
    parallel_for(inner.rows, 4, [&](int64_t begin, int64_t end) {
        for (int bi = int(begin); bi < int(end); ++bi) {
            for (int bj = 0; bj < inner.cols; ++bj) {
                const size_t c = level.cell(bi + pad, bj + pad);
                for (int y = bi * block; y < std::min((bi + 1) * block, input.height); ++y) {
                    for (int x = bj * block; x < std::min((bj + 1) * block, input.width); ++x) {
                        const size_t t = size_t(y) * input.width + x;
                        level.rigid_area[c] += texel_rigid_area[rigid[t]];
                        if (input.mask && !input.mask[t]) {
                            level.uncovered_area[c] += 1.0;
                            continue;
                        }
                        for (int k = 0; k < input.channels; ++k) {
                            level.energy[c * input.channels + k] += input.energy[t * input.channels + k];
                        }
                    }
                }
            }
        }
    });
}

// Per texel: rigid (uncovered: the gutter keeps its width in texels, and the
// texels input.rigid marks), a chart's edge (covered, next to an uncovered
// texel: shrinks only to edge_shrink) or free.
LargeVector<uint8_t> rigid_texels(const AutomatonInput& input) {
    LargeVector<uint8_t> rigid(size_t(input.width) * input.height, kFreeTexel);
    if (input.rigid) {
        for (size_t t = 0; t < rigid.size(); ++t) rigid[t] = input.rigid[t] ? kRigidTexel : kFreeTexel;
    }
    if (!input.mask) return rigid;
    parallel_for(input.height, 16, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            for (int j = 0; j < input.width; ++j) {
                bool near_gutter = false;
                for (int y = std::max(0, i - 1); y <= std::min(input.height - 1, i + 1); ++y) {
                    for (int x = std::max(0, j - 1); x <= std::min(input.width - 1, j + 1); ++x) {
                        near_gutter = near_gutter || !input.mask[size_t(y) * input.width + x];
                    }
                }
                uint8_t& kind = rigid[size_t(i) * input.width + j];
                if (!input.mask[size_t(i) * input.width + j]) kind = kRigidTexel;
                else if (near_gutter && kind == kFreeTexel) kind = kEdgeTexel;
            }
        }
    });
    return rigid;
}

// Reserves every per-cell and per-node array of the levels, and the nodes
// of the grid handed down between them, for the finest level (ring
// included): each level reuses the storage of the coarser one before it,
// so a run faults in fresh memory for the finest level only (on some
// machines fresh memory costs more than a step; docs/refiner.md "How a step
// stays cheap"), in large pages where the system gives them (LargeVector).
// Reserving touches no memory.
void reserve_levels(Level& level, NodeGrid& carried, int width, int height, int channels, bool ring) {
    const size_t pad = ring ? 2 : 0;
    const size_t cells = (size_t(width) + pad) * (size_t(height) + pad);
    const size_t nodes = (size_t(width) + pad + 1) * (size_t(height) + pad + 1);
    for (auto* v : {&level.energy, &level.next_energy}) v->reserve(cells * size_t(channels));
    for (auto* v : {&level.uncovered_area, &level.rigid_area, &level.area, &level.safe_radius, &level.quality,
                    &level.next_area, &level.next_safe_radius, &level.next_quality}) {
        v->reserve(cells);
    }
    for (auto* v : {&level.grid.nodes, &level.next_nodes, &carried.nodes}) v->reserve(nodes);
    level.kind.reserve(cells);
    level.node_mode.reserve(nodes);
    level.suspect_round.reserve(cells);
    level.breaking_cell.reserve(cells);
    level.reverted_node.reserve(nodes);
}

// The level's grid without its ring, affinely rescaled so the inner border
// nodes' bounding box is the lightmap again (an affine map with positive
// scales keeps every cell convex and non-inverted).
NodeGrid inner_grid(const Level& level, int width, int height) {
    NodeGrid inner;
    inner.rows = level.rows() - 2;
    inner.cols = level.cols() - 2;
    inner.xs.assign(level.grid.xs.begin() + 1, level.grid.xs.end() - 1);
    inner.ys.assign(level.grid.ys.begin() + 1, level.grid.ys.end() - 1);
    glm::dvec2 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
    for (int i = 1; i <= inner.rows + 1; ++i) {
        for (int j = 1; j <= inner.cols + 1; ++j) {
            lo = glm::min(lo, level.grid.node(i, j));
            hi = glm::max(hi, level.grid.node(i, j));
        }
    }
    const glm::dvec2 scale = glm::dvec2(width, height) / (hi - lo);
    for (int i = 1; i <= inner.rows + 1; ++i) {
        for (int j = 1; j <= inner.cols + 1; ++j) {
            glm::dvec2 p = (level.grid.node(i, j) - lo) * scale;
            inner.nodes.push_back(glm::clamp(p, glm::dvec2(0), glm::dvec2(width, height)));
        }
    }
    return inner;
}

// Hands the finished level's grid to the next finer level as `carried`.
// Without a ring its nodes swap buffers with carried's (level.grid keeps
// its rows, cols, xs and ys, which level.cell() reads; its nodes are then
// the old carried ones, overwritten by the next make_level).
void hand_down(Level& level, bool ring, int width, int height, NodeGrid& carried) {
    if (ring) {
        carried = inner_grid(level, width, height);
        return;
    }
    carried.rows = level.grid.rows;
    carried.cols = level.grid.cols;
    carried.xs = level.grid.xs;
    carried.ys = level.grid.ys;
    carried.nodes.swap(level.grid.nodes);
}

// Steps a level of `block`-texel cells may take (kCoarseStepFactor above).
int level_step_budget(int block, const AutomatonOptions& options) {
    return block >= kManyStepsBlock ? options.max_steps * kCoarseStepFactor : options.max_steps;
}

// Runs `level` for at most `budget` steps.
void run_level(Level& level, const AutomatonOptions& options, bool ring, int budget, LevelStats& stats,
               int& total_steps, Progress* progress) {
    // A level only fitted (0 steps) needs no step buffers nor measured cells.
    const bool stepping = budget > 0 || options.check_invariants;
    automaton_detail::prepare_level(level, options, ring, stepping);
    // The finest level's grid: every bound holds from its start.
    if (level.block == 1) {
        const automaton_detail::Fit fit = automaton_detail::fit_to_bounds(level);
        stats.fit_rounds = fit.rounds;
        stats.fit_reset = fit.reset;
    }
    if (!stepping) return;
    automaton_detail::measure_cells(level);
    if (options.check_invariants) {
        level.start_nodes = level.grid.nodes;
        automaton_detail::check_invariants(level, total_steps);
    }
    stats.steps = 0;
    stats.converged = false;
    for (int s = 0; s < budget; ++s) {
        if (progress) progress->check();
        const automaton_detail::StepStats step = automaton_detail::step(level, options);
        stats.max_difference = step.difference;
        stats.converged = step.difference < options.delta;
        // Settled: guards hold the remaining differences and nodes have
        // stopped moving; more steps would only let diffusion creep on.
        stats.settled = !stats.converged && step.moved < kSettledMove;
        ++stats.steps;
        ++total_steps;
        if (options.check_invariants) automaton_detail::check_invariants(level, total_steps);
        if (progress) progress->advance();
        if (stats.converged || stats.settled) break;
    }
}

}  // namespace

BorderMode parse_border_mode(const std::string& name) {
    if (name == "same") return BorderMode::Same;
    if (name == "border_rule") return BorderMode::BorderRule;
    if (name == "extra_ring") return BorderMode::ExtraRing;
    LMREFINE_THROW(InvalidArgument, "border must be 'same', 'border_rule' or 'extra_ring', got '" + name + "'");
}

AutomatonResult run_automaton(const AutomatonInput& input, const AutomatonOptions& options, Progress* progress) {
    LMREFINE_REQUIRE(input.width > 0 && input.height > 0, "the energy map is empty");
    LMREFINE_REQUIRE(input.channels == 1 || input.channels == 4,
                     "the energy map needs 1 channel, or 4 for the directional variant (r, g, b, a)");
    LMREFINE_REQUIRE(options.diffusion >= 0 && options.diffusion <= 0.25,
                     "diffusion must be in [0, 0.25] (above 0.25 a cell could give away more energy than it has)");
    LMREFINE_REQUIRE(options.rate > 0 && options.rate <= 1, "rate must be in (0, 1]");
    LMREFINE_REQUIRE(options.delta > 0, "delta must be positive");
    // Bounded so a mistyped value cannot run for days (the defaults are 8 and 1).
    LMREFINE_REQUIRE(options.max_steps >= 0 && options.max_steps <= 10000, "max_steps must be in [0, 10000]");
    LMREFINE_REQUIRE(options.min_area > 0 && options.min_area <= 1,
                     "min_shrink must be in (0, 1]: the smallest allowed cell area relative to its original area");
    LMREFINE_REQUIRE(options.max_area >= 1, "max_magnification must be >= 1");
    LMREFINE_REQUIRE(options.edge_shrink > 0 && options.edge_shrink <= 1,
                     "edge_shrink must be in (0, 1]: the smallest area of a chart's edge texel relative to its "
                     "original area (1 = rigid)");
    LMREFINE_REQUIRE(options.passes >= 1 && options.passes <= 64, "passes must be in [1, 64]");
    LMREFINE_REQUIRE(options.finest_block >= 1 && options.finest_block <= 1024 &&
                         (options.finest_block & (options.finest_block - 1)) == 0,
                     "finest_block must be a power of two in [1, 1024]");
    const int64_t values = int64_t(input.width) * input.height * input.channels;
    for (int64_t k = 0; k < values; ++k) {
        if (!(input.energy[k] >= 0) || !std::isfinite(input.energy[k])) {
            LMREFINE_THROW(InvalidArgument, "energy must be finite and >= 0; found " +
                                                std::to_string(input.energy[k]) + " at flat index " +
                                                std::to_string(k));
        }
    }

    const bool ring = options.border == BorderMode::ExtraRing;
    const int levels = level_count(input.width, input.height, options.coarse_to_fine);
    // The finest level run: finest_block's, or the coarsest if that is coarser.
    int finest = 0;
    while ((1 << finest) < options.finest_block && finest < levels - 1) ++finest;
    const int finest_block = 1 << finest;
    uint64_t budget = uint64_t(level_step_budget(finest_block, options)) * uint64_t(options.passes - 1);
    for (int l = finest; l < levels; ++l) budget += uint64_t(level_step_budget(1 << l, options));
    if (progress) progress->begin("automaton", budget);

    const LargeVector<uint8_t> rigid = rigid_texels(input);
    AutomatonResult result;
    NodeGrid carried;
    Level level;
    reserve_levels(level, carried, input.width, input.height, input.channels, ring);
    using Clock = std::chrono::steady_clock;
    // Levels run coarsest first, down to the finest block; then extra passes
    // of it. Above one-texel cells, the one-texel level is made from that
    // grid and fitted to its bounds, with no step, so the returned grid
    // holds every bound as a run down to one texel does.
    auto run = [&](int block, int steps) {
        const Clock::time_point start = Clock::now();
        const bool first = result.levels.empty();
        make_level(level, input, rigid, options.edge_shrink, block, first ? nullptr : &carried, ring);
        LevelStats stats;
        stats.block = block;
        stats.rows = level.rows() - (ring ? 2 : 0);
        stats.cols = level.cols() - (ring ? 2 : 0);
        run_level(level, options, ring, steps, stats, result.steps, progress);
        hand_down(level, ring, input.width, input.height, carried);
        stats.seconds = std::chrono::duration<double>(Clock::now() - start).count();
        result.levels.push_back(stats);
    };
    for (int l = levels - 1; l >= finest; --l) run(1 << l, level_step_budget(1 << l, options));
    for (int pass = 1; pass < options.passes; ++pass) run(finest_block, level_step_budget(finest_block, options));
    if (finest_block > 1) run(1, 0);
    if (progress) progress->finish();

    // The finest level run decides (a fitted one-texel level takes no step).
    result.converged = result.levels[result.levels.size() - (finest_block > 1 ? 2 : 1)].converged;
    result.grid = std::move(carried);
    const int pad = ring ? 1 : 0;
    result.energy.resize(size_t(values));
    for (int i = 0; i < input.height; ++i) {
        for (int j = 0; j < input.width; ++j) {
            for (int k = 0; k < input.channels; ++k) {
                result.energy[(size_t(i) * input.width + j) * input.channels + k] =
                    float(level.energy[level.cell(i + pad, j + pad) * input.channels + k]);
            }
        }
    }
    return result;
}

RuleStep automaton_rule_step(const AutomatonInput& input, const AutomatonOptions& options,
                             const std::vector<glm::dvec2>& nodes) {
    LMREFINE_REQUIRE(input.width > 0 && input.height > 0, "the energy map is empty");
    LMREFINE_REQUIRE(input.channels == 1 || input.channels == 4, "the energy map needs 1 or 4 channels");
    const bool ring = options.border == BorderMode::ExtraRing;
    Level level;
    make_level(level, input, rigid_texels(input), options.edge_shrink, 1, nullptr, ring);
    LMREFINE_REQUIRE(nodes.size() == level.grid.nodes.size(),
                     "nodes must be the level's (rows + 1) x (cols + 1) nodes, ring included");
    level.grid.nodes.assign(nodes.begin(), nodes.end());
    automaton_detail::prepare_level(level, options, ring);
    automaton_detail::measure_cells(level);
    RuleStep out;
    out.difference = automaton_detail::apply_rule(level, options);
    out.nodes.assign(level.next_nodes.begin(), level.next_nodes.end());
    out.energy.assign(level.next_energy.begin(), level.next_energy.end());
    return out;
}

}  // namespace lmrefine
