// The cellular automaton (docs/method.md §4): a grid of nodes over the lightmap, one
// cell per texel, every cell holding energy. Energy diffuses from denser to
// less dense neighbours (density = energy / cell area) and every edge between
// two cells moves towards the less dense one, so high-energy cells grow and
// low-energy cells shrink until densities are even.
//
// Steps are synchronous (every cell reads the previous state, writes a second
// buffer), so the result does not depend on visiting order or thread count.
// Guards hold after every step: every cell valid (well shaped, within its
// area bounds, a rigid cell as thick as at rest; docs/refiner.md,
// "Invariants") or no further outside a bound than at its level's start, no
// negative energy, total energy conserved, every node inside the grid's
// rectangle. To converge in a number of steps that does not grow with the
// resolution, the automaton runs coarse-to-fine on a pyramid of grids (cells
// of 2^k x 2^k texels), each level starting from the one above.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "lmrefine/automaton/warp.h"

namespace lmrefine {

class Progress;

// How the outermost ring of cells is treated (the thesis tried all three).
enum class BorderMode {
    Same,       // border nodes follow the common rule, sliding along the border
    BorderRule, // border cells keep their outer edges pinned to the border
    ExtraRing,  // a ring of neutral cells is added outside and removed after
                // each level; the inner grid is rescaled onto the border
};

struct AutomatonOptions {
    double diffusion = 0.05;     // energy moved per step per unit density difference, [0, 0.25]
    double rate = 0.5;           // node move per step, in cell sizes, at full contrast (capped at 1/4)
    double delta = 0.02;         // stop when every neighbour density difference / mean density < delta
    int max_steps = 8;           // step cap per pyramid level (and per extra pass)
    double min_area = 0.25;      // a covered cell never shrinks below this times its original area
    double max_area = 8.0;       // ... nor grows above this
    // A chart's edge texels facing the gutter (covered, next to an uncovered
    // texel, not rigid) may shrink to this times their area (never below
    // min_area) and need not keep their width and height; 1 = rigid. 0.8:
    // the best equal-error ratio on the bundled scenes (docs/refiner.md).
    double edge_shrink = 0.8;
    BorderMode border = BorderMode::Same;
    bool coarse_to_fine = true;  // false: a single level (needs O(L^2) steps; for comparison)
    int passes = 1;              // extra passes rerun the finest level with energies reset
    // Texels per cell side of the finest level that steps (a power of two):
    // above 1 the pyramid stops stepping there, and the one-texel level is
    // only made from its grid and fitted to its bounds. A warp moves only
    // vertices, so a deformation much finer than the triangles is lost
    // anyway (docs/refiner.md, "The finest level").
    int finest_block = 1;
    bool check_invariants = false;  // verify every guard after every step (tests; slower)
};

// One energy per cell (channels = 1) or four directional ones (channels = 4:
// r = facing down (+row), g = facing right (+column), b = facing up,
// a = facing left, the gradient map's channels).
struct AutomatonInput {
    const float* energy = nullptr;  // height * width * channels, >= 0
    const uint8_t* mask = nullptr;  // height * width, 1 = covered; null = all covered
    // height * width, 1 = rigid: the cell may shift, never get smaller than
    // its original area, width or height (the gutter). Uncovered texels
    // always are; covered ones next to them (a chart's edge) shrink only to
    // edge_shrink unless rigid here.
    const uint8_t* rigid = nullptr;
    int height = 0;
    int width = 0;
    int channels = 1;
};

struct LevelStats {
    int block = 1;       // texels per cell side
    int rows = 0;
    int cols = 0;
    int steps = 0;
    double max_difference = 0;  // largest neighbour density difference / mean density at the end
    bool converged = false;
    bool settled = false;       // stopped because no node moved any more (guards hold the rest)
    double seconds = 0;         // wall time of the level, setup included
    // The finest level: rounds fit_to_bounds took to bring the cells
    // interpolated from the level above inside their bounds (0: none
    // outside; dozens: the deformation was partly undone, see docs/refiner.md).
    int fit_rounds = 0;
    // The finest level: fit_to_bounds gave up blending and sent the nodes
    // around the cells still outside back to rest, round after round (it
    // cascaded: a region's deformation was undone, see docs/refiner.md).
    bool fit_reset = false;
};

struct AutomatonResult {
    NodeGrid grid;                 // finest grid (one texel per cell), pixel space
    // Final energies of the one-texel level, height * width * channels (with
    // finest_block > 1 it takes no step: the input's, uncovered texels 0).
    LargeVector<float> energy;
    std::vector<LevelStats> levels;  // coarsest first
    int steps = 0;
    bool converged = false;        // the finest level that stepped reached delta
};

AutomatonResult run_automaton(const AutomatonInput& input, const AutomatonOptions& options,
                              Progress* progress = nullptr);

BorderMode parse_border_mode(const std::string& name);

// Test hook, not part of the method: one synchronous step of the rule with
// the guards off, for the plain reference in tests/automaton_reference.py.
// One level of one-texel cells (with BorderMode::ExtraRing, plus its ring)
// starts from `nodes`, the level's (rows + 1) x (cols + 1) node positions in
// pixel space, ring included; the result is what the rule proposes, before
// any guard puts a node back.
struct RuleStep {
    std::vector<glm::dvec2> nodes;  // proposed node positions, as `nodes`
    std::vector<double> energy;     // new energies, level cells x channels
    double difference = 0;          // largest neighbour density difference / reference density, before
};
RuleStep automaton_rule_step(const AutomatonInput& input, const AutomatonOptions& options,
                             const std::vector<glm::dvec2>& nodes);

}  // namespace lmrefine
