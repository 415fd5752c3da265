"""Grouping equal rows of a key table (edges by their end points, vertices
by their chart and position): np.unique(keys, axis=0)'s groups from one
lexicographic sort of the columns, about twice as fast, which the re-chart
route pays for several times a call."""

import numpy as np


def group_rows(keys):
    """(inverse (N,), counts (G,)) for the rows of `keys` (N, K): each row's
    group among the distinct rows, numbered in lexicographic order, and each
    group's size, as np.unique(keys, axis=0, return_inverse=True,
    return_counts=True) gives them (a row holding a NaN is a group of its own,
    as there, though the two may number such groups differently)."""
    keys = np.asarray(keys)
    count = len(keys)
    if count == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    order = np.lexsort(keys.reshape(count, -1).T[::-1])
    ordered = keys[order]
    starts = np.empty(count, bool)
    starts[0] = True
    np.any(ordered[1:] != ordered[:-1], axis=1, out=starts[1:])
    inverse = np.empty(count, np.intp)
    inverse[order] = np.cumsum(starts) - 1
    counts = np.diff(np.append(np.flatnonzero(starts), count))
    return inverse, counts
