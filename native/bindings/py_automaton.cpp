#include <pybind11/pybind11.h>

#include <string>

#include "grid_array.h"
#include "lmrefine/automaton/automaton.h"
#include "lmrefine/core/error.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

using ByteMap = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>;

// The energy map (float32 (H, W) or (H, W, 4)) as AutomatonInput; `energy`
// keeps the viewed memory alive.
AutomatonInput energy_input(const py::handle& energy_in, py_util::FloatArray& energy) {
    energy = py_util::require_float32(energy_in, "energy", {2, 3});
    AutomatonInput input;
    input.height = int(energy.shape(0));
    input.width = int(energy.shape(1));
    input.channels = energy.ndim() == 3 ? int(energy.shape(2)) : 1;
    input.energy = energy.data();
    return input;
}

// An optional (H, W) boolean map matching the energy map (mask, rigid), or
// null; `map` keeps the viewed memory alive.
const uint8_t* matching_map(const py::handle& in, const char* name, const AutomatonInput& input, ByteMap& map) {
    if (in.is_none()) return nullptr;
    map = py_util::contiguous<uint8_t>(in, name);
    if (map.ndim() != 2 || map.shape(0) != input.height || map.shape(1) != input.width) {
        throw py::value_error(std::string(name) + " must be a (H, W) boolean array matching energy's " +
                              std::to_string(input.height) + "x" + std::to_string(input.width));
    }
    return map.data();
}

// Numbers and names arrive as Python objects and go through py_util's
// readers, so a wrong type is a TypeError naming the argument.
py::dict run(const py::handle& energy_in, const py::handle& mask_in, const py::handle& rigid_in,
             const py::handle& diffusion, const py::handle& rate, const py::handle& delta, const py::handle& max_steps,
             const py::handle& min_shrink, const py::handle& max_magnification, const py::handle& edge_shrink,
             const py::handle& border, const py::handle& coarse_to_fine, const py::handle& passes,
             const py::handle& finest_block, const py::handle& check_invariants,
             py::object progress_callback) {
    py_util::FloatArray energy;
    AutomatonInput input = energy_input(energy_in, energy);
    ByteMap mask, rigid;
    input.mask = matching_map(mask_in, "mask", input, mask);
    input.rigid = matching_map(rigid_in, "rigid", input, rigid);
    AutomatonOptions options;
    options.diffusion = py_util::real_param(diffusion, "diffusion");
    options.rate = py_util::real_param(rate, "rate");
    options.delta = py_util::real_param(delta, "delta");
    options.max_steps = int(py_util::int_param(max_steps, "max_steps", 0, 10000));
    options.min_area = py_util::real_param(min_shrink, "min_shrink");
    options.max_area = py_util::real_param(max_magnification, "max_magnification");
    options.edge_shrink = py_util::real_param(edge_shrink, "edge_shrink");
    options.border = parse_border_mode(py_util::string_param(border, "border"));
    options.coarse_to_fine = py_util::bool_param(coarse_to_fine, "coarse_to_fine");
    options.passes = int(py_util::int_param(passes, "passes", 1, 64));
    options.finest_block = int(py_util::int_param(finest_block, "finest_block", 1, 1024));
    options.check_invariants = py_util::bool_param(check_invariants, "check_invariants");

    py_util::PythonProgress progress(std::move(progress_callback));
    AutomatonResult result = progress.run([&](Progress& p) { return run_automaton(input, options, &p); });

    py::list levels;
    for (const LevelStats& s : result.levels) {
        py::dict level;
        level["block"] = s.block;
        level["rows"] = s.rows;
        level["cols"] = s.cols;
        level["steps"] = s.steps;
        level["max_difference"] = s.max_difference;
        level["converged"] = s.converged;
        level["settled"] = s.settled;
        level["seconds"] = s.seconds;
        level["fit_rounds"] = s.fit_rounds;
        level["fit_reset"] = s.fit_reset;
        levels.append(level);
    }
    py::dict out;
    out["cell_area"] = py_util::to_numpy(cell_areas(result.grid), {input.height, input.width});
    out["grid"] = py_util::grid_to_numpy(result.grid, input.width, input.height);
    std::vector<py::ssize_t> shape{input.height, input.width};
    if (input.channels > 1) shape.push_back(input.channels);
    out["energy"] = py_util::to_numpy(std::move(result.energy), shape);
    out["steps"] = result.steps;
    out["converged"] = result.converged;
    out["levels"] = levels;
    return out;
}

// Test hook (tests/test_automaton_reference.py): one step of the rule with
// the guards off, from given nodes; not part of the public API.
py::dict rule_step(const py::handle& energy_in, const py::handle& mask_in, const py::handle& nodes_in,
                   const py::handle& diffusion, const py::handle& rate, const py::handle& border) {
    py_util::FloatArray energy;
    AutomatonInput input = energy_input(energy_in, energy);
    ByteMap mask;
    input.mask = matching_map(mask_in, "mask", input, mask);
    AutomatonOptions options;
    options.diffusion = py_util::real_param(diffusion, "diffusion");
    options.rate = py_util::real_param(rate, "rate");
    options.border = parse_border_mode(py_util::string_param(border, "border"));
    const auto nodes_array = py_util::contiguous<double>(nodes_in, "nodes");
    if (nodes_array.ndim() != 3 || nodes_array.shape(2) != 2) {
        throw py::value_error("nodes must be a (rows + 1, cols + 1, 2) float64 array");
    }
    std::vector<glm::dvec2> nodes(size_t(nodes_array.shape(0) * nodes_array.shape(1)));
    for (size_t n = 0; n < nodes.size(); ++n) nodes[n] = {nodes_array.data()[2 * n], nodes_array.data()[2 * n + 1]};
    const RuleStep result = automaton_rule_step(input, options, nodes);
    std::vector<double> flat(2 * result.nodes.size());
    for (size_t n = 0; n < result.nodes.size(); ++n) {
        flat[2 * n] = result.nodes[n].x;
        flat[2 * n + 1] = result.nodes[n].y;
    }
    const py::ssize_t rows = nodes_array.shape(0) - 1, cols = nodes_array.shape(1) - 1;
    std::vector<double> energy_out = result.energy;
    std::vector<py::ssize_t> energy_shape{rows, cols};
    if (input.channels > 1) energy_shape.push_back(input.channels);
    py::dict out;
    out["nodes"] = py_util::to_numpy(std::move(flat), {rows + 1, cols + 1, 2});
    out["energy"] = py_util::to_numpy(std::move(energy_out), energy_shape);
    out["difference"] = result.difference;
    return out;
}

}  // namespace

void bind_automaton(py::module_& m) {
    m.def("_automaton_rule_step", &rule_step, py::arg("energy"), py::arg("mask"), py::arg("nodes"), py::kw_only(),
          py::arg("diffusion"), py::arg("rate"), py::arg("border"),
          "Test hook, not public API: one step of the automaton's rule with the guards off, from `nodes` "
          "(float64 (rows + 1, cols + 1, 2), pixel space, ring included with border='extra_ring'). Returns "
          "dict(nodes, energy, difference) as the rule proposes them (tests/test_automaton_reference.py).");
    const AutomatonOptions d;
    m.def("run_automaton", &run, py::arg("energy"), py::arg("mask") = py::none(), py::kw_only(),
          py::arg("rigid") = py::none(),
          py::arg("diffusion") = py::float_(d.diffusion), py::arg("rate") = py::float_(d.rate),
          py::arg("delta") = py::float_(d.delta), py::arg("max_steps") = py::int_(d.max_steps),
          py::arg("min_shrink") = py::float_(d.min_area), py::arg("max_magnification") = py::float_(d.max_area),
          py::arg("edge_shrink") = py::float_(d.edge_shrink), py::arg("border") = py::str("same"),
          py::arg("coarse_to_fine") = py::bool_(d.coarse_to_fine), py::arg("passes") = py::int_(d.passes),
          py::arg("finest_block") = py::int_(d.finest_block),
          py::arg("check_invariants") = py::bool_(false), py::arg("progress") = py::none(),
          R"doc(Run the cellular automaton on an energy map (see docs/refiner.md).

Args:
    energy (numpy.ndarray): float32 (H, W) energies >= 0, or (H, W, 4) for
        the directional variant (r facing down, g right, b up, a left).
    mask (numpy.ndarray | None): (H, W) bool, True where a chart covers the
        texel. Uncovered cells hold no energy and are never compressed.
    rigid (numpy.ndarray | None): (H, W) bool, more texels whose cells may
        shift but never shrink below their original area, width or height
        (e.g. gutter_texels(uvs, triangles, resolution)); uncovered texels
        always are.
    diffusion (float): energy moved per step per unit density difference, <= 0.25.
    rate (float): node move per step, in cell sizes, at full contrast.
    delta (float): stop when every neighbour density difference, relative
        to the mean density, is below delta.
    max_steps (int): step cap per pyramid level.
    min_shrink, max_magnification (float): bounds on a covered cell's area
        relative to its original area.
    edge_shrink (float): in (0, 1]; a chart's edge texels facing the gutter
        (covered, next to an uncovered texel, not rigid) shrink to at most
        this times their area, keeping no width or height; 1 = rigid.
    border (str): 'same', 'border_rule' or 'extra_ring'.
    coarse_to_fine (bool): run on a pyramid (False: one level, for comparison).
    passes (int): extra passes rerun the finest level with fresh energies.
    finest_block (int): texels per cell side of the finest level that
        steps, a power of two; above 1 the one-texel level is only made
        from its grid and fitted to the bounds (no step).
    check_invariants (bool): verify every invariant after every step and
        raise RuntimeError naming the first that fails (for tests).
    progress (callable | None): progress(fraction, stage); False cancels.

Returns:
    dict: grid (H + 1, W + 1, 2) float32 node positions in UV space,
    cell_area (H, W) float32 in texels, energy (final energies, the input's
    shape), steps (int), converged (bool), levels (list of per-level dicts:
    block, rows, cols, steps, max_difference, converged, settled, seconds, fit_rounds, fit_reset (the
    finest level's fit sent nodes back to rest: it cascaded); coarsest first).
)doc");
}

}  // namespace lmrefine::bindings
