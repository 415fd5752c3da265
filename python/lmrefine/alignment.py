"""Light steps on texel boundaries: a layout the refinement would make worse.

A flat-shaded mesh lights each face alike, so its light steps at the faces'
edges. When a layout puts those edges on texel boundaries (the UV maps
Blender gives its sphere, cylinder and cube, at a power-of-two resolution:
u = i/32, v = j/16), no texel straddles a step: the bake is exact per texel
and only the lookup blends across an edge, within half a texel of it. Any
move of the vertices takes the steps off the boundaries, and the texels they
then cross read a mix of two faces; a refinement that moves texels by tens
of percent loses more there than it gains (docs/evaluation.md, "A user's
first try, measured"). The usual lightmap layouts (Smart UV Project,
Lightmap Pack, packed atlases) put no edge on a boundary by design.

`aligned_step_share` measures how much of a bake's sharp light steps lie
on a boundary that a triangle edge of the layout runs along. A step counts
by how much it exceeds the larger of the steps one texel before and after
it across the same line: a step that sits between two texels stands out,
noise (a bake of few samples) mostly does not, nor does an edge inside a
texel (two half steps). 0.000-0.006 on every bundled scene's layouts;
0.26-0.92 on the sphere, cylinder and cube maps above, from 1 to 16
samples per texel; 0.18-0.34 where a grid floor's shadow edges fall on its
lattice-aligned grid lines by chance.
"""

import numpy as np

from .allocation import texel_luminance

# A triangle edge runs along a texel boundary when both its ends lie on that
# grid line to within this many texels.
_ON_LINE = 1e-3
# At least this share of the first lightmap's sharp light steps on texel
# boundaries the layout's edges run along: the source layout is returned as
# it is (refine_uvs) and not tessellated (the add-on). The bundled scenes'
# layouts measure 0.000-0.006; a grid floor on a lattice-aligned map whose
# shadow edges fall on its grid lines by chance 0.18-0.34 (the tests' small
# scenes); the flat-shaded sphere, cube and cylinder maps that lose when
# moved 0.63-0.92, 0.45-0.88 and 0.26-0.74 from 1 to 16 samples per texel
# (0.74 and more at the add-on's default 16).
ALIGNED_STEP_SHARE = 0.5


def _marked(lines, lo, hi, count, length):
    """(count, length) bool: on grid line `lines[k]`, the texel spans
    [lo[k], hi[k]) marked (a difference array, then a running sum)."""
    lo = np.clip(np.floor(lo + _ON_LINE).astype(np.int64), 0, length)
    hi = np.clip(np.ceil(hi - _ON_LINE).astype(np.int64), 0, length)
    keep = (lines >= 0) & (lines < count) & (hi > lo)
    marked = np.zeros((count, length), bool)
    if not keep.any():
        return marked
    used = np.unique(lines[keep])  # only the grid lines an edge runs along
    row = np.searchsorted(used, lines[keep])
    steps = np.zeros((len(used), length + 1), np.int32)
    np.add.at(steps, (row, lo[keep]), 1)
    np.add.at(steps, (row, hi[keep]), -1)
    marked[used] = np.cumsum(steps, axis=1)[:, :length] > 0
    return marked


def _sharp(steps):
    """Each step (along axis 0) less the larger of its neighbours along that
    axis (0 past the ends), not below 0."""
    beside = np.zeros_like(steps)
    beside[1:] = steps[:-1]
    np.maximum(beside[:-1], steps[1:], out=beside[:-1])
    return np.maximum(steps - beside, 0.0)


def aligned_step_share(lightmap, uvs, triangles, mask):
    """The share (0..1) of the sharp luminance steps between neighbouring
    covered texels of `lightmap` (baked on uvs, triangles; `mask` its
    coverage) that lie on texel boundaries a triangle edge of the layout
    runs along."""
    height, width = mask.shape
    corners = np.asarray(uvs, np.float64)[np.asarray(triangles, np.int64)]  # (T, 3, 2)
    start, end = corners.reshape(-1, 2), np.roll(corners, -1, axis=1).reshape(-1, 2)
    x0, y0 = start[:, 0] * width, (1.0 - start[:, 1]) * height
    x1, y1 = end[:, 0] * width, (1.0 - end[:, 1]) * height
    # Horizontal edges on the line between texel rows r - 1 and r (line r).
    on_row = (np.abs(y0 - y1) < _ON_LINE) & (np.abs(y0 - np.round(y0)) < _ON_LINE)
    on_column = (np.abs(x0 - x1) < _ON_LINE) & (np.abs(x0 - np.round(x0)) < _ON_LINE)
    if not (on_row.any() or on_column.any()):
        return 0.0  # no edge runs along a texel boundary: no step can lie on one
    rows = _marked(np.round(y0[on_row]).astype(np.int64), np.minimum(x0, x1)[on_row],
                   np.maximum(x0, x1)[on_row], height + 1, width)
    columns = _marked(np.round(x0[on_column]).astype(np.int64), np.minimum(y0, y1)[on_column],
                      np.maximum(y0, y1)[on_column], width + 1, height).T  # (height, width + 1)
    lum = texel_luminance(lightmap)
    across_rows = _sharp(np.abs(lum[1:] - lum[:-1]) * (mask[1:] & mask[:-1]))
    across_columns = _sharp((np.abs(lum[:, 1:] - lum[:, :-1]) * (mask[:, 1:] & mask[:, :-1])).T).T
    total = across_rows.sum(dtype=np.float64) + across_columns.sum(dtype=np.float64)
    if not (np.isfinite(total) and total > 0):
        return 0.0
    aligned = (across_rows[rows[1:height]].sum(dtype=np.float64)
               + across_columns[columns[:, 1:width]].sum(dtype=np.float64))
    return float(aligned / total)


def layout_held(lightmap, uvs, triangles, mask):
    """(aligned_step_share, whether the layout is to stay as it is: the share
    is at least ALIGNED_STEP_SHARE)."""
    share = aligned_step_share(lightmap, uvs, triangles, mask)
    return share, share >= ALIGNED_STEP_SHARE
