"""Backing off a deformed grid until the layout it gives is valid (docs/method.md §7).

The full warp can break a layout where triangles are large next to strong
deformation (a triangle's edges stay straight while the grid bends), or
where charts sit closer than the deformation allows. Rather than weakening
the whole refinement for one tight spot, the deformation is blended back
towards the identity only around the charts that fail: every node keeps a
fraction t of its displacement; t halves, round by round, in the
neighbourhood of each failing chart (and of any grid cell the blend made
invalid) until the layout passes, and rises from there no faster than the
nodes' displacement allows, so the blend itself shears no cell much. A
chart with flipped triangles backs off just enough to unflip them instead:
scaling the fraction kept in its neighbourhood scales each of its corners'
moves alike (the warp is linear in the nodes), so a triangle's area is a
quadratic in the scale, whose root is found (if the chart fails in another
way too, the next round halves it). Before a chart backs off for flips, backing off around the flipped
triangles alone is tried, with the fraction kept rising from them no
faster than the nodes' displacement allows. The original layout is the
last resort.
"""

import numpy as np

from . import _native
from .allocation import signed_areas

# Chart edges facing the gutter shrink (refine_uvs' edge_shrink) only when
# every chart pair is at least this many texels farther apart than the
# padding: their cells may move a chart's boundary a fraction of a texel
# closer, and the guards and the rigid gutter cells between keep the rest
# (why this margin: docs/refiner.md, "Options and defaults").
EDGE_SHRINK_GUTTER_MARGIN = 0.5

# Nodes this many texels around a failing chart's bounding box back off with it.
_MARGIN = 3
_ROUNDS = 10
# Rounds in which flips back off around the flipped triangles only, before
# their whole charts do.
_LOCAL_ROUNDS = 4
# Around a local back-off the fraction kept changes between neighbouring
# nodes by at most this over the node's displacement in texels: the blend
# shears a cell by (change in fraction) x (displacement).
_SLOPE = 0.1
# Below this fraction a region goes all the way back to the original.
_SNAP_TO_ZERO = 0.05
# A flipped triangle's chart keeps this share of the fraction at which the
# triangle turns degenerate: it stays clear of zero area, and of the rounding
# between the float64 root and the float32 warp.
_UNFLIP_SHARE = 0.9
_ROOT_ITERATIONS = 40


def failures(report, original, padding):
    """What makes `report` worse than allowed, relative to the original layout.
    The gutter: per chart pair when `report` has gutter_violations (a
    check_layout(..., relative_gutter=True) report), else globally."""
    failed = []
    if report["flipped"]:
        failed.append("flipped")
    if report["degenerate"] > original["degenerate"]:
        failed.append("degenerate")
    if overlaps_grew(report, original):
        failed.append("overlapping")
    if report["out_of_bounds"]:
        failed.append("out_of_bounds")
    if "gutter_violations" in report:
        if report["gutter_violations"]:
            failed.append("gutter")
    elif report["min_gutter_texels"] < allowed_gutter(padding, original):
        failed.append("gutter")
    return failed


def overlaps_grew(report, original):
    """Whether the layout of check_layout report `report` overlaps where the
    original's did not: a chart overlaps now that did not before, when both
    reports list their overlapping charts (failing_charts=True; the charts
    are the same, numbered alike), else more triangles overlap. A chart that
    overlapped itself before may count more of its triangles once scaled or
    stretched (overlaps are found in texels) without being worse, and one
    that overlaps now is worse even when the count fell elsewhere."""
    if "overlapping_charts" in report and "overlapping_charts" in original:
        now = set(np.asarray(report["overlapping_charts"]).tolist())
        return bool(now - set(np.asarray(original["overlapping_charts"]).tolist()))
    return report["overlapping"] > original["overlapping"]


def without_chart_lists(check):
    """check_layout report `check` without its chart lists (failing_charts=True
    adds them): the set of failing charts."""
    check.pop("overlapping_charts", None)
    return set(check.pop("failing_charts").tolist())


def worse_than_source(uvs, source_uvs, triangles, resolution, padding, source=None, recharted=False):
    """The promise refine_uvs makes, checked from the outside: what makes the
    refined layout `uvs` worse than `source_uvs` (an empty list: nothing), and
    the refined layout's check_layout report. Moved inside charts, each chart
    pair keeps its own distance (relative gutter) and no triangle turns over;
    repacked or re-charted, the charts sit anew (a re-charted chart may be
    mirrored against the source), the gutter is held to the padding or the
    source's narrowest and flips are counted within each chart.
    `source`: the source layout's check_layout report, if the caller has it.
    `recharted`: the charts sit anew (the re-chart route), so the check
    against the source's chart positions is not made; a layout whose charts
    (find_charts) are not the source's is taken as re-charted whatever the
    caller says (the add-on checks every map the same way)."""
    if source is None or "overlapping_charts" not in source:
        source = _native.check_layout(source_uvs, triangles, resolution, padding, failing_charts=True)
    recharted = recharted or not np.array_equal(_native.find_charts(uvs, triangles),
                                                _native.find_charts(source_uvs, triangles))
    if recharted:  # other charts: overlaps counted
        check = _native.check_layout(uvs, triangles, resolution, padding)
        return failures(check, source, padding), check
    check = _native.check_layout(uvs, triangles, resolution, padding, reference_uvs=source_uvs,
                                 relative_gutter=True, failing_charts=True)
    worse = failures(check, source, padding)
    if worse and set(worse) <= {"gutter", "flipped"}:
        # Repacked or re-charted (refine_uvs(positions=)), charts sit anew and
        # a re-charted one may be mirrored against the source: flips then
        # count against the chart's own orientation.
        check = _native.check_layout(uvs, triangles, resolution, padding, failing_charts=True)
        worse = failures(check, source, padding)
    without_chart_lists(check)
    return worse, check


def allowed_gutter(padding, original):
    """The padding, or the original's gutter if that is already narrower
    (less float32 rounding: about 1e-4 texel at 4k)."""
    return min(padding, original["min_gutter_texels"]) - 1e-4


def invalid_cells(grid):
    """(H, W) bool: cells that are not convex, non-inverted quadrilaterals
    (UV space, v up, so a valid cell turns clockwise; float32 cross products)."""
    return _native.grid_invalid_cells(np.asarray(grid, np.float32))


def chart_boxes(uvs, triangles, shape, charts=None):
    """Per chart, its node-index bounding box (i0, j0, i1, j1), widened by
    _MARGIN. charts: find_charts(uvs, triangles) if already known."""
    height, width = shape
    if charts is None:
        charts = _native.find_charts(uvs, triangles)
    count = int(charts.max()) + 1 if len(charts) else 0
    corner_chart = np.repeat(charts, 3)
    corners = uvs[triangles.ravel()].astype(np.float64)
    x, y = corners[:, 0] * width, (1 - corners[:, 1]) * height
    lo_x, lo_y = np.full(count, np.inf), np.full(count, np.inf)
    hi_x, hi_y = np.full(count, -np.inf), np.full(count, -np.inf)
    np.minimum.at(lo_x, corner_chart, x)
    np.minimum.at(lo_y, corner_chart, y)
    np.maximum.at(hi_x, corner_chart, x)
    np.maximum.at(hi_y, corner_chart, y)
    i0 = np.clip(np.floor(lo_y) - _MARGIN, 0, height).astype(int)
    j0 = np.clip(np.floor(lo_x) - _MARGIN, 0, width).astype(int)
    i1 = np.clip(np.ceil(hi_y) + _MARGIN, 0, height).astype(int)
    j1 = np.clip(np.ceil(hi_x) + _MARGIN, 0, width).astype(int)
    return np.stack([i0, j0, i1, j1], axis=1)


def _around(cells, margin):
    """Nodes of the given cells, grown by `margin` nodes."""
    nodes = np.zeros((cells.shape[0] + 1, cells.shape[1] + 1), bool)
    for di in (0, 1):
        for dj in (0, 1):
            nodes[di:di + cells.shape[0], dj:dj + cells.shape[1]] |= cells
    for _ in range(margin):
        grown = nodes.copy()
        grown[1:] |= nodes[:-1]
        grown[:-1] |= nodes[1:]
        grown[:, 1:] |= nodes[:, :-1]
        grown[:, :-1] |= nodes[:, 1:]
        nodes = grown
    return nodes


def _lower(kept, boxes, factors):
    """Scale `kept` by each factor on its node box (i0, j0, i1, j1), from the
    fractions before this call (boxes overlap: the lowest kept); a fraction
    that would fall below _SNAP_TO_ZERO goes to 0."""
    lowered = []
    for (i0, j0, i1, j1), factor in zip(boxes, factors):
        box = (slice(i0, i1 + 1), slice(j0, j1 + 1))
        lowered.append((box, np.where(kept[box] > _SNAP_TO_ZERO, np.float32(factor) * kept[box], np.float32(0))))
    for box, values in lowered:
        np.minimum(kept[box], values, out=kept[box])


def _bounded_ramp(kept, slope):
    """Lower `kept` in place so that it rises by at most `slope[n]` into any
    node n from a neighbour: the lowest over paths of the start value plus
    the slopes the path enters. Along a line that bound is a running minimum
    of kept - cumsum(slope), so sweeps along rows and columns, both ways,
    repeat until nothing changes (a path needs one round per turn). Only
    the window of the dips, grown by the farthest a dip can reach at the
    window's lowest slope, can change: a path out of it climbs that far
    first, back to 1."""
    dip_rows, dip_cols = np.flatnonzero(np.any(kept < 1, axis=1)), np.flatnonzero(np.any(kept < 1, axis=0))
    if not len(dip_rows):
        return
    climb_needed, reach = 1.0 - float(kept.min()), 0

    def grown(by):
        return (slice(max(dip_rows[0] - by, 0), dip_rows[-1] + by + 1),
                slice(max(dip_cols[0] - by, 0), dip_cols[-1] + by + 1))
    while True:  # the reach grows with the window, whose lowest slope can only fall
        needed = int(np.ceil(climb_needed / float(slope[grown(reach)].min())))
        if needed <= reach:
            break
        reach = needed
    window = grown(reach)
    values, slope = kept[window].astype(np.float64), slope[window].astype(np.float64)
    while True:
        before = values.copy()
        for axis in (0, 1):
            for reverse in (False, True):
                line = np.flip(values, axis) if reverse else values
                climb = np.cumsum(np.flip(slope, axis) if reverse else slope, axis=axis)
                bound = np.minimum.accumulate(line - climb, axis=axis) + climb
                np.minimum(line, bound, out=line)  # a view of `values` when reversed
        if np.array_equal(values, before):
            break
    np.minimum(kept[window], values.astype(np.float32), out=kept[window])


def unflip_factors(uvs, new_uvs, triangles, charts, count):
    """(count,) per chart, the factor on the fraction of the deformation its
    nodes keep that turns each of its flipped triangles back over with room
    to spare (_UNFLIP_SHARE of the factor at which the triangle is degenerate),
    or nan for a chart with no flipped triangle. new_uvs: the layout at the
    current fractions; a factor on them scales every corner's move from
    `uvs` by the same factor."""
    factors = np.full(count, np.nan)
    flipped, factor = flipped_triangles(uvs, new_uvs, triangles)
    np.fmin.at(factors, charts[flipped], factor)
    return factors


def flipped_triangles(uvs, new_uvs, triangles):
    """(indices of the triangles new_uvs turns over, the factor on each one's
    corner moves that turns it back with room to spare)."""
    before, after = signed_areas(uvs, triangles), signed_areas(new_uvs, triangles)
    flipped = np.flatnonzero((before != 0) & (np.sign(after) != np.sign(before)))
    if not len(flipped):
        return flipped, np.zeros(0)
    start = uvs[triangles[flipped]].astype(np.float64)  # (F, 3, 2)
    move = new_uvs[triangles[flipped]].astype(np.float64) - start
    orientation = np.sign(before[flipped])

    def keeps_orientation(t):
        corners = start + t[:, None, None] * move
        e, f = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        return (e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]) * orientation > 0

    # The area has the source's sign at 0 and the other at 1: bisect for the
    # change (the quadratic has one root between them).
    low, high = np.zeros(len(flipped)), np.ones(len(flipped))
    for _ in range(_ROOT_ITERATIONS):
        middle = 0.5 * (low + high)
        unflipped = keeps_orientation(middle)
        low, high = np.where(unflipped, middle, low), np.where(unflipped, high, middle)
    return flipped, _UNFLIP_SHARE * low


def _passed(check, threshold):
    """check (a passing relative-gutter report) with `valid` at the gutter required of the whole layout."""
    without_chart_lists(check)
    check["valid"] = bool(check["flipped"] == check["degenerate"] == check["overlapping"]
                          == check["out_of_bounds"] == 0 and check["min_gutter_texels"] >= threshold)
    return check


def _slopes(displacement, shape):
    """Per node, the most the fraction kept may change into it from a neighbour: _SLOPE over the node's
    displacement in texels (at most 1)."""
    across, down = displacement[..., 0] * np.float32(shape[1]), displacement[..., 1] * np.float32(shape[0])
    return _SLOPE / np.maximum(np.sqrt(across * across + down * down), _SLOPE)  # as np.linalg.norm, bit for bit


def _unflip_locally(kept, displacement, identity, uvs, new_uvs, triangles, shape, padding, original, checker,
                    threshold):
    """Back off around flipped triangles only, from the fractions `kept`
    (not modified) whose layout `new_uvs` has flips and perhaps overlaps but
    no other failure: each flipped triangle's nodes keep its unflip factor,
    and the fraction rises from there no faster than _SLOPE over the nodes'
    displacement. Returns (grid, uvs, check, kept) once the layout passes,
    or None if it fails in another way or is still flipped after
    _LOCAL_ROUNDS (the caller then backs off whole charts)."""
    kept = kept.copy()
    slope = _slopes(displacement, shape)
    for _ in range(_LOCAL_ROUNDS):
        flipped, factor = flipped_triangles(uvs, new_uvs, triangles)
        # Each triangle its own box: every node its corners are warped with, so its corners' moves scale alike.
        _lower(kept, chart_boxes(uvs, triangles[flipped], shape, charts=np.arange(len(flipped))), factor)
        _bounded_ramp(kept, slope)
        grid = kept[..., None] * displacement
        grid += identity
        grid = grid.astype(np.float32, copy=False)
        if invalid_cells(grid).any():
            return None
        new_uvs = _native.warp_uvs(uvs, grid)
        check = checker.check(new_uvs, failing_charts=True, relative_gutter=True)
        failed = failures(check, original, padding)
        if not failed:
            return grid, new_uvs, _passed(check, threshold), kept
        if "flipped" not in failed or not set(failed) <= {"flipped", "overlapping"}:
            return None
    return None


def accept(full, identity, uvs, triangles, shape, padding, original, checker=None):
    """The most of `full` that gives a valid layout. checker: the original's
    LayoutChecker (uvs, triangles, shape, padding) if the caller has one.

    Returns (grid, uvs, check, kept, limited_by): the blended grid, the
    warped UVs, their check_layout report, the (H + 1, W + 1) fraction of
    the deformation kept at each node, and what forced any back-off.
    """
    if checker is None:
        checker = _native.LayoutChecker(uvs, triangles, shape, padding)
    kept = np.ones(full.shape[:2], np.float32)
    displacement = full - identity
    threshold = max(allowed_gutter(padding, original), 0.0)
    boxes = slope = None
    limited_by = []
    tried_locally = False
    for _ in range(_ROUNDS):
        # identity + kept * (full - identity), without temporaries.
        grid = kept[..., None] * displacement
        grid += identity
        grid = grid.astype(np.float32, copy=False)
        bad_cells = invalid_cells(grid)
        if not bad_cells.any():
            new_uvs = _native.warp_uvs(uvs, grid)
            # Per chart pair: no pair closer than min(padding, its original
            # distance), so one tight pair does not hold back all the others.
            check = checker.check(new_uvs, failing_charts=True, relative_gutter=True)
            failed = failures(check, original, padding)
            if not failed:
                return grid, new_uvs, _passed(check, threshold), kept, limited_by
            limited_by += [f for f in failed if f not in limited_by]
            if not tried_locally and "flipped" in failed and set(failed) <= {"flipped", "overlapping"}:
                # One small flipped triangle need not hold back its whole chart: first try
                # backing off around the flipped triangles only.
                tried_locally = True
                local = _unflip_locally(kept, displacement, identity, uvs, new_uvs, triangles, shape, padding,
                                        original, checker, threshold)
                if local is not None:
                    return (*local, limited_by)
            if boxes is None:
                boxes = chart_boxes(uvs, triangles, shape, checker.charts)
            failing = check["failing_charts"]
            factors = np.full(len(boxes), 0.5)
            if "flipped" in failed:
                unflip = unflip_factors(uvs, new_uvs, triangles, checker.charts, len(boxes))
                factors = np.where(np.isnan(unflip), factors, unflip)
            if len(failing):
                _lower(kept, boxes[failing], factors[failing])
                slope = _slopes(displacement, shape) if slope is None else slope
                _bounded_ramp(kept, slope)
                continue
            region = np.ones(kept.shape, bool)  # a failure no chart owns: back off everywhere
        else:
            if "grid" not in limited_by:
                limited_by.append("grid")
            region = _around(bad_cells, _MARGIN)
        kept[region] = np.where(kept[region] > _SNAP_TO_ZERO, 0.5 * kept[region], 0.0)
        slope = _slopes(displacement, shape) if slope is None else slope
        _bounded_ramp(kept, slope)
    kept[:] = 0.0
    return identity, uvs.copy(), original, kept, limited_by
