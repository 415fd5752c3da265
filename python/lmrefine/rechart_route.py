"""The re-chart route of refine_uvs: a source layout with no room is re-charted from the mesh.

The automaton moves UVs inside charts; a UV on a chart's border keeps its
place. Lightmap Pack cuts one chart per face, so every UV is on a border and
only the chart repack can gain (docs/refiner.md, "Chart scaling"). When the
source layout gives the refiner no room (`layout_room`) and the caller gives
the mesh (`refine_uvs(..., positions=)`), the mesh is re-charted
(lmrefine.rechart), the first lightmap is carried over to the new layout
(`resample_lightmap`), and the new layout is refined instead. It is kept only
when the error model (`predicted_error`: light changes and chart borders,
in world units) predicts clearly less error than the source layout and no
more than the source layout's own refinement. docs/refiner.md, "The re-chart
route".
"""

import numpy as np

from . import _native, allocation, backoff, stretch
from .charting import rechart
from .packer import CHART_TOLERANCE
from .rows import group_rows

# A layout has no room when less than this fraction of its UV area lies in
# triangles with a corner strictly inside their chart. Lightmap Pack layouts
# measure 0 on every bundled scene, Smart UV layouts 0.78-0.99 (plaza's 120
# triangles lowest): docs/refiner.md.
MIN_ROOM_FRACTION = 0.25
# The re-charted layout is kept when the model predicts at most this
# fraction of the source layout's error (as allocation.REQUIRED_GAIN).
REQUIRED_GAIN = allocation.REQUIRED_GAIN
# The re-chart angle of the route, in degrees. Chosen on courtyard, the only
# tuning scene whose charts change with it: 5-17 degrees (231 charts)
# measured 2.35x / 1.59x at 256^2 / 512^2, 20 (201 charts) 2.40x / 2.27x,
# 30 2.31x / 1.97x, 45 2.22x / 1.92x (docs/evaluation.md, "The re-chart
# route"). lmrefine.rechart keeps its own default for evaluate --rechart.
ANGLE = 20.0
# Texels at least between the re-charted charts (more when the caller's
# padding asks): the new layout is not held to the source's gutter, and a
# re-charted courtyard (tuning) measured 2.00x at the source's 1.03-texel
# gutter against 2.35x at 2 (docs/evaluation.md, "The re-chart route").
PADDING = 2.0
# The re-charted layout wins without the source layout's repack being made
# when its prediction is this much (relative) below the repack's lower bound:
# the packed charts' float32 UVs scale each triangle to a few ulps.
_BOUND_MARGIN = 1e-4
# The border term's weight in the route's model, over allocation.BORDER_ERROR
# (derived before the baker clamped a border texel's samples onto its chart,
# it overstated the borders of one-face charts): chosen with
# bench/route_choice.py on the tuning scenes (docs/refiner.md, "The re-chart
# route").
BORDER_WEIGHT = 0.25
_BORDER = allocation.BORDER_ERROR * BORDER_WEIGHT
# UVs closer than this (a power of two near CHART_TOLERANCE) are one vertex
# of a chart when telling border corners from inner ones.
_VERTEX_GRID = float(1 << 17)


def layout_room(uvs, triangles):
    """How much room a layout gives the refiner: where its UVs can move.

    A corner is on its chart's border when one of its chart's border edges
    (an edge only one triangle of the chart uses; UVs of a chart equal to
    1/2^17 are one vertex) ends at it. `room_fraction` is the UV area of the
    triangles with a corner off the border, over the layout's UV area.
    Returns {charts, triangles, triangles_per_chart, room_fraction, no_room}
    with no_room = room_fraction < MIN_ROOM_FRACTION.
    """
    uvs = np.asarray(uvs)
    triangles = np.asarray(triangles)
    count = len(triangles)
    charts, vertex, border = _chart_borders(uvs, triangles)
    chart_count = int(charts.max()) + 1 if count else 0
    fraction = 0.0
    if count:
        inner = np.ones(int(vertex.max()) + 1, bool)
        inner[vertex[border]] = False  # the start of a border edge (its end starts the next one)
        area = np.abs(allocation.signed_areas(uvs, triangles))
        total = float(area.sum())
        fraction = float(area[inner[vertex].any(axis=1)].sum() / total) if total > 0 else 0.0
    return {"charts": chart_count, "triangles": int(count),
            "triangles_per_chart": float(count / chart_count) if chart_count else 0.0,
            "room_fraction": fraction, "no_room": bool(count and fraction < MIN_ROOM_FRACTION)}


def _chart_borders(uvs, triangles):
    """(charts (T,), vertex (T, 3) ids of the corners' chart vertices, border
    (T, 3) bool: the edge from corner k to corner k + 1 is a border edge of
    its chart)."""
    count = len(triangles)
    if not count:
        return np.zeros(0, np.int32), np.zeros((0, 3), np.int64), np.zeros((0, 3), bool)
    charts = _native.find_charts(uvs, triangles, tolerance=CHART_TOLERANCE)
    snapped = np.round(np.asarray(uvs, np.float64)[triangles.ravel()] * _VERTEX_GRID).astype(np.int64)
    vertex = group_rows(np.column_stack([np.repeat(charts, 3), snapped]))[0].reshape(count, 3)
    edges = np.sort(np.stack([vertex, np.roll(vertex, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    edge_id, uses = group_rows(edges)
    return charts, vertex, (uses[edge_id] == 1).reshape(count, 3)


# The least perimeter over sqrt(area) of a chart's equal-area affine images
# (ErrorModel.lowest_packed lets a packing stretch its charts): a triangle's
# is the equilateral one's, a convex quadrilateral's the square's (a regular
# n-gon has the least perimeter of the n-gons of its area). Steiner's formula,
# area + perimeter r + pi r^2, is a convex chart's area grown by r; for any
# other chart the disc's factor gives the Brunn-Minkowski bound.
TRIANGLE_PERIMETER = 2.0 * np.sqrt(3.0 * np.sqrt(3.0))
QUADRILATERAL_PERIMETER = 4.0
DISC_PERIMETER = 2.0 * np.sqrt(np.pi)


def perimeter_factors(uvs, triangles, charts, vertex, count):
    """(count,) per chart a factor k such that the chart, of area a, turned,
    moved or stretched at equal area and grown by r covers at least a + k
    sqrt(a) r + pi r^2: TRIANGLE_PERIMETER for a chart of one triangle,
    QUADRILATERAL_PERIMETER for two triangles that share one edge and make a
    convex quadrilateral (a Lightmap Pack quad), DISC_PERIMETER otherwise.
    `charts` (T,) and `vertex` (T, 3) as _chart_borders gives them."""
    charts = np.asarray(charts, np.int64)
    factors = np.full(count, DISC_PERIMETER)
    if not len(charts):
        return factors
    size = np.bincount(charts, minlength=count)[:count]
    factors[size == 1] = TRIANGLE_PERIMETER
    pairs = np.flatnonzero(size == 2)
    if not len(pairs):
        return factors
    order = np.argsort(charts, kind="stable")
    start = np.searchsorted(charts[order], pairs)
    first, second = order[start], order[start + 1]
    shared = vertex[first][:, :, None] == vertex[second][:, None, :]  # (P, 3, 3)
    in_first, in_second = shared.any(axis=2), shared.any(axis=1)  # corners on the shared edge
    one_edge = (shared.sum(axis=(1, 2)) == 2) & (in_first.sum(axis=1) == 2)
    corners = np.asarray(uvs, np.float64)[np.asarray(triangles)]
    a, b = corners[first], corners[second]
    rows = np.arange(len(pairs))
    x = a[rows, np.argmin(in_first, axis=1)]  # the corner of `first` off the shared edge
    y = b[rows, np.argmin(in_second, axis=1)]  # and of `second`
    on_edge = np.argsort(~in_first, axis=1, kind="stable")[:, :2]
    p, q = a[rows, on_edge[:, 0]], a[rows, on_edge[:, 1]]

    def side(o, d, point):
        return (d[:, 0] - o[:, 0]) * (point[:, 1] - o[:, 1]) - (d[:, 1] - o[:, 1]) * (point[:, 0] - o[:, 0])

    # Convex: x and y on either side of the shared edge pq, and p and q on either side of xy.
    convex = one_edge & (side(p, q, x) * side(p, q, y) < 0) & (side(x, y, p) * side(x, y, q) < 0)
    factors[pairs[convex]] = QUADRILATERAL_PERIMETER
    return factors


def resample_lightmap(lightmap, source_uvs, source_triangles, uvs, triangles, mask):
    """The lightmap baked on (source_uvs, source_triangles) carried over to
    the layout (uvs, triangles) of the same triangles: each texel of `mask`
    takes the bilinear value of the source map at the same surface point (the
    texel centre in the triangle that holds it, or the nearest point of the
    nearest triangle for a texel a triangle only grazes). Other texels are 0.
    Returns float32 with the lightmap's shape.

    Native (lmrefine._native.carry_lightmap: texel_points, then per texel
    the clamped barycentrics, the source UV and the bilinear lookup, on all
    cores), bit-identical to the numpy reference in tests/test_rechart_route.py."""
    lightmap = np.asarray(lightmap, np.float32)
    return _native.carry_lightmap(lightmap, source_uvs, source_triangles, uvs, triangles, np.asarray(mask, bool))


def predicted_error(source_uvs, uvs, triangles, energy, positions=None, lightmap=None, mask=None, folds=None):
    """The error model's prediction for layout `uvs` relative to the source
    layout `source_uvs` (same triangles; 1.0 = the same), from the first
    bake on the source layout: its gradient `energy` (H, W) and, with
    `positions` and `lightmap`, its luminance slope.

    Both terms of docs/refiner.md "Chart scaling", in world units so that
    layouts with different charts compare: the edge term, each triangle's
    gradient energy times its texel size in the source and its texel
    spacing in `uvs` across the light changes (EDGE_ERROR;
    ErrorModel.gradient_spacing); the border term, each chart border edge's
    world length times the luminance slope of its triangle (per world unit)
    times the squared texel size there (BORDER_ERROR x BORDER_WEIGHT: the
    border texels, filled by dilation, miss part of the slope). Without
    positions the edge term alone, by the linear texel scale sqrt(new /
    source UV area).

    `folds` (lmrefine.folds.Folds of the source layout): the light changes
    in a fold's band count in the edge term only for layouts that keep the
    fold inside a chart, and the band's luminance slope (the bake's blurred
    step, not smooth light) is left out of the border term."""
    return ErrorModel(source_uvs, triangles, energy, positions, lightmap, mask, folds).relative(uvs)


class ErrorModel:
    """predicted_error with what depends only on the source layout and the
    first bake (texel sizes, the opened slope, the source layout's own error)
    computed once: the route compares two layouts against the same source.
    `relative(uvs)` is predicted_error(source_uvs, uvs, ...) bit for bit."""

    def __init__(self, source_uvs, triangles, energy, positions=None, lightmap=None, mask=None, folds=None):
        source_uvs = np.asarray(source_uvs)
        self.triangles, self.folds, self.texels = triangles, folds, float(energy.shape[0] * energy.shape[1])
        self.edge = allocation.triangle_energy(source_uvs, triangles, energy)
        self.before = np.abs(allocation.signed_areas(source_uvs, triangles))
        self.world = None
        if positions is None or lightmap is None:
            return
        corners = np.asarray(positions, np.float64)[triangles]
        self.world = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
                                          axis=1)
        # Texel size in world units per triangle in the source layout.
        self.size_before = np.where(self.world > 0, np.sqrt(self.world / np.maximum(self.before * self.texels,
                                                                                    1e-300)), 0.0)
        # Slope per world unit: the source bake's slope per texel over its texel size.
        if mask is None:
            mask = _native.coverage_mask(source_uvs, triangles, energy.shape)
        slope = allocation.luminance_slope(lightmap, mask)
        if folds is not None:
            slope = np.where(folds.band, np.float32(0), slope)
        slope = allocation.opening(slope, mask)
        rows, cols = allocation.triangle_texels(source_uvs, triangles, energy.shape)
        self.slope_texel = slope[rows, cols].mean(axis=1)
        # The first bake's light changes per triangle by direction: a layout's
        # texels count by how they space the light's gradient, not by their area.
        self.tensors = stretch.source_tensors(lightmap, mask, source_uvs, triangles)
        self.tensor_trace = self.tensors[:, 0, 0] + self.tensors[:, 1, 1]
        self.lengths = np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2)  # edge k: corner k to k + 1
        self.source_uvs = source_uvs
        self._source_error = {}  # per keep mask's bytes: the source layout's error over those triangles

    def relative(self, uvs):
        """The predicted error of layout `uvs` over the source layout's (1.0 = the same)."""
        uvs = np.asarray(uvs)
        edge, before = self.edge, self.before
        after = np.abs(allocation.signed_areas(uvs, self.triangles))
        if self.world is None:
            keep = (before > 0) & (edge > 0)
            total = float(edge[keep].sum())
            if total <= 0:
                return 1.0
            return float((edge[keep] / np.sqrt(np.maximum(after[keep], 1e-300) / before[keep])).sum() / total)
        keep, size_after = self._kept(after)
        edge_terms, border_terms, _, _ = self._terms(uvs, size_after, keep)
        source_error = self._source(keep)
        error = (allocation.EDGE_ERROR * edge_terms[keep].sum()
                 + _BORDER * border_terms[keep].sum())
        return float(error / source_error) if source_error > 0 else 1.0

    def _kept(self, after):
        """The triangles with area in the source, in a layout of UV areas
        `after` and on the surface, and their texel size in that layout."""
        keep = (self.before > 0) & (after > 0) & (self.world > 0)
        return keep, np.where(keep, np.sqrt(self.world / np.maximum(after * self.texels, 1e-300)), 0.0)

    def _terms(self, layout, size, keep):
        """Per triangle, the edge term's and the border term's products
        (before their constants) of `layout`, whose texel sizes are `size`:
        the light changes it keeps inside its charts times the source's
        texel size and the texel spacing across them (gradient_spacing); the
        slope along its charts' borders times its texel size squared; each
        triangle's chart, and its corners' chart vertices (_chart_borders)."""
        size_before = np.where(keep, self.size_before, 0.0)
        slope_world = np.where(keep, self.slope_texel / np.maximum(size_before, 1e-300), 0.0)
        charts, vertex, border = _chart_borders(layout, self.triangles)
        border = (border * self.lengths).sum(axis=1)
        held = self.edge if self.folds is None else np.maximum(
            self.edge - self.folds.energy_removed(layout, self.triangles), 0.0)
        spacing = self.gradient_spacing(layout, size, keep)
        return held * size_before * spacing, slope_world * border * size * size, charts, vertex

    def gradient_spacing(self, layout, size, keep):
        """Per triangle, the world size of `layout`'s texels across the first
        bake's light changes: the source texel size times sqrt(tr(A^-T S A^-1)
        / tr S), S the triangle's structure tensor in the source layout and A
        its map from the source layout to `layout` (a gradient maps by A^-T).
        A uniform scale s gives 1 / s, as the texel size `size` does, which a
        triangle without light changes keeps; texels long across the light
        changes count for less than their area, long along them for more."""
        mapped = stretch.triangle_tensors(None, None, self.source_uvs, layout, self.triangles, source=self.tensors)
        trace = mapped[:, 0, 0] + mapped[:, 1, 1]
        lit = keep & (self.tensor_trace > 0) & (trace > 0)
        ratio = np.ones(len(lit))
        ratio[lit] = trace[lit] / self.tensor_trace[lit]
        return np.where(lit, self.size_before * np.sqrt(ratio), size)

    def _source(self, keep):
        """The source layout's error over the `keep` triangles. It depends on
        the layout compared only through `keep`: computed once per mask."""
        key = keep.tobytes()
        if key not in self._source_error:
            edge_terms, border_terms, _, _ = self._terms(self.source_uvs, np.where(keep, self.size_before, 0.0),
                                                         keep)
            self._source_error[key] = (allocation.EDGE_ERROR * edge_terms[keep].sum()
                                       + _BORDER * border_terms[keep].sum())
        return self._source_error[key]

    def lowest_packed(self, shape, padding, scales, base_uvs=None, max_stretch=1.0):
        """A lower bound on `relative(uvs)` over every layout that keeps each
        chart of `base_uvs` (default the source layout; the same charts,
        moved inside by the automaton) whole, turned, moved or stretched at
        equal area by at most `max_stretch` (the map's larger singular value),
        scaled linearly by g * scales[c] for one g (the scales of
        allocation.signal_scales: the repack's packings), at least `padding`
        texels apart inside the (H, W) = `shape` atlas. None without
        positions.

        Chart c scaled by s predicts A_c / s + B_c / s^2 (its edge term by
        texel spacing across the light changes, its border term by the
        texel size squared, from `base_uvs`' texels), falling as g grows; a
        stretch T lowers no triangle's spacing below 1 / sigma_max(T) of it
        (gradient_spacing: the gradient maps by T^-T), so A_c counts
        divided by `max_stretch`. Grown by a disc of radius r = padding /
        2, a chart of texel area a_c s^2 covers at least a_c s^2 + k_c
        sqrt(a_c) s r + pi r^2 texels (perimeter_factors: k_c = 2 sqrt(pi)
        by Brunn-Minkowski for any chart, more by Steiner's formula for a
        triangle or a convex quadrilateral), and the grown charts are
        disjoint inside the atlas grown by r: the largest g that allows
        bounds the error from below. A chart whose triangles overlap covers
        less than their areas: the caller gives only layouts without
        overlaps."""
        if self.world is None:
            return None
        base = self.source_uvs if base_uvs is None else np.asarray(base_uvs)
        area = np.abs(allocation.signed_areas(base, self.triangles))
        # Scaled whole, a chart keeps its triangles' areas > 0, its borders and the folds it holds.
        keep, size = self._kept(area)
        edge_terms, border_terms, charts, vertex = self._terms(base, size, keep)
        count = len(scales)
        edge = allocation.EDGE_ERROR / max_stretch * np.bincount(charts[keep], edge_terms[keep], minlength=count)
        slope = _BORDER * np.bincount(charts[keep], border_terms[keep], minlength=count)
        total = float(self._source(keep))
        texels = np.bincount(charts, area, minlength=count) * self.texels
        scales = np.asarray(scales, np.float64)
        live = (texels > 0) & (scales > 0)
        if total <= 0 or not live.any():
            return None
        radius = 0.5 * padding
        root = np.sqrt(texels[live]) * scales[live]
        perimeter = perimeter_factors(base, self.triangles, charts, vertex, count)[live]
        # sum (root^2 g^2 + k root g r + pi r^2) <= budget, a quadratic in g.
        quadratic, linear = float((root * root).sum()), radius * float((perimeter * root).sum())
        constant = live.sum() * np.pi * radius * radius - (shape[0] + padding) * (shape[1] + padding)
        if constant >= 0:
            return None  # no packing could hold the charts: nothing to bound
        g = (-linear + np.sqrt(linear * linear - 4.0 * quadratic * constant)) / (2.0 * quadratic)
        scaled = g * scales[live]
        return float((edge[live] / scaled + slope[live] / scaled ** 2).sum() / total)


def _per_index(recharted, uvs, triangles):
    """The per-corner re-charted UVs (3T, 2) in the source's indexing (N, 2),
    or None when one UV index would need two places (faces sharing a UV whose
    corners land in different new charts). Unused UVs keep their value."""
    out = np.asarray(uvs, np.float32).copy()
    flat = triangles.ravel()
    out[flat] = recharted
    if not np.array_equal(out[flat], recharted):
        return None
    return out


def _per_uv_vectors(value, count, name, what):
    """`value` as an (count, 3) array of real numbers, one `what` per UV."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise TypeError(f"{name} must be an (N, 3) array of the UVs' {what}s, got {type(value).__name__}")
    array = np.asarray(value)
    if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)):
        raise TypeError(f"{name} must hold real numbers, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape != (count, 3):
        raise ValueError(f"{name} must have shape ({count}, 3), one {what} per UV (the uvs' indexing), "
                         f"got {array.shape}")
    return array


def positions_array(positions, count):
    """`positions` validated: (count, 3) float64, finite."""
    array = _per_uv_vectors(positions, count, "positions", "3-D position").astype(np.float64)
    if not np.isfinite(array).all():
        bad = int(np.flatnonzero(~np.isfinite(array).all(axis=1))[0])
        raise ValueError(f"positions[{bad}] is NaN or Inf; fix the mesh's vertices (or pass positions=None "
                         f"to refine without re-charting)")
    return array


def normals_array(normals, count):
    """`normals` (shading normals per UV) validated: (count, 3) float32. A
    zero or non-finite normal is allowed: its edges count as hard."""
    array = _per_uv_vectors(normals, count, "normals", "shading normal")
    with np.errstate(over="ignore", invalid="ignore"):
        return array.astype(np.float32)


def polygons_array(polygons, count):
    """`polygons` (a face id per triangle) validated: (count,) int64, ids
    renumbered 0..P-1 in the order of their values."""
    array = np.asarray(polygons)
    if array.shape != (count,) or not (np.issubdtype(array.dtype, np.integer) and array.dtype != np.bool_):
        raise ValueError(f"polygons must hold one integer face id per triangle, shape ({count},), got "
                         f"{array.dtype} {array.shape}: pass the face each triangle was cut from (Blender's "
                         "loop_triangles' polygon_index), or polygons=None")
    return np.unique(array, return_inverse=True)[1].astype(np.int64).reshape(count)


def polygon_ids(triangles, polygons=None):
    """(T,) int32: per triangle, the smallest UV index of its polygon: the
    triangles that share UV indices, chained (in Blender's per-loop layout a
    quad's or an n-gon's triangles: one loop, one UV, so one chart), joined
    with the triangles of the same face in `polygons` (polygons_array; a
    per-corner layout shares no UV index, so only its caller knows its
    faces; None: none given)."""
    triangles = np.asarray(triangles)
    if len(triangles) == 0:
        return np.zeros(0, np.int32)
    if polygons is not None:
        # A face id is one more index its triangles share (after every UV index).
        triangles = np.column_stack([triangles, int(triangles.max()) + 1 + np.asarray(polygons)])
    label = np.arange(int(triangles.max()) + 1)
    while True:
        smallest = label[triangles].min(axis=1)
        joined = label.copy()
        np.minimum.at(joined, triangles.ravel(), np.repeat(smallest, triangles.shape[1]))
        joined = joined[joined]  # pointer jumping: a long chain closes in log steps
        if np.array_equal(joined, label):
            return label[triangles[:, 0]].astype(np.int32)
        label = joined


def _recharted_refinement(refine, lightmap, uvs, triangles, shape, positions, normals, polygons, padding, gutter,
                          progress):
    """The mesh re-charted with its charts `gutter` texels apart (each of
    `polygons`, a label per triangle, kept whole) and refined at `padding`
    from `lightmap` carried over: (re-charting report, result), or (None,
    why not)."""
    try:
        recharted = rechart(positions, triangles, ANGLE, shape, gutter, progress=progress,
                            normals=None if normals is None else normals[triangles].reshape(-1, 3),
                            polygons=polygons)
    except ValueError as error:
        return None, f"the mesh could not be re-charted: {error}"
    new_uvs = _per_index(recharted.uvs, uvs, triangles)
    if new_uvs is None:
        return None, ("the re-charted layout puts corners that share a UV into different charts "
                      "(a polygon with a degenerate triangle, or one that folds over itself)")
    new_mask = _native.coverage_mask(new_uvs, triangles, shape)
    carried = resample_lightmap(lightmap, uvs, triangles, new_uvs, triangles, new_mask)
    return recharted.report, refine(carried, new_uvs, new_mask, padding)


def fit_reset(levels):
    """Whether the automaton's finest level (of a report's `levels`) started
    with a fit that sent a region back to rest (it cascaded:
    run_automaton's `fit_reset`), undoing that region's deformation."""
    return bool(levels) and bool(levels[-1].get("fit_reset"))


def refine_recharted(refine, lightmap, uvs, triangles, shape, padding, positions, room, energy, source_layout,
                     original, progress, folds=None, normals=None, polygons=None, source_lowest=None):
    """The re-chart route: `refine(lightmap, uvs, mask, padding)` (refine_uvs without
    positions, with the caller's options, up to its repack: refine._Unfinished,
    its `compared` layout before the triangle stretch and `finished()` the
    result) on the re-charted mesh, from `lightmap` carried over to it.
    `source_layout()` makes the source layout's own refinement up to the
    layout the model compares (called at most once, and not at all when
    `source_lowest(model)`, given, bounds its prediction from below
    (ErrorModel.lowest_packed) above the re-charted layout's, which then
    wins: report predicted_error_source_route None, source_route_bound the
    bound), `original` the source layout's check_layout report, `energy` the first bake's gradient
    energy on the source layout, `folds` its charts' folds (lmrefine.folds;
    None: counted as none), `normals` the shading normals per UV (None: flat
    shading), `polygons` the caller's face id per triangle (polygons_array;
    None: the faces are read from the UV indices the triangles share). When
    the refinement's automaton fit reset a region of a layout whose chart
    edges were all rigid, the charts are packed once more half a texel
    farther apart and refined, and tried first where the model prefers it
    (report "edge_room": whether the layout reported is that one). A
    re-charted refinement is finished (its triangle stretch made) and
    checked against the source layout only once the model has chosen it.
    Returns (result or None, rechart report)."""
    info = {"used": False, "room": room, "angle": float(ANGLE), "folds": fold_report(folds), "edge_room": None,
            "source_route_bound": None}
    # The new layout is not held to the source's gutter: at least PADDING.
    pack_padding = max(float(padding), PADDING)
    faces = polygon_ids(triangles, polygons)
    recharted, result = _recharted_refinement(refine, lightmap, uvs, triangles, shape, positions, normals, faces,
                                              pack_padding, pack_padding, progress)
    if recharted is None:
        info["reason"] = result
        return None, info
    # One model of the source layout for every prediction (its texel sizes, slope and error).
    model = ErrorModel(uvs, triangles, energy, positions, lightmap, folds=folds)
    # Layouts are compared before their triangle stretch (its gain on the
    # one-face charts of a source layout the model overstates as often as it
    # understates: docs/refiner.md, "Compared finished, tried"); a refinement
    # is finished (the stretch made) only where it may be returned.
    predicted = model.relative(result.compared)
    # The candidates in the order tried: the one packed farther apart first where the model prefers it.
    candidates = [(recharted, result, predicted, False)]
    if result.fit_reset and result.edge_shrink == 1.0:
        # Charts exactly the padding apart keep every edge texel rigid, and
        # the automaton's fit undid a region's deformation: charts packed
        # farther apart let the edge texels shrink (docs/refiner.md, "Edge
        # room when the automaton's fit cascades"). Kept when the model
        # prefers it and it passes the same checks.
        roomier, retried = _recharted_refinement(
            refine, lightmap, uvs, triangles, shape, positions, normals, faces, pack_padding,
            pack_padding + backoff.EDGE_SHRINK_GUTTER_MARGIN, progress)
        info["edge_room"] = False
        if roomier is not None:
            retried_predicted = model.relative(retried.compared)
            if retried_predicted < predicted:
                candidates.insert(0, (roomier, retried, retried_predicted, True))
    if source_lowest is not None:
        info["source_route_bound"] = source_lowest(model)
    bound = info["source_route_bound"]
    source_predicted = None
    for recharted, result, predicted, edge_room in candidates:
        info.update({key: recharted[key] for key in ("charts", "split_charts", "degenerate_triangles",
                                                     "utilisation", "area_utilisation")})
        info["predicted_error"] = predicted
        info.pop("failed", None)  # an earlier candidate's checks
        if info["edge_room"] is not None:
            info["edge_room"] = edge_room
        if bound is not None and predicted < REQUIRED_GAIN and predicted <= bound * (1.0 - _BOUND_MARGIN):
            # The source layout's refinement could only predict more error: not made.
            info["predicted_error_source_route"] = None
        else:
            if source_predicted is None:
                source_predicted = model.relative(source_layout())
            info["predicted_error_source_route"] = source_predicted
            # Both against the source layout; the lower prediction wins (the source
            # layout's own refinement is never worse than the source by its checks).
            # A later candidate predicts more error, so it loses too.
            if not (predicted < REQUIRED_GAIN and predicted <= source_predicted):
                info["reason"] = (f"the error model predicts {predicted:.3f} of the source layout's error "
                                  f"re-charted and {source_predicted:.3f} refining the source layout "
                                  f"(re-charting needs below {REQUIRED_GAIN} and below the other)")
                return None, info
        # Finished (its triangle stretch made) and checked only where it may be returned.
        result = result.finished()
        worse, check = backoff.worse_than_source(result.uvs, uvs, triangles, shape, padding, source=original,
                                                 recharted=True)
        if not worse:
            info["used"] = True
            result.report["check"] = check
            return result, info
        info["failed"] = worse
        info["reason"] = f"the re-charted layout failed {', '.join(worse)} against the source layout"
    return None, info


def fold_report(folds):
    """The report's summary of a source layout's folds (None: not looked for)."""
    if folds is None:
        return None
    smooth = 0 if folds.smooth is None else int(folds.smooth.sum())
    return {"count": int(len(folds.faces)), "length": float(folds.length.sum()), "smooth": smooth,
            "energy_fraction": folds.energy_fraction}
