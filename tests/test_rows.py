"""lmrefine.rows.group_rows against np.unique(axis=0), its plain reference."""

import numpy as np
import pytest

from lmrefine.rows import group_rows


def reference(keys):
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return inverse.ravel(), counts


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.float64, np.float32])
@pytest.mark.parametrize("columns", [1, 2, 5])
def test_groups_equal_rows_as_np_unique_does(dtype, columns):
    rng = np.random.default_rng(columns)
    keys = rng.integers(-3, 4, (5000, columns)).astype(dtype)
    if np.issubdtype(dtype, np.floating):
        keys[::7, 0] = -0.0  # equal to 0.0
        keys[::11, -1] = np.inf
        keys[::13, -1] = -np.inf
    inverse, counts = group_rows(keys)
    expected_inverse, expected_counts = reference(keys)
    np.testing.assert_array_equal(inverse, expected_inverse)
    np.testing.assert_array_equal(counts, expected_counts)
    assert counts.sum() == len(keys)


def test_a_row_with_a_nan_is_a_group_of_its_own():
    keys = np.array([[0.0, 1.0], [np.nan, 1.0], [0.0, 1.0], [np.nan, 1.0], [2.0, np.nan]])
    inverse, counts = group_rows(keys)
    assert inverse[0] == inverse[2] and len(set(inverse[[1, 3, 4]])) == 3 and inverse[1] != inverse[0]
    np.testing.assert_array_equal(np.sort(counts), np.sort(reference(keys)[1]))


def test_empty_and_single_rows():
    inverse, counts = group_rows(np.zeros((0, 3)))
    assert inverse.shape == (0,) and counts.shape == (0,)
    inverse, counts = group_rows(np.array([[4, 2]]))
    np.testing.assert_array_equal(inverse, [0])
    np.testing.assert_array_equal(counts, [1])
