import numpy as np
import pytest

import lmrefine


def quad(u0, v0, u1, v1):
    uvs = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], np.float32)
    return uvs, np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def test_texel_aligned_square_covers_exactly_its_texels():
    uvs, tris = quad(0.25, 0.25, 0.75, 0.5)  # u: cols 2..5, v 0.25..0.5 -> rows 4..5 (row 0 = top)
    mask = lmrefine.coverage_mask(uvs, tris, 8)
    assert mask.dtype == np.bool_ and mask.shape == (8, 8)
    expected = np.zeros((8, 8), bool)
    expected[4:6, 2:6] = True
    assert np.array_equal(mask, expected)


def test_conservative_thin_triangle_is_not_lost():
    uvs = np.array([[0.05, 0.5], [0.95, 0.5], [0.95, 0.5001]], np.float32)
    mask = lmrefine.coverage_mask(uvs, np.array([[0, 1, 2]]), 16)
    assert mask.sum() >= 14  # a sliver across the map still touches a texel per column


def test_rectangular_resolution_and_int64_indices():
    uvs, tris = quad(0.0, 0.0, 1.0, 1.0)
    mask = lmrefine.coverage_mask(uvs.astype(np.float64), tris.astype(np.int64), (4, 6))
    assert mask.shape == (4, 6) and mask.all()


@pytest.mark.parametrize("uvs,tris,res,match", [
    (np.zeros((3, 3), np.float32), np.array([[0, 1, 2]]), 4, r"\(N, 2\)"),
    (np.zeros((3, 2), np.float32), np.array([[0, 1, 3]]), 4, "refers to UV 3"),
    (np.zeros((3, 2), np.float32), np.array([[0, 1, -1]]), 4, "-1"),
    (np.array([[0, 0], [1, 0], [np.nan, 1]], np.float32), np.array([[0, 1, 2]]), 4, "NaN"),
    (np.zeros((3, 2), np.float32), np.array([[0, 1, 2]]), 0, "positive"),
    (np.zeros((3, 2), np.float32), np.array([[0.0, 1, 2]]), 4, "integers"),
])
def test_bad_layouts_raise(uvs, tris, res, match):
    with pytest.raises(ValueError, match=match):
        lmrefine.coverage_mask(uvs, tris, res)


def test_find_charts_joins_per_corner_copies_and_separates_islands():
    # Two quads, each stored with per-corner UVs (no shared indices), apart.
    a_uvs, a_tris = quad(0.1, 0.1, 0.4, 0.4)
    b_uvs, b_tris = quad(0.6, 0.6, 0.9, 0.9)
    uvs = np.concatenate([a_uvs[[0, 1, 2]], a_uvs[[0, 2, 3]], b_uvs[[0, 1, 2]], b_uvs[[0, 2, 3]]])
    tris = np.arange(12, dtype=np.int32).reshape(4, 3)
    charts = lmrefine.find_charts(uvs, tris)
    assert charts.dtype == np.int32
    assert charts.tolist() == [0, 0, 1, 1]



def test_find_charts_joins_corners_within_the_tolerance_only():
    # Two per-corner quads whose shared edge is off by 3e-6 (Blender's
    # layouts are not bit-exact), and a third quad 1e-3 away.
    a_uvs, _ = quad(0.1, 0.1, 0.4, 0.4)
    b_uvs, _ = quad(0.4, 0.1, 0.7, 0.4)
    c_uvs, _ = quad(0.701, 0.1, 0.9, 0.4)
    b_uvs = b_uvs + np.float32(3e-6)
    uvs = np.concatenate([q[[0, 1, 2, 0, 2, 3]] for q in (a_uvs, b_uvs, c_uvs)])
    tris = np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)
    assert lmrefine.find_charts(uvs, tris).tolist() == [0, 0, 1, 1, 2, 2]
    assert lmrefine.find_charts(uvs, tris, tolerance=1e-5).tolist() == [0, 0, 0, 0, 1, 1]
    assert lmrefine.find_charts(uvs, tris, tolerance=2e-3).tolist() == [0, 0, 0, 0, 0, 0]
    with pytest.raises(ValueError, match="tolerance"):
        lmrefine.find_charts(uvs, tris, tolerance=-1.0)


def _charts_by_every_pair(uvs, tris, tolerance):
    """find_charts' rule, pair by pair: triangles share a UV index, or hold
    corners closer than the tolerance (in doubles from the float32 UVs) or
    bit-identical; charts numbered in order of first appearance."""
    uvs = np.asarray(uvs, np.float32)
    parent = list(range(len(uvs)))

    def find(x):
        while parent[x] != x:
            x = parent[x]
        return x

    def join(a, b):
        a, b = find(a), find(b)
        parent[max(a, b)] = min(a, b)

    used = np.unique(tris)
    wide = uvs.astype(np.float64)
    bits = uvs.view(np.uint32)
    for k, i in enumerate(used):
        others = used[k + 1:]
        d = wide[others] - wide[i]
        close = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] < tolerance * tolerance) | ((d == 0).all(axis=1))
        close |= (bits[others] == bits[i]).all(axis=1)
        for j in others[close]:
            join(int(i), int(j))
    for a, b, c in tris:
        join(int(a), int(b))
        join(int(a), int(c))
    ids = {}
    return [ids.setdefault(find(int(t[0])), len(ids)) for t in tris]


@pytest.mark.parametrize("seed", range(6))
def test_find_charts_joins_exactly_the_corners_closer_than_the_tolerance(seed):
    # Crowds of corners (thousands at one point, or within a fraction of the
    # tolerance), pairs exactly at the tolerance on a lattice, and spread
    # corners: the charts of the every-pair rule.
    rng = np.random.default_rng(seed)
    tolerance = 10.0 ** rng.uniform(-6, -2)
    centres = rng.random((8, 2))
    uvs = np.concatenate([
        np.repeat(centres[:2], 60, axis=0),                                # bit-identical crowds
        centres[2:4].repeat(60, axis=0) + rng.normal(0, tolerance / 8, (120, 2)),  # crowds within the tolerance
        centres[4] + np.round(rng.random((80, 2)) * 6) * tolerance,        # a lattice at the tolerance
        centres[5:].repeat(40, axis=0) + rng.normal(0, tolerance, (120, 2)),
        rng.random((80, 2)),
    ]).astype(np.float32)
    tris = rng.integers(0, len(uvs), (150, 3)).astype(np.int32)
    for scale in (0.5, 1.0, 2.0):
        assert lmrefine.find_charts(uvs, tris, tolerance * scale).tolist() == \
            _charts_by_every_pair(uvs, tris, tolerance * scale)


@pytest.mark.parametrize("scale, tolerance", [
    (1.0, 1e-200),  # the tolerance's square underflows
    (1e12, 1e-5),   # coordinates beyond 2^30 cells
    (1e12, 5e4),
    (1e-30, 1e-31),
])
def test_find_charts_at_extreme_scales_keeps_the_rule(scale, tolerance):
    rng = np.random.default_rng(7)
    uvs = (np.repeat(rng.random((40, 2)), 3, axis=0) * scale).astype(np.float32)
    uvs[::7] += (rng.normal(0, tolerance, (len(uvs[::7]), 2))).astype(np.float32)
    tris = rng.integers(0, len(uvs), (60, 3)).astype(np.int32)
    assert lmrefine.find_charts(uvs, tris, tolerance).tolist() == _charts_by_every_pair(uvs, tris, tolerance)


@pytest.mark.parametrize("spread", [0.0, 1e-7, 3e-6])
def test_find_charts_joins_corners_crowded_at_one_point(spread):
    # All-zero UVs (or corners within a fraction of the tolerance): every
    # pair was tested, 11 s for 20,000 triangles (found by a crash hunt; its speed: bench/bench_charts.py).
    count = 60000
    uvs = (0.5 + np.random.default_rng(1).normal(0.0, spread, (3 * count, 2))).astype(np.float32)
    tris = np.arange(3 * count, dtype=np.int32).reshape(-1, 3)
    charts = lmrefine.find_charts(uvs, tris, tolerance=1e-5)
    assert charts.tolist() == [0] * count


def _overlaps_texel(p, col, row, touch=1e-7):
    """The conservative rasterization's rule, texel by texel: the separating
    axes of a triangle (pixel space) and the unit square at (col, row)."""
    corners = [(col, row), (col + 1, row), (col, row + 1), (col + 1, row + 1)]
    for e in range(3):
        (ax, ay), (bx, by) = p[e], p[(e + 1) % 3]
        axis = (ay - by, bx - ax)
        scale = float(np.hypot(*axis))
        if scale == 0.0:
            return False
        t = [axis[0] * x + axis[1] * y for x, y in p]
        s = [axis[0] * x + axis[1] * y for x, y in corners]
        if max(t) <= min(s) + touch * scale or max(s) <= min(t) + touch * scale:
            return False
    return True


def test_coverage_is_exactly_the_per_texel_separating_axis_test(rng):
    # The rasterizer finds each row's span by walking to where the test
    # flips; it must accept exactly the texels the per-texel test accepts,
    # including triangles on texel corners, slivers and ones leaving the map.
    height, width = 9, 13
    cases = []
    for k in range(120):
        uv = rng.uniform(-0.2, 1.2, (3, 2))
        if k % 4 == 1:
            uv = np.round(uv * [width, height]) / [width, height]  # corners on texel corners
        if k % 4 == 2:
            uv[1:] = uv[0] + (uv[1:] - uv[0]) * [1e-3, 1e-6]  # a sliver
        cases.append(uv.astype(np.float32))
    for uv in cases:
        mask = lmrefine.coverage_mask(uv, np.array([[0, 1, 2]]), (height, width))
        p = [(float(u) * width, (1.0 - float(v)) * height) for u, v in uv]
        xs, ys = [x for x, _ in p], [y for _, y in p]
        expected = np.zeros((height, width), bool)
        for row in range(max(0, int(np.floor(min(ys)))), min(height - 1, int(np.ceil(max(ys)))) + 1):
            for col in range(max(0, int(np.floor(min(xs)))), min(width - 1, int(np.ceil(max(xs)))) + 1):
                expected[row, col] = _overlaps_texel(p, col, row)
        np.testing.assert_array_equal(mask, expected, err_msg=f"triangle {uv.tolist()}")
    assert sum(lmrefine.coverage_mask(uv, np.array([[0, 1, 2]]), (height, width)).sum() for uv in cases) > 100
