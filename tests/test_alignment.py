"""Light steps on texel boundaries (python/lmrefine/alignment.py) and the
refinement's refusal to move a layout whose steps sit there."""

import numpy as np
import pytest

import lmrefine
from lmrefine import alignment
from lmrefine.allocation import texel_luminance
from layouts import grid_chart

R = 64


def _facets(n, lo, hi, resolution=R, seed=0):
    """A chart of n x n quads over [lo, hi] and a lightmap whose light is
    constant on each quad (a flat-shaded surface): steps at every quad edge."""
    uvs, tris = grid_chart(n, (lo, lo), (hi, hi))
    rng = np.random.default_rng(seed)
    level = rng.uniform(0.1, 1.0, (n, n))
    v, u = (1 - (np.arange(resolution) + 0.5) / resolution), (np.arange(resolution) + 0.5) / resolution
    column = np.clip(((u - lo) / (hi - lo) * n).astype(int), 0, n - 1)
    row = np.clip(((v - lo) / (hi - lo) * n).astype(int), 0, n - 1)
    lightmap = np.repeat(level[row[:, None], column[None, :]][..., None], 3, axis=2).astype(np.float32)
    return uvs, tris, lightmap


def _share_reference(lightmap, uvs, triangles, mask):
    """The rule, plainly: mark every texel boundary an axis-parallel edge on
    a grid line covers; a boundary's sharp step is its luminance step (0
    unless both texels are covered) less the larger of the steps at the
    boundaries before and after it across the same line, not below 0; the
    share is the sharp steps on marked boundaries over all sharp steps."""
    height, width = mask.shape
    lum = texel_luminance(lightmap).astype(np.float64)
    rows, columns = set(), set()  # (line, texel along it)
    for t in np.asarray(triangles):
        for k in range(3):
            (u0, v0), (u1, v1) = uvs[t[k]], uvs[t[(k + 1) % 3]]
            x0, y0, x1, y1 = u0 * width, (1 - v0) * height, u1 * width, (1 - v1) * height
            if abs(y0 - y1) < 1e-3 and abs(y0 - round(y0)) < 1e-3:
                for c in range(int(np.floor(min(x0, x1) + 1e-3)), int(np.ceil(max(x0, x1) - 1e-3))):
                    rows.add((int(round(y0)), c))
            if abs(x0 - x1) < 1e-3 and abs(x0 - round(x0)) < 1e-3:
                for r in range(int(np.floor(min(y0, y1) + 1e-3)), int(np.ceil(max(y0, y1) - 1e-3))):
                    columns.add((int(round(x0)), r))
    def step_down(i, j):  # across the boundary above texel row i (i in 1..height-1), column j
        if 1 <= i < height and mask[i, j] and mask[i - 1, j]:
            return abs(lum[i, j] - lum[i - 1, j])
        return 0.0

    def step_right(i, j):  # across the boundary left of texel column j (j in 1..width-1), row i
        if 1 <= j < width and mask[i, j] and mask[i, j - 1]:
            return abs(lum[i, j] - lum[i, j - 1])
        return 0.0

    total = aligned = 0.0
    for i in range(height):
        for j in range(width):
            sharp = max(step_down(i, j) - max(step_down(i - 1, j), step_down(i + 1, j)), 0.0)
            total += sharp
            aligned += sharp if (i, j) in rows else 0.0
            sharp = max(step_right(i, j) - max(step_right(i, j - 1), step_right(i, j + 1)), 0.0)
            total += sharp
            aligned += sharp if (j, i) in columns else 0.0
    return aligned / total if total > 0 else 0.0


def test_the_share_matches_the_plain_rule():
    rng = np.random.default_rng(4)
    cases = [_facets(8, 8 / R, 56 / R), _facets(6, 5.3 / R, 57.1 / R), _facets(4, 0.0, 1.0)]
    for _ in range(4):  # random triangles, some with ends on grid lines
        uvs = np.round(rng.uniform(0, 1, (30, 2)) * R * rng.choice([1, 4], (30, 1))) / (R * 4)
        uvs = np.clip(uvs, 0, 1).astype(np.float32)
        tris = np.arange(30).reshape(10, 3)
        cases.append((uvs, tris, rng.uniform(0, 1, (R, R, 3)).astype(np.float32)))
    for uvs, tris, lightmap in cases:
        mask = lmrefine.coverage_mask(uvs, tris, R)
        expected = _share_reference(lightmap, uvs, tris, mask)
        # The kernel takes its steps in float32, the reference in float64.
        assert alignment.aligned_step_share(lightmap, uvs, tris, mask) == pytest.approx(expected, rel=1e-5, abs=1e-9)


def test_facets_on_texel_boundaries_are_left_where_they_are():
    # 8 x 8 facets of 6 texels each, their edges on texel boundaries: every step is on one.
    uvs, tris, lightmap = _facets(8, 8 / R, 56 / R)
    result = lmrefine.refine_uvs(lightmap, uvs, tris, R)
    assert result.report["aligned_steps"] > 0.95
    assert result.report["moved"] is False and result.report["limited_by"] == ["aligned_steps"]
    np.testing.assert_array_equal(result.uvs, uvs)
    assert any("lie on texel boundaries" in note for note in result.report["notes"])
    # A bake of few samples: noise steps everywhere, as large as a third of the facets' mean step; the
    # sharp steps still stand out on the facet edges.
    noisy = (lightmap + np.random.default_rng(1).normal(0, 0.1, lightmap.shape)).astype(np.float32)
    assert lmrefine.refine_uvs(noisy, uvs, tris, R).report["limited_by"] == ["aligned_steps"]
    # The same facets a third of a texel off the grid: every step inside a texel, the refinement runs.
    shifted = (uvs + np.float32(1 / (3 * R))).astype(np.float32)
    _, _, lightmap = _facets(8, 8 / R + 1 / (3 * R), 56 / R + 1 / (3 * R))
    moved = lmrefine.refine_uvs(lightmap, shifted, tris, R)
    assert moved.report["aligned_steps"] < 0.05 and moved.report["moved"] is True
    assert "aligned_steps" not in moved.report["limited_by"]


def test_without_a_lightmap_the_share_is_not_measured():
    uvs, tris, lightmap = _facets(8, 8 / R, 56 / R)
    mask = lmrefine.coverage_mask(uvs, tris, R)
    gradient = lmrefine.gradient_map(lightmap, mask)
    result = lmrefine.refine_uvs(None, uvs, tris, R, gradient=gradient)
    assert result.report["aligned_steps"] is None and "aligned_steps" not in result.report["limited_by"]
    assert lmrefine.refine_uvs(lightmap, uvs, tris, R, strength=0).report["aligned_steps"] is None
