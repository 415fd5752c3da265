"""The native automaton step against its plain reference (tests/automaton_reference.py):
one step of the rule, guards off, on small random grids, scalar and
four-spring, every border mode.

Tolerance: the native code does the same IEEE operations in the same order
(its paired divisions are correctly rounded like numpy's), so on a build
that does not fuse a * b + c into one FMA (gcc with -std=c++17 does not;
x86-64 without -march has no FMA) the results are equal to the last bit. A
compiler that fuses may differ in the last bits of a product sum; 1e-12
relative (about 5000 units in the last place) allows that and nothing a
wrong rule would give (a wrong flux, push or limit changes values by 1e-3
or more)."""

import platform

import numpy as np
import pytest

from automaton_reference import level_energy, rest_nodes, rule_step

import lmrefine

_native = lmrefine._native

BORDERS = ("same", "border_rule", "extra_ring")
SIZES = ((6, 7), (12, 9), (9, 12), (7, 6))


def random_case(height, width, channels, border, seed, masked):
    rng = np.random.default_rng(seed)
    shape = (height, width) if channels == 1 else (height, width, 4)
    energy = rng.uniform(0.04, 1.0, shape).astype(np.float32)
    mask = rng.random((height, width)) > 0.2 if masked else None
    nodes = rest_nodes(height, width, border)
    rows, cols = nodes.shape[0] - 1, nodes.shape[1] - 1
    # Moved nodes keep every cell convex (a jitter below 1/4 cell); border
    # nodes only along the border they slide on.
    jitter = rng.uniform(-0.2, 0.2, nodes.shape)
    jitter[[0, -1], :, 1] = 0
    jitter[:, [0, -1], 0] = 0
    if border == "extra_ring":  # the ring's outer nodes stay where the ring was built
        jitter[[0, -1], :] = jitter[:, [0, -1]] = 0
    nodes = nodes + jitter
    options = dict(diffusion=float(rng.uniform(0.02, 0.25)), rate=float(rng.uniform(0.3, 1.0)), border=border)
    return energy, mask, nodes, options, (rows, cols)


@pytest.mark.parametrize("border", BORDERS)
@pytest.mark.parametrize("channels", (1, 4))
@pytest.mark.parametrize("masked", (False, True))
def test_native_rule_step_matches_reference(border, channels, masked):
    for seed, (height, width) in enumerate(SIZES):
        energy, mask, nodes, options, _ = random_case(height, width, channels, border, seed, masked)
        native = _native._automaton_rule_step(energy, mask, nodes, **options)
        ref_nodes, ref_energy, ref_difference = rule_step(energy, mask, nodes, **options)
        assert native["nodes"].shape == ref_nodes.shape
        assert native["energy"].shape == ref_energy.shape
        np.testing.assert_allclose(native["nodes"], ref_nodes, rtol=1e-12, atol=1e-12 * max(height, width))
        np.testing.assert_allclose(native["energy"], ref_energy, rtol=1e-12, atol=1e-15)
        assert native["difference"] == pytest.approx(ref_difference, rel=1e-12)
        # Not a comparison of two no-ops: the step moved nodes and energy.
        assert np.abs(ref_nodes - nodes).max() > 0.01
        assert np.abs(ref_energy.sum() - native["energy"].sum()) < 1e-9 * ref_energy.sum()
        assert np.abs(ref_energy - level_energy(energy, mask, border)).max() > 1e-4


def test_move_limit_and_slides_are_exercised():
    """The cases above reach the move limit (a quarter cell at rest) and
    slide border nodes: a reference that skipped either would differ."""
    energy, mask, nodes, options, _ = random_case(12, 9, 1, "same", 1, True)
    options["rate"] = 1.0
    ref_nodes, _, _ = rule_step(energy, mask, nodes, **options)
    native = _native._automaton_rule_step(energy, mask, nodes, **options)
    np.testing.assert_allclose(native["nodes"], ref_nodes, rtol=1e-12, atol=1e-11)
    move = np.linalg.norm(ref_nodes - nodes, axis=-1)
    assert move.max() > 0.1
    border_moves = ref_nodes[0, 1:-1, 0] - nodes[0, 1:-1, 0]
    assert np.abs(border_moves).max() > 0.01  # top border nodes slide in x ...
    np.testing.assert_array_equal(ref_nodes[0, :, 1], nodes[0, :, 1])  # ... and stay on the border


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                    reason="other CPUs have FMA, which compilers may fuse into (tolerance above)")
def test_native_step_is_bit_identical_to_reference_on_x86_64():
    """x86-64 without -march has no FMA instruction, so nothing is fused and
    the native step equals the reference to the last bit."""
    for border in BORDERS:
        for channels in (1, 4):
            energy, mask, nodes, options, _ = random_case(9, 12, channels, border, 7, True)
            native = _native._automaton_rule_step(energy, mask, nodes, **options)
            ref_nodes, ref_energy, ref_difference = rule_step(energy, mask, nodes, **options)
            np.testing.assert_array_equal(native["nodes"], ref_nodes)
            np.testing.assert_array_equal(native["energy"], ref_energy)
            assert native["difference"] == ref_difference
