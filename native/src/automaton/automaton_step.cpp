// The automaton's rule (method §4) and its guards. Every quantity of step n+1
// is computed from the state of step n only, cell by cell and edge by edge,
// so rows can be split among threads in any way with the same result.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "automaton_cell.h"
#include "automaton_level.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"

namespace lmrefine::automaton_detail {
namespace {

// Guard reverts run over the whole grid while more than 1/this of the cells
// break a bound, over lists of cells below.
constexpr int64_t kDenseRevertFraction = 32;
// Coarse levels keep cells above min_shrink x this: cells interpolated from
// a coarse cell differ in size, and the finest level must start (nearly)
// inside its bounds (docs/refiner.md, "Constants and how they were chosen").
constexpr double kCoarseShrinkMargin = 1.5;

// The channel of a cell that faces each side (directional variant); with one
// channel every side uses channel 0.
struct Facing {
    int down, right, up, left;
};
constexpr Facing facing(int channels) { return channels == 4 ? Facing{0, 1, 2, 3} : Facing{0, 0, 0, 0}; }

// Relative pressure difference in [-1, 1]; > 0 moves the edge towards b.
double push(double a, double b) { return a + b > 0 ? (a - b) / (a + b) : 0.0; }

}  // namespace

void prepare_level(Level& level, const AutomatonOptions& options, bool ring, bool stepping) {
    const int rows = level.rows(), cols = level.cols(), channels = level.channels;
    const size_t cells = size_t(rows) * cols;
    level.kind.assign(cells, CellKind::Material);
    std::array<double, 4> energy{}, covered_area{};
    // Coarse levels keep a margin inside the bounds: cells interpolated from
    // a coarse cell differ in size, and the finest level must start inside.
    const bool coarse = level.block > 1;
    const double lowest = coarse ? std::min(1.0, options.min_area * kCoarseShrinkMargin) : options.min_area;
    const double highest = coarse ? std::max(1.0, options.max_area * 0.8) : options.max_area;
    level.covered_min_factor = lowest;
    level.covered_max_factor = highest;
    level.ring_min_factor = options.min_area;
    for (int i = 0; i < rows; ++i) {
        for (int j = 0; j < cols; ++j) {
            const size_t c = level.cell(i, j);
            const double a0 = (level.grid.xs[j + 1] - level.grid.xs[j]) * (level.grid.ys[i + 1] - level.grid.ys[i]);
            const bool in_ring = ring && (i == 0 || j == 0 || i == rows - 1 || j == cols - 1);
            if (in_ring) {
                level.kind[c] = CellKind::Ring;
                level.uncovered_area[c] = a0;
                level.rigid_area[c] = 0;
            } else if (level.uncovered_area[c] >= a0) {
                level.kind[c] = CellKind::Gutter;
            } else {
                // A coarse cell holding any rigid texel is rigid as a whole:
                // its texels get their share of its area when it is
                // interpolated, so a partly rigid block may not shrink.
                if (coarse && level.rigid_area[c] > 0) level.rigid_area[c] = a0;
                for (int k = 0; k < channels; ++k) {
                    energy[k] += level.energy[c * channels + k];
                    covered_area[k] += a0 - level.uncovered_area[c];
                }
            }
        }
    }
    level.initial_total = 0;
    for (double e : level.energy) level.initial_total += e;
    for (int k = 0; k < channels; ++k) {
        level.reference_density[k] = covered_area[k] > 0 ? energy[k] / covered_area[k] : 0.0;
    }

    level.node_mode.assign(size_t(rows + 1) * (cols + 1), NodeMode::Free);
    for (int i = 0; i <= rows; ++i) {
        for (int j = 0; j <= cols; ++j) {
            const bool top_bottom = i == 0 || i == rows, left_right = j == 0 || j == cols;
            NodeMode mode = NodeMode::Free;
            if (top_bottom && left_right) {
                mode = NodeMode::Fixed;
            } else if (top_bottom || left_right) {
                if (ring || options.border == BorderMode::BorderRule) {
                    mode = NodeMode::Fixed;
                } else {
                    mode = top_bottom ? NodeMode::SlideX : NodeMode::SlideY;
                }
            }
            level.node_mode[level.node(i, j)] = mode;
        }
    }

    level.suspect_round.assign(cells, 0);
    level.revert_round = 0;
    if (!stepping) return;
    level.next_nodes = level.grid.nodes;
    level.next_energy = level.energy;
    for (auto* v : {&level.area, &level.safe_radius, &level.quality, &level.next_area, &level.next_safe_radius,
                    &level.next_quality}) {
        v->resize(cells);
    }
    level.row_difference.assign(size_t(rows + 1), 0.0);
    level.row_moved.assign(size_t(rows + 1), 0.0);
    level.breaking_cell.assign(cells, 0);
    level.reverted_node.assign(size_t(rows + 1) * (cols + 1), 0);
}

namespace {

// A cell's shape state, written to the given arrays.
void write_shape(size_t c, const Shape& now, double* area, double* radius, double* quality) {
    area[c] = now.area;
    radius[c] = now.radius;
    quality[c] = now.quality2;
}

// Densities of the cells of row i from their energies and areas: energy /
// area for diffusion (0 outside material cells); pressure per axis: a
// cell's springs along an axis push both its edges across that axis (four
// channels: y from r + b, x from g + a), uncovered texels weighing as the
// mean density.
template <int channels>
void row_densities(const Level& level, int i, double* diffusion, double* pressure) {
    constexpr int axes = channels == 4 ? 2 : 1;
    for (int j = 0; j < level.cols(); ++j) {
        const size_t c = level.cell(i, j);
        const double a = level.area[c];
        const double* e = &level.energy[c * channels];
        if (channels == 1 && level.uncovered_area[c] == 0) {
            // One channel, no uncovered texel: the pressure's numerator is
            // e + reference x 0 = e exactly, so one division gives both.
            const double density = e[0] / a;
            diffusion[j] = level.kind[c] == CellKind::Material ? density : 0.0;
            pressure[j] = density;
            continue;
        }
        // Numerators: each channel's energy, then each axis' pressure
        // energy; divided by the area in one loop the compiler may vectorise.
        double numerator[channels + axes];
        for (int k = 0; k < channels; ++k) numerator[k] = e[k];
        for (int axis = 0; axis < axes; ++axis) {
            double sum = 0.0, reference = 0.0;
            for (int k = axis; k < channels; k += axes) {
                sum += e[k];
                reference += level.reference_density[k];
            }
            numerator[channels + axis] = sum + reference * level.uncovered_area[c];
        }
        double quotient[channels + axes];
        for (int k = 0; k < channels + axes; ++k) quotient[k] = numerator[k] / a;
        const bool material = level.kind[c] == CellKind::Material;
        for (int k = 0; k < channels; ++k) diffusion[j * channels + k] = material ? quotient[k] : 0.0;
        for (int axis = 0; axis < axes; ++axis) pressure[j * axes + axis] = quotient[channels + axis];
    }
}

}  // namespace

double exact_quality2(const double c2[4], const double l2[4], double shortest, double longest) {
    const double sine_over[4] = {l2[3] * l2[0], l2[0] * l2[1], l2[1] * l2[2], l2[2] * l2[3]};
    double sine2[4];
    for (int k = 0; k < 4; ++k) sine2[k] = c2[k] / sine_over[k];
    const double sin2 = std::min({1.0, sine2[0], sine2[1], sine2[2], sine2[3]});
    return std::min(sin2, 16 * shortest / longest);
}

void measure_cells(Level& level) {
    parallel_for(level.rows(), kRowGrain, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            for (int j = 0; j < level.cols(); ++j) {
                glm::dvec2 q[4];
                corners(level, level.grid.nodes, i, j, q);
                write_shape(level.cell(i, j), shape(q), level.area.data(), level.safe_radius.data(),
                            level.quality.data());
            }
        }
    });
}

namespace {

// The rule's move of a node that is not fixed: rate / 2 x sqrt(mean area
// of its cells) x (fx, fy), fx the sum of the pushes of the vertical edges
// above and below it, fy of the horizontal edges left and right of it (an
// edge missing at the border adds nothing); a border node keeps to its
// border; shortened to the smallest move radius of its cells (a quarter
// cell for a square) and clamped to the grid's rectangle.
template <class PushV, class PushH>
inline glm::dvec2 propose_node(const Level& level, const AutomatonOptions& options, int i, int j, const PushV& push_v,
                        const PushH& push_h) {
    const int rows = level.rows(), cols = level.cols();
    const NodeMode mode = level.node_mode[level.node(i, j)];
    double fx = 0, fy = 0, area_sum = 0, radius = std::numeric_limits<double>::infinity();
    int adjacent = 0;
    if (i > 0 && i < rows && j > 0 && j < cols) {
        // Inside (nearly every node): all four edges and cells, in the order
        // of the general case below (same rounding).
        const size_t up = size_t(i - 1) * cols + j, down = up + cols;
        fx = push_v(i - 1, j) + push_v(i, j);
        fy = push_h(i, j - 1) + push_h(i, j);
        area_sum = level.area[up - 1] + level.area[up] + level.area[down - 1] + level.area[down];
        radius = std::min(std::min(level.safe_radius[up - 1], level.safe_radius[up]),
                          std::min(level.safe_radius[down - 1], level.safe_radius[down]));
        adjacent = 4;
    } else {
        if (i > 0) fx += push_v(i - 1, j);
        if (i < rows) fx += push_v(i, j);
        if (j > 0) fy += push_h(i, j - 1);
        if (j < cols) fy += push_h(i, j);
        for (int di = -1; di <= 0; ++di) {
            for (int dj = -1; dj <= 0; ++dj) {
                const int ci = i + di, cj = j + dj;
                if (ci < 0 || cj < 0 || ci >= rows || cj >= cols) continue;
                area_sum += level.area[level.cell(ci, cj)];
                radius = std::min(radius, level.safe_radius[level.cell(ci, cj)]);
                ++adjacent;
            }
        }
    }
    // x / 4 == x * 0.25 exactly; a division costs as much as the root.
    const double size = std::sqrt(adjacent == 4 ? area_sum * 0.25 : area_sum / adjacent);
    glm::dvec2 move = 0.5 * options.rate * size * glm::dvec2(fx, fy);
    if (mode == NodeMode::SlideX) move.y = 0;
    if (mode == NodeMode::SlideY) move.x = 0;
    // Squared first: the root is only needed to shorten a move.
    const double length2 = glm::dot(move, move);
    if (length2 > radius * radius) move *= radius / std::sqrt(length2);
    glm::dvec2 p = level.grid.nodes[level.node(i, j)] + move;
    p.x = std::clamp(p.x, level.grid.xs.front(), level.grid.xs.back());
    p.y = std::clamp(p.y, level.grid.ys.front(), level.grid.ys.back());
    return p;
}

// The rule (docs/refiner.md "The automaton", the plain version in
// tests/automaton_reference.py), for one or four channels (constants let the
// compiler unroll the per-channel loops). From the current state only:
// 1. per cell, the diffusion density energy / area (0 outside chart cells)
//    and the pressure per axis (the axis' energies plus the reference
//    density times the uncovered area, over the area);
// 2. per edge between 4-neighbours, the flux diffusion x min(area) x the
//    difference of the facing densities (between chart cells only) and the
//    push (p_a - p_b) / (p_a + p_b) of the pressures across it;
// 3. new energies into next_energy (each flux leaves one cell and enters the
//    other: the total is conserved) and proposed nodes into next_nodes
//    (propose_node). No guard: step() judges the proposal.
// Returns the largest neighbour density difference relative to the
// reference density (the stop criterion), before the step.
template <int channels>
double rule_of(Level& level, const AutomatonOptions& options) {
    const int rows = level.rows(), cols = level.cols();
    constexpr Facing face = facing(channels);
    constexpr int axes = channels == 4 ? 2 : 1;  // pressure: y (and x) axis
    const LargeVector<glm::dvec2>& nodes = level.grid.nodes;

    // 1. Edges: energy flux (only between covered cells, from the denser to
    // the less dense; the border and the gutter are adiabatic) and the push
    // that moves the edge towards the less dense cell.
    // Cells a and b with their densities (da, pa: diffusion, pressure).
    // Returns |pa - pb| between covered cells (0 elsewhere): the density
    // difference, relative to the axis' reference density below.
    auto edge = [&](size_t a, double da, double pa, size_t b, double db, double pb, double& push_out,
                    double& flux_out) {
        push_out = push(pa, pb);
        flux_out = 0.0;
        if (level.kind[a] != CellKind::Material || level.kind[b] != CellKind::Material) return 0.0;
        flux_out = options.diffusion * std::min(level.area[a], level.area[b]) * (da - db);
        return std::abs(pa - pb);
    };
    // Reference density per axis; dividing the largest difference of a row
    // by it once gives the largest quotient (rounding is monotonic).
    double reference[2] = {0.0, 0.0};
    for (int axis = 0; axis < axes; ++axis) {
        for (int k = axis; k < channels; k += axes) reference[axis] += level.reference_density[k];
    }
    auto relative = [&](double difference, int axis) {
        return reference[axis] > 0 ? difference / reference[axis] : 0.0;
    };
    // Edge row r: the vertical edges between the cells of row r (r < rows)
    // and the horizontal edges along node row r (between cell rows r - 1 and
    // r); border edges stay 0. `above` and `here`: the densities of cell
    // rows r - 1 and r (diffusion, then pressure), where they exist.
    auto edge_row = [&](int r, const double* above, const double* here, double* push_v, double* flux_v,
                        double* push_h, double* flux_h) {
        const double* pressure_above = above + size_t(cols) * channels;
        const double* pressure_here = here + size_t(cols) * channels;
        double largest_v = 0.0, largest_h = 0.0;
        push_v[0] = flux_v[0] = push_v[cols] = flux_v[cols] = 0.0;
        if (r < rows) {
            for (int j = 1; j < cols; ++j) {
                largest_v = std::max(largest_v, edge(level.cell(r, j - 1), here[(j - 1) * channels + face.right],
                                                     pressure_here[(j - 1) * axes + axes - 1], level.cell(r, j),
                                                     here[j * channels + face.left],
                                                     pressure_here[j * axes + axes - 1], push_v[j], flux_v[j]));
            }
        } else {
            std::fill(push_v, push_v + cols + 1, 0.0);
            std::fill(flux_v, flux_v + cols + 1, 0.0);
        }
        if (r > 0 && r < rows) {
            for (int j = 0; j < cols; ++j) {
                largest_h = std::max(largest_h, edge(level.cell(r - 1, j), above[j * channels + face.down],
                                                     pressure_above[j * axes], level.cell(r, j),
                                                     here[j * channels + face.up], pressure_here[j * axes],
                                                     push_h[j], flux_h[j]));
            }
        } else {
            std::fill(push_h, push_h + cols, 0.0);
            std::fill(flux_h, flux_h + cols, 0.0);
        }
        return std::max(relative(largest_v, axes - 1), relative(largest_h, 0));
    };

    // 2. New energies (each edge's flux leaves one cell and enters the other,
    // so the total is conserved) and proposed node positions.
    parallel_for(rows + 1, kRowGrain, [&](int64_t begin, int64_t end) {
        // The energies and nodes of node rows [begin, end) need edge rows
        // [begin - 1, end], and those the densities of cell rows
        // [begin - 2, end]: each chunk computes its own (the halo rows
        // twice) into scratch that stays in cache, and only its own rows'
        // differences.
        const int first = std::max(0, int(begin) - 1), last = std::min(rows, int(end));
        const int first_cells = std::max(0, first - 1), last_cells = std::min(rows - 1, last);
        const size_t stride = size_t(cols) + 1, edge_rows = size_t(last - first + 1);
        const size_t density_stride = size_t(cols) * (channels + axes);
        thread_local std::vector<double> scratch;
        scratch.resize(4 * stride * edge_rows + density_stride * size_t(last_cells - first_cells + 1));
        double* const pv = scratch.data();
        double* const fv = pv + stride * edge_rows;
        double* const ph = fv + stride * edge_rows;
        double* const fh = ph + stride * edge_rows;
        double* const densities = fh + stride * edge_rows;
        auto density_row = [&](int i) {  // rows outside the grid are never read: any row will do
            return densities + density_stride * size_t(std::clamp(i, first_cells, last_cells) - first_cells);
        };
        for (int i = first_cells; i <= last_cells; ++i) {
            row_densities<channels>(level, i, density_row(i), density_row(i) + size_t(cols) * channels);
        }
        for (int r = first; r <= last; ++r) {
            const size_t o = stride * size_t(r - first);
            const double largest = edge_row(r, density_row(r - 1), density_row(r), pv + o, fv + o, ph + o, fh + o);
            if (r >= begin && r < end) level.row_difference[size_t(r)] = largest;
        }
        // Edge values by edge row and column, as in the whole-grid arrays.
        auto push_v = [&](int r, int j) { return pv[stride * size_t(r - first) + j]; };
        auto flux_v = [&](int r, int j) { return fv[stride * size_t(r - first) + j]; };
        auto push_h = [&](int r, int j) { return ph[stride * size_t(r - first) + j]; };
        auto flux_h = [&](int r, int j) { return fh[stride * size_t(r - first) + j]; };
        for (int i = int(begin); i < int(end); ++i) {
            double largest_move = 0.0;
            if (i < rows) {
                for (int j = 0; j < cols; ++j) {
                    const size_t c = level.cell(i, j);
                    double* e = &level.next_energy[c * channels];
                    for (int k = 0; k < channels; ++k) e[k] = level.energy[c * channels + k];
                    e[face.left] += flux_v(i, j);
                    e[face.right] -= flux_v(i, j + 1);
                    e[face.up] += flux_h(i, j);
                    e[face.down] -= flux_h(i + 1, j);
                    // Rounding can leave -1e-17 where a cell gave all it had.
                    for (int k = 0; k < channels; ++k) e[k] = std::max(e[k], 0.0);
                }
            }
            for (int j = 0; j <= cols; ++j) {
                const size_t n = level.node(i, j);
                glm::dvec2 p = nodes[n];
                if (level.node_mode[n] != NodeMode::Fixed) {
                    p = propose_node(level, options, i, j, push_v, push_h);
                    const glm::dvec2 d = p - nodes[n];
                    largest_move = std::max(largest_move, glm::dot(d, d));
                }
                level.next_nodes[n] = p;
            }
            level.row_moved[size_t(i)] = largest_move;
        }
    });
    return *std::max_element(level.row_difference.begin(), level.row_difference.end());
}

// The guards. Two rules: a moved cell must be valid (`validity`,
// automaton_cell.h: well shaped, area within its bounds, a rigid cell as wide
// and tall as at rest), or, where it already broke a bound before the step
// (cells interpolated from a coarser level may), not break that bound
// further. Invariant: a cell all of whose corners are put back is its
// previous self, which passed these rules (an unchanged cell breaks
// nothing), so putting back the corners of every breaking cell, round after
// round until none breaks, ends in a state that passes them. Rounds are whole sets (every cell judged on
// the same nodes), so the order within a round does not matter.
//
// Judging a cell also measures it for its proposed corners into next_area,
// next_safe_radius and next_quality (the next step's state): a cell whose
// corners did not move keeps its shape and breaks nothing.
inline bool breaks_bound(Level& level, int i, int j) {
    const size_t c = level.cell(i, j);
    glm::dvec2 q[4];
    corners(level, level.next_nodes, i, j, q);
    glm::dvec2 old[4];
    corners(level, level.grid.nodes, i, j, old);
    const bool unchanged = q[0] == old[0] && q[1] == old[1] && q[2] == old[2] && q[3] == old[3];
    const Shape now = unchanged ? Shape{level.area[c], level.safe_radius[c], level.quality[c]} : shape(q);
    write_shape(c, now, level.next_area.data(), level.next_safe_radius.data(), level.next_quality.data());
    if (unchanged) return false;
    const Validity v = validity(q, now, bounds_of(level, i, j));
    if (v.valid()) return false;
    const Shape before{level.area[c], level.safe_radius[c], level.quality[c]};
    return breaks_further(v, now, before, [&] { return thickness(old, before.area); });
}

// Judges the cells of the whole grid in parallel (all of them, or only those
// with a corner put back in this dense round): verdicts in breaking_cell,
// counts per cell row in row_count.
void judge_grid(Level& level, bool only_reverted, std::vector<int64_t>& row_count) {
    const int cols = level.cols();
    parallel_for(level.rows(), kRowGrain, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            int64_t count = 0;
            for (int j = 0; j < cols; ++j) {
                const bool suspect = !only_reverted || level.reverted_node[level.node(i, j)] ||
                                     level.reverted_node[level.node(i, j + 1)] ||
                                     level.reverted_node[level.node(i + 1, j)] ||
                                     level.reverted_node[level.node(i + 1, j + 1)];
                const bool breaks = suspect && breaks_bound(level, i, j);
                level.breaking_cell[level.cell(i, j)] = breaks;
                count += breaks;
            }
            row_count[size_t(i)] = count;
        }
    });
}

// Dense revert rounds, while more than 1/kDenseRevertFraction of the cells
// break a bound (a seventh of the finest level's cells on a Lightmap Pack
// layout): two passes over the whole grid, in parallel. The nodes of
// breaking cells go back; the cells around them are judged again. The same
// sets as revert_sparse's rounds. Marks node rows with a node put back in
// reverted_rows.
void revert_dense(Level& level, std::vector<int64_t>& row_count, std::vector<uint8_t>& reverted_rows) {
    const int rows = level.rows(), cols = level.cols();
    auto total = [&] { return std::accumulate(row_count.begin(), row_count.end(), int64_t(0)); };
    while (total() > int64_t(rows) * cols / kDenseRevertFraction) {
        parallel_for(rows + 1, kRowGrain, [&](int64_t begin, int64_t end) {
            for (int i = int(begin); i < int(end); ++i) {
                // The cell rows above and below node row i, where they exist.
                const uint8_t* above = i > 0 ? &level.breaking_cell[level.cell(i - 1, 0)] : nullptr;
                const uint8_t* below = i < rows ? &level.breaking_cell[level.cell(i, 0)] : nullptr;
                for (int j = 0; j <= cols; ++j) {
                    uint8_t revert = 0;
                    for (const uint8_t* row : {above, below}) {
                        if (!row) continue;
                        if (j > 0) revert |= row[j - 1];
                        if (j < cols) revert |= row[j];
                    }
                    const size_t n = level.node(i, j);
                    level.reverted_node[n] = revert;
                    if (!revert) continue;
                    level.next_nodes[n] = level.grid.nodes[n];
                    reverted_rows[size_t(i)] = 1;
                }
            }
        });
        judge_grid(level, true, row_count);
    }
}

// Sparse revert rounds on lists: the corners of the cells still breaking a
// bound (in breaking_cell, counted per row in row_count) go back, and the
// cells around them are judged again (in parallel, each once per round),
// until none breaks. Marks node rows with a node put back in reverted_rows.
void revert_sparse(Level& level, const std::vector<int64_t>& row_count, std::vector<uint8_t>& reverted_rows) {
    const int rows = level.rows(), cols = level.cols();
    std::vector<std::vector<int32_t>> row_breaking(static_cast<size_t>(rows));
    parallel_for(rows, kRowGrain, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            row_breaking[size_t(i)].clear();
            if (!row_count[size_t(i)]) continue;
            for (int j = 0; j < cols; ++j) {
                if (level.breaking_cell[level.cell(i, j)]) row_breaking[size_t(i)].push_back(int32_t(level.cell(i, j)));
            }
        }
    });
    std::vector<int32_t> breaking;
    for (const auto& r : row_breaking) breaking.insert(breaking.end(), r.begin(), r.end());
    std::vector<int32_t> suspects;
    std::vector<uint8_t> verdicts;
    const auto judge = [&level](int i, int j) { return breaks_bound(level, i, j); };
    while (!breaking.empty()) {
        // Each cell once per round (a stamp, not a sort: within a round the
        // order does not matter, every cell is judged on the same nodes).
        const uint32_t round = ++level.revert_round;
        suspects.clear();
        for (int32_t c : breaking) {
            const int i = c / cols, j = c % cols;
            reverted_rows[size_t(i)] = reverted_rows[size_t(i) + 1] = 1;
            for (int ni = i; ni <= i + 1; ++ni) {
                for (int nj = j; nj <= j + 1; ++nj) {
                    level.next_nodes[level.node(ni, nj)] = level.grid.nodes[level.node(ni, nj)];
                    queue_cells_around(level, ni, nj, round, suspects);
                }
            }
        }
        // Judged in parallel: each suspect once, writing only its own state.
        judge_cells(level, suspects, judge, verdicts, breaking);
    }
}

// The largest node move actually made, in cell sizes of this level: the
// rule's per-row largest moves (row_moved), measured again in the node rows
// a guard put a node back in.
double largest_move(Level& level, const std::vector<uint8_t>& reverted_rows) {
    const int cols = level.cols();
    parallel_for(level.rows() + 1, kRowGrain, [&](int64_t begin, int64_t end) {
        for (int i = int(begin); i < int(end); ++i) {
            if (!reverted_rows[size_t(i)]) continue;
            double largest = 0.0;
            for (int j = 0; j <= cols; ++j) {
                const glm::dvec2 d = level.next_nodes[level.node(i, j)] - level.grid.nodes[level.node(i, j)];
                largest = std::max(largest, glm::dot(d, d));
            }
            level.row_moved[size_t(i)] = largest;
        }
    });
    return std::sqrt(*std::max_element(level.row_moved.begin(), level.row_moved.end())) / level.block;
}

// The step for one or four channels: the rule proposes, the guards put back
// what would break a bound, and the buffers swap.
template <int channels>
StepStats step_of(Level& level, const AutomatonOptions& options) {
    const double difference = rule_of<channels>(level, options);
    std::vector<int64_t> row_count(size_t(level.rows()), 0);
    std::vector<uint8_t> reverted_rows(size_t(level.rows()) + 1, 0);  // node rows with a node put back
    judge_grid(level, false, row_count);
    revert_dense(level, row_count, reverted_rows);
    revert_sparse(level, row_count, reverted_rows);
    const double moved = largest_move(level, reverted_rows);

    level.grid.nodes.swap(level.next_nodes);
    level.energy.swap(level.next_energy);
    level.area.swap(level.next_area);
    level.safe_radius.swap(level.next_safe_radius);
    level.quality.swap(level.next_quality);
    return {difference, moved};
}
}  // namespace

StepStats step(Level& level, const AutomatonOptions& options) {
    return level.channels == 4 ? step_of<4>(level, options) : step_of<1>(level, options);
}

double apply_rule(Level& level, const AutomatonOptions& options) {
    return level.channels == 4 ? rule_of<4>(level, options) : rule_of<1>(level, options);
}

void check_invariants(const Level& level, int step_index) {
    auto fail = [&](const std::string& what) {
        LMREFINE_THROW(Error, "automaton invariant broken after step " + std::to_string(step_index) + " (" +
                                  std::to_string(level.rows()) + "x" + std::to_string(level.cols()) +
                                  " cells): " + what);
    };
    const NodeGrid& grid = level.grid;
    for (int i = 0; i < level.rows(); ++i) {
        for (int j = 0; j < level.cols(); ++j) {
            glm::dvec2 q[4];
            corners(level, grid.nodes, i, j, q);
            const Shape s = shape(q);
            const Validity v = validity(q, s, bounds_of(level, i, j));
            if (v.valid()) continue;
            // Valid, or no further outside a bound than at the level's start.
            glm::dvec2 start[4];
            corners(level, level.start_nodes, i, j, start);
            const Shape was = shape(start);
            if (!breaks_further(v, s, was, [&] { return thickness(start, was.area); })) continue;
            const std::string cell = "cell (" + std::to_string(i) + ", " + std::to_string(j) + ") ";
            if (!(s.quality2 > 0)) fail(cell + "is inverted, concave or degenerate");
            if (v.ill_shaped) fail(cell + "is less well shaped than allowed and than at the level's start");
            if (v.too_small || v.too_large) {
                fail(cell + "has area " + std::to_string(s.area) + ", further outside its bounds than at the level's start");
            }
            fail(cell + "is thinner than at rest and than at the level's start");
        }
    }
    for (const glm::dvec2& p : grid.nodes) {
        if (!(p.x >= grid.xs.front() && p.x <= grid.xs.back() && p.y >= grid.ys.front() && p.y <= grid.ys.back())) {
            fail("a node left the grid's rectangle");
        }
    }
    double total = 0;
    for (double e : level.energy) {
        if (!(e >= 0)) fail("negative energy " + std::to_string(e));
        total += e;
    }
    if (std::abs(total - level.initial_total) > 1e-9 * std::max(1.0, level.initial_total)) {
        fail("total energy changed from " + std::to_string(level.initial_total) + " to " + std::to_string(total));
    }
}

}  // namespace lmrefine::automaton_detail
