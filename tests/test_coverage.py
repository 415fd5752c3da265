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
