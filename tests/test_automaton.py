"""The cellular automaton (docs/method.md §4): the thesis' example, symmetry, and the
invariants after every step on random inputs."""

import numpy as np
import pytest

import lmrefine
from lmrefine import backoff

BORDERS = ("same", "border_rule", "extra_ring")


def densities(run, energy):
    e = run["energy"] if run["energy"].ndim == 2 else run["energy"].sum(axis=2)
    return e / run["cell_area"]


def test_thesis_example_centre_is_compressed_and_energies_equalize():
    energy = np.ones((3, 3), np.float32)
    energy[1, 1] = 0.0
    run = lmrefine.run_automaton(energy, max_steps=500, check_invariants=True)
    area = run["cell_area"]
    assert run["converged"]
    assert area[1, 1] < 0.6  # the empty centre is squeezed ...
    assert (np.delete(area.ravel(), 4) > 1.5 * area[1, 1]).all()  # ... the others take its room
    assert (area[[0, 0, 2, 2], [0, 2, 0, 2]] > 1.0).all()
    assert area.sum() == pytest.approx(9.0, abs=1e-4)
    assert run["energy"].sum() == pytest.approx(8.0, abs=1e-5)  # energy conserved
    assert run["energy"][1, 1] > 0.2  # energy flowed into the centre: its neighbours turn grey
    assert (run["energy"][[0, 1, 1, 2], [1, 0, 2, 1]] < 1.0).all()
    d = densities(run, energy)
    assert d.max() - d.min() < 0.02 * d.mean()  # energies (densities) equalized


def test_energy_flows_only_from_higher_to_lower():
    energy = np.ones((3, 3), np.float32)
    energy[1, 1] = 0.0
    run = lmrefine.run_automaton(energy, max_steps=1, coarse_to_fine=False)
    after = run["energy"]
    assert after[1, 1] > 0
    assert (np.delete(after.ravel(), 4) <= 1.0).all()
    # Corners touch the centre only diagonally: no direct flow in one step.
    assert after[0, 0] == pytest.approx(1.0)


@pytest.mark.parametrize("border", BORDERS)
def test_mirror_symmetric_input_gives_mirror_symmetric_grid(rng, border):
    half = rng.random((21, 8)).astype(np.float32) ** 3
    energy = np.concatenate([half, half[:, ::-1]], axis=1)
    mask = np.ones(energy.shape, bool)
    mask[3:6, 2:4] = False
    mask = mask & mask[:, ::-1]
    grid = lmrefine.run_automaton(energy, mask, border=border)["grid"]
    assert not np.allclose(grid, lmrefine.identity_grid(energy.shape), atol=1e-3)
    np.testing.assert_allclose(grid[:, ::-1, 0], 1 - grid[..., 0], atol=2e-5)
    np.testing.assert_allclose(grid[:, ::-1, 1], grid[..., 1], atol=2e-5)


def test_directional_mirror_swaps_left_and_right_channels(rng):
    half = rng.random((12, 6, 4)).astype(np.float32)
    mirrored = half[:, ::-1][..., [0, 3, 2, 1]]  # g (faces right) <-> a (faces left)
    energy = np.ascontiguousarray(np.concatenate([half, mirrored], axis=1))
    grid = lmrefine.run_automaton(energy, check_invariants=True)["grid"]
    np.testing.assert_allclose(grid[:, ::-1, 0], 1 - grid[..., 0], atol=2e-5)


def test_uniform_energy_is_the_identity():
    energy = np.full((37, 50), 0.3, np.float32)
    run = lmrefine.run_automaton(energy)
    np.testing.assert_array_equal(run["grid"], lmrefine.identity_grid((37, 50)))


@pytest.mark.parametrize("shape", [(1, 1), (2, 3), (5, 7), (16, 16), (33, 20), (64, 48), (17, 100)])
@pytest.mark.parametrize("border", BORDERS)
def test_invariants_hold_after_every_step_on_random_inputs(rng, shape, border):
    for trial in range(3):
        energy = (rng.random(shape) ** rng.uniform(0.5, 6)).astype(np.float32)
        mask = rng.random(shape) < rng.uniform(0.5, 1.0)
        # check_invariants raises on the first step that breaks one: cells
        # inverted or degenerate, negative energy, total energy changed,
        # nodes outside the lightmap.
        run = lmrefine.run_automaton(energy, mask, border=border, max_steps=24, check_invariants=True)
        assert (run["cell_area"] > 0).all()
        assert (run["grid"] >= 0).all() and (run["grid"] <= 1).all()
        if border == "extra_ring":  # the rescaled inner grid may leave texels unused
            assert 0.5 * shape[0] * shape[1] < run["cell_area"].sum() <= shape[0] * shape[1] * (1 + 1e-5)
        else:
            assert run["cell_area"].sum() == pytest.approx(shape[0] * shape[1], rel=1e-4)
        covered = energy[mask].sum()
        assert run["energy"][mask].sum() == pytest.approx(covered, rel=1e-5, abs=1e-6)
        assert (run["energy"] >= 0).all()
        # Uncovered cells shift but are not compressed, and covered cells
        # stay within [min_shrink, max_magnification] (extra_ring's final
        # rescale shrinks every cell alike).
        if border != "extra_ring":
            area = run["cell_area"]
            if (~mask).any():
                assert area[~mask].min() >= 1 - 1e-4
            if mask.any():
                assert 0.25 - 1e-4 <= area[mask].min() and area[mask].max() <= 8 + 1e-3


def test_rigid_cells_keep_their_width_and_height(rng):
    # Cells of rigid texels may shift, never get thinner: both edge pairs
    # stay at least one texel apart (parallelogram thickness, exact enough
    # for these near-parallelogram cells), and their area at least 1.
    shape = (48, 64)
    energy = (rng.random(shape) ** 4).astype(np.float32)
    rigid = np.zeros(shape, bool)
    rigid[:, 20:23] = True
    rigid[30:32, :] = True
    run = lmrefine.run_automaton(energy, rigid=rigid, check_invariants=True)
    grid = run["grid"] * np.array([shape[1], shape[0]])
    assert run["cell_area"][rigid].min() >= 1 - 1e-4
    assert run["cell_area"][~rigid].min() < 0.9  # the others do shrink
    left, right = grid[:-1, :-1], grid[:-1, 1:]
    width = np.linalg.norm(right - left, axis=-1)
    assert width[rigid].min() >= 1 - 1e-3


def test_chart_edges_facing_the_gutter_shrink_only_to_edge_shrink(rng):
    # A chart with a flat middle and the gutter around it: its edge texels
    # (covered, next to an uncovered texel) give room down to edge_shrink,
    # not to min_shrink; with edge_shrink 1 they are rigid as before.
    shape = (48, 48)
    mask = np.zeros(shape, bool)
    mask[4:44, 4:44] = True
    energy = np.full(shape, 0.05, np.float32)
    energy[20:28, 20:28] = 1.0
    edge = mask & ~np.pad(mask, 1)[:-2, 1:-1] | mask & ~np.pad(mask, 1)[2:, 1:-1]
    edge |= mask & ~np.pad(mask, 1)[1:-1, :-2] | mask & ~np.pad(mask, 1)[1:-1, 2:]
    soft = lmrefine.run_automaton(energy, mask, edge_shrink=0.8, check_invariants=True)["cell_area"]
    rigid = lmrefine.run_automaton(energy, mask, edge_shrink=1.0, check_invariants=True)["cell_area"]
    assert edge.sum() == 4 * 39
    assert soft[edge].min() >= 0.8 - 1e-4 and soft[edge].min() < 0.95
    assert rigid[edge].min() >= 1 - 1e-4
    assert soft[~mask].min() >= 1 - 1e-4  # the gutter stays rigid either way
    assert soft[mask & ~edge].min() < 0.5  # the flat middle shrinks further


def test_invariants_hold_for_the_directional_variant(rng):
    for shape in [(9, 13), (40, 40)]:
        energy = (rng.random(shape + (4,)) ** 4).astype(np.float32)
        mask = rng.random(shape) < 0.85
        run = lmrefine.run_automaton(energy, mask, check_invariants=True)
        assert run["energy"].shape == shape + (4,)
        assert run["energy"][mask].sum() == pytest.approx(energy[mask].sum(), rel=1e-5)


def test_high_energy_cells_grow_and_bounds_hold():
    energy = np.full((64, 64), 0.1, np.float32)
    energy[:, 30:34] = 1.0
    run = lmrefine.run_automaton(energy, max_magnification=4.0, min_shrink=0.5)
    area = run["cell_area"]
    assert area[:, 30:34].mean() > 2.0
    assert area[:, :20].mean() < 1.0
    assert area.max() <= 4.0 + 1e-4


@pytest.mark.parametrize("width", (1, 3))
def test_a_map_one_texel_wide_runs_like_its_transpose(width):
    """A level knows its block size: a map one texel wide has cell columns
    xs = {0, 1} at every level, which once made every coarse level look like
    the finest (the finest level's step budget, no coarse margin inside the
    bounds, moves measured in texels); a map 3 texels wide got the step
    budget of 3-texel blocks. Scalar energy has no preferred axis, so the map
    turned on its side (whose xs do show the block) must give the same
    levels and, transposed, the same cells. (Border 'same': with
    'border_rule' a one-cell-wide grid has only fixed nodes.)"""
    y = np.arange(64)
    column = np.repeat(np.where(y < 29, 0.05, 1.0).astype(np.float32)[:, None], width, axis=1)
    wide = lmrefine.run_automaton(column, max_steps=2, delta=1e-9, check_invariants=True)
    tall = lmrefine.run_automaton(np.ascontiguousarray(column.T), max_steps=2, delta=1e-9, check_invariants=True)
    assert [level["block"] for level in wide["levels"]] == [8, 4, 2, 1]
    # Levels of 8-texel blocks and coarser take 4 x max_steps.
    assert [level["steps"] for level in wide["levels"]] == [level["steps"] for level in tall["levels"]]
    assert wide["levels"][0]["steps"] > 2
    np.testing.assert_allclose(wide["cell_area"], tall["cell_area"].T, atol=1e-5)
    assert np.abs(wide["cell_area"] - 1).max() > 0.1  # and something happened


def test_coarse_to_fine_gets_further_than_one_level_in_fewer_steps():
    # A high-energy band must take room from the whole grid; one level moves
    # that room one cell per step, the pyramid moves it at every scale.
    energy = np.full((64, 64), 0.1, np.float32)
    energy[:, 4:8] = 1.0
    pyramid = lmrefine.run_automaton(energy)
    one = lmrefine.run_automaton(energy, coarse_to_fine=False, max_steps=4 * pyramid["steps"])
    assert len(pyramid["levels"]) == 4 and len(one["levels"]) == 1
    assert pyramid["cell_area"][:, 4:8].mean() > 1.3 * one["cell_area"][:, 4:8].mean()


@pytest.mark.parametrize("border", BORDERS)
def test_a_coarser_finest_level_steps_no_further_and_its_grid_holds_every_bound(border):
    # A band of light changes: the pyramid stepping down to 2-texel cells
    # only still widens it; the one-texel level is made from that grid and
    # fitted to its bounds, taking no step, so every cell holds them.
    energy = np.full((64, 48), 0.1, np.float32)
    energy[:, 20:26] = 1.0
    mask = np.ones(energy.shape, bool)
    mask[:, :2] = False
    fine = lmrefine.run_automaton(energy, mask, border=border)
    coarse = lmrefine.run_automaton(energy, mask, border=border, finest_block=2, check_invariants=True)
    assert [level["block"] for level in coarse["levels"]] == [level["block"] for level in fine["levels"]]
    assert coarse["levels"][-1]["steps"] == 0 < coarse["levels"][-2]["steps"]
    assert coarse["steps"] == fine["steps"] - fine["levels"][-1]["steps"]
    area = coarse["cell_area"]
    assert area[:, 20:26].mean() > 1.5 > 1 > area[:, 30:].mean()
    assert area[mask].min() >= 0.25 - 1e-5 and area[mask].max() <= 8 + 1e-5 and area[~mask].min() >= 1 - 1e-5
    assert not backoff.invalid_cells(coarse["grid"]).any()
    np.testing.assert_allclose(coarse["energy"], np.where(mask, energy, 0))  # the one-texel level's, unstepped
    # Coarser than the coarsest level: the coarsest level, then the fit.
    assert [level["block"] for level in lmrefine.run_automaton(energy, finest_block=1024)["levels"]] == [8, 1]


def test_progress_can_cancel():
    energy = np.random.default_rng(0).random((64, 64)).astype(np.float32)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.run_automaton(energy, progress=lambda fraction, stage: False)


def test_bad_arguments_raise_value_errors():
    energy = np.ones((4, 4), np.float32)
    with pytest.raises(ValueError, match=">= 0"):
        lmrefine.run_automaton(-energy)
    with pytest.raises(ValueError, match="float32"):
        lmrefine.run_automaton(energy.astype(np.float64))
    with pytest.raises(ValueError, match="mask"):
        lmrefine.run_automaton(energy, np.ones((3, 4), bool))
    with pytest.raises(ValueError, match="border"):
        lmrefine.run_automaton(energy, border="wrap")
    with pytest.raises(ValueError, match="edge_shrink"):
        lmrefine.run_automaton(np.ones((4, 4), np.float32), edge_shrink=0.0)
    with pytest.raises(ValueError, match="diffusion"):
        lmrefine.run_automaton(energy, diffusion=0.5)
    with pytest.raises(ValueError, match="channel"):
        lmrefine.run_automaton(np.ones((4, 4, 3), np.float32))
    for block in (0, 3, 2048):
        with pytest.raises(ValueError, match="finest_block"):
            lmrefine.run_automaton(energy, finest_block=block)


def test_result_does_not_depend_on_the_thread_count(rng, monkeypatch):
    energy = (rng.random((70, 90)) ** 3).astype(np.float32)
    mask = rng.random((70, 90)) < 0.9
    runs = []
    for threads in ("1", "2", "5"):
        monkeypatch.setenv("LMREFINE_THREADS", threads)
        runs.append(lmrefine.run_automaton(energy, mask))
    for other in runs[1:]:
        np.testing.assert_array_equal(runs[0]["grid"], other["grid"])
        np.testing.assert_array_equal(runs[0]["energy"], other["energy"])


def test_levels_report_the_fit_to_bounds_rounds():
    # Only the finest level is fitted; a flat map starts inside every bound.
    flat = lmrefine.run_automaton(np.ones((64, 64), np.float32))["levels"]
    assert [level["fit_rounds"] for level in flat] == [0] * len(flat)
    assert not any(level["fit_reset"] for level in flat)
    rng = np.random.default_rng(3)
    energy = ((rng.random((96, 96)) ** 6) * 0.96 + 0.04).astype(np.float32)
    levels = lmrefine.run_automaton(energy)["levels"]
    assert all(level["fit_rounds"] == 0 for level in levels[:-1])
    assert levels[-1]["block"] == 1 and levels[-1]["fit_rounds"] >= 1
    # A fit that blended its way inside: nothing sent back to rest (a cascading
    # fit is in test_rechart_route.py, on the bundled hillside).
    assert not any(level["fit_reset"] for level in levels)
