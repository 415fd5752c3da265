"""Chart-level texel allocation: each chart's scale from its signal, then one packed atlas.

The error model (docs/refiner.md, "Chart scaling"): a chart c at linear
texel scale s_c (texels per UV unit, relative to the input layout) has a
reconstruction error

    err_c(s_c) = edge_c / s_c + smooth_c / s_c^2,

edge_c from its light changes (the sharp part of the first bake's gradient
energy: a blurred edge's error falls with the texel size) and smooth_c from
its smooth light (the curvature inside the chart and the gradient across its
border texels, both falling with the texel area). For a fixed texel budget
sum_c A_c s_c^2 (A_c the chart's UV area) the scales that minimise
sum_c err_c solve edge_c s_c + 2 smooth_c = 2 lambda A_c s_c^4 (Lagrange),
with one lambda for all charts (`optimal_scales`). Flat charts would shrink
to nothing: a floor on the edge density and bounds on the relative scale
keep every chart large enough for bilinear lookup and dilation. The packer
(lmrefine.pack_charts) then finds the largest global scale at which all
charts fit. The smooth term is off by default (SMOOTH_TERM): the edge term
alone, on the whole gradient energy, gives s_c proportional to
(E_c / A_c)^(1/3).
"""

from typing import NamedTuple

import numpy as np

from .packer import CHART_TOLERANCE, pack_charts
from .progressbar import cancels
from ._native import coverage_mask, find_charts
from .rows import group_rows

# Edge-density floor, relative to the mean over charts: a flat chart is
# treated as if it had this much light change (without smooth light it
# shrinks by at most (FLOOR)^(1/3) before the scale bounds apply).
ENERGY_FLOOR = 0.05
# Texel error per unit, at the input's scale (docs/refiner.md, "Chart
# scaling"). EDGE_ERROR per unit of gradient energy (the gradient map's
# channel sum): a step of height d blurred over a texel has an L1 error of
# d / 4 per unit of its length and d4 energy 1.93 d per unit length.
# BORDER_ERROR per unit of luminance slope and border length: a texel on a
# chart's border (its centre outside the chart half the time, filled by
# dilation) misses the slope over about a quarter texel. CURVATURE_ERROR per
# unit of the smooth part of the gradient energy: a parabola of curvature k
# has a linear-interpolation error of k / 12 per texel and d4 energy 1.22 k
# per texel, so 1 / (12 x 1.22) as derived; it is 0 (the smooth part of the
# gradient energy left out of both terms): the tuning scenes measured better
# so (docs/refiner.md).
EDGE_ERROR = 1.0 / (4.0 * 1.93)
BORDER_ERROR = 0.25
CURVATURE_ERROR = 0.0
# Weight of the smooth term against the edge term (1: as derived).
SMOOTH_WEIGHT = 1.0
# The smooth term is off by default: on the tuning scenes it lowered some
# rows (docs/evaluation.md, "The chart model's smooth term"). Off, the
# model is the edge term alone on the whole gradient energy, as before.
SMOOTH_TERM = False
# Rec. 709 luminance, as the gradient map reads RGB.
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
# repack is kept when the model predicts at most this fraction of the
# unpacked error, and the packed atlas is at least this fraction as dense as
# the input, charts grown by half the padding (padded_utilisation;
# docs/refiner.md, "Chart scaling").
REQUIRED_GAIN = 0.95
MIN_UTILISATION_KEPT = 0.95


class KeepRule(NamedTuple):
    """When a packing is kept: its predicted error below `required_gain`,
    its padded utilisation at least `min_utilisation` of the input's; of
    the stretch's candidates, the first that passes, or with `lowest` the
    one the model predicts least error for."""
    required_gain: float
    min_utilisation: float
    lowest: bool


def callers_rule():
    """The rule for a caller's packing (REQUIRED_GAIN, MIN_UTILISATION_KEPT)."""
    return KeepRule(REQUIRED_GAIN, MIN_UTILISATION_KEPT, False)


# For a layout this library packed itself at one scale (the re-chart
# route's charts) there is no caller's packing to hold a repack to: the
# model's word alone, any predicted gain, the lowest prediction of the
# stretch's candidates (docs/refiner.md, "The route's own packing").
OWN_PACKING_RULE = KeepRule(1.0, 0.0, True)
# The fewest texels (area) a repack leaves a chart: 2 x 2, what a bilinear
# lookup reads; a chart already smaller keeps its size. The scale bounds are
# relative to the median chart, so without it a flat chart shrinks again at
# every stage of a multi-stage refinement.
MIN_CHART_TEXELS = 4.0
# The share of the atlas texel_floor expects the repacked charts to cover
# (the packer reaches 84-95% on the bundled scenes, docs/packer.md): lower
# than reached, so a small chart ends at or above the floor.
FLOOR_PACKING = 0.8


def triangle_texels(uvs, triangles, shape):
    """(rows, cols), each (T, 4): the texels under four points inside each
    triangle (its centroid and the midpoints towards its corners)."""
    height, width = shape
    corners = uvs[triangles].astype(np.float64)
    centroid = corners.mean(axis=1, keepdims=True)
    points = np.concatenate([centroid, 0.5 * (corners + centroid)], axis=1)
    cols = np.clip(np.floor(points[..., 0] * width), 0, width - 1).astype(np.int64)
    rows = np.clip(np.floor((1.0 - points[..., 1]) * height), 0, height - 1).astype(np.int64)
    return rows, cols


def signed_areas(uvs, triangles):
    """Signed UV area per triangle (counter-clockwise positive), float64."""
    a, b, c = (uvs[triangles[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def chart_areas(uvs, triangles, charts, count):
    """(count,) each chart's UV area: its triangles' |signed_areas| summed."""
    return np.bincount(charts, weights=np.abs(signed_areas(uvs, triangles)), minlength=count)


def triangle_samples(uvs, triangles, field):
    """A texel field (H, W[, ...]) read at each triangle's four points
    (triangle_texels): (T, 4[, ...]), and each triangle's area in texels (T,)."""
    rows, cols = triangle_texels(uvs, triangles, field.shape[:2])
    texels = np.abs(signed_areas(uvs, triangles)) * field.shape[0] * field.shape[1]
    return field[rows, cols], texels


def triangle_energy(uvs, triangles, energy):
    """Gradient energy each triangle covers: the mean energy at its four
    points (triangle_texels) times its area in texels."""
    samples, texels = triangle_samples(uvs, triangles, energy)
    return samples.astype(np.float64).mean(axis=1) * texels


def _window(values, mask, reduce, fill):
    """3x3 min or max (reduce: np.minimum or np.maximum) of `values` over
    covered texels (uncovered ones read as `fill`), separably; 0 outside
    the mask."""
    out = np.pad(np.where(mask, values, values.dtype.type(fill)), 1, constant_values=fill)
    out = reduce(reduce(out[:-2], out[1:-1]), out[2:])
    out = reduce(reduce(out[:, :-2], out[:, 1:-1]), out[:, 2:])
    return np.where(mask, out, out.dtype.type(0))


def opening(values, mask):
    """Morphological opening (3x3 min, then 3x3 max) over covered texels: the
    smooth part of a texel field. A feature at most two texels wide, like a
    shadow edge in the gradient map or the luminance slope across it,
    vanishes; a level that holds over three texels stays."""
    eroded = _window(values, mask, np.minimum, np.inf)
    return _window(eroded, mask, np.maximum, -np.inf)


def texel_luminance(lightmap):
    """(H, W) float32 luminance of a (H, W[, C]) lightmap (one channel: itself)."""
    image = np.asarray(lightmap, np.float32)
    lum = image if image.ndim == 2 else image[..., 0] if image.shape[2] == 1 else image[..., :3] @ LUMA
    return lum.astype(np.float32)


def luminance_slope(lightmap, mask):
    """|grad L| per covered texel (L the lightmap's luminance, per texel),
    from the differences to its covered neighbours (0 where it has none)."""
    lum = texel_luminance(lightmap)
    slope = []
    for axis in (0, 1):
        head = [slice(None)] * 2
        tail = [slice(None)] * 2
        head[axis], tail[axis] = slice(1, None), slice(None, -1)
        both = mask[tuple(head)] & mask[tuple(tail)]
        step = np.where(both, np.abs(lum[tuple(head)] - lum[tuple(tail)]), np.float32(0))
        total, count = np.zeros(lum.shape, np.float32), np.zeros(lum.shape, np.float32)
        total[tuple(head)] += step
        total[tuple(tail)] += step
        count[tuple(head)] += both
        count[tuple(tail)] += both
        slope.append(total / np.maximum(count, 1))
    return np.where(mask, np.hypot(*slope), np.float32(0))


def texel_weights(uvs, triangles, world_areas):
    """(T,) the surface a texel of each triangle covers (world area over UV
    area), relative to the layout's mean (sum of world areas over sum of UV
    areas): 1 everywhere on a layout of uniform texel density. A texel's
    error counts on the surface it covers, so a chart whose texels are
    already small (a layout refined before) earns less from the same
    gradient energy. Triangles of zero UV area get 1 (they cover no texel)."""
    uv_area = np.abs(signed_areas(uvs, triangles))
    world = np.abs(np.asarray(world_areas, np.float64))
    live = uv_area > 0
    mean = world[live].sum() / uv_area[live].sum() if live.any() else 0.0
    if not mean > 0:
        return np.ones(len(uv_area))
    return np.where(live, world / np.maximum(uv_area, 1e-300) / mean, 1.0)


def chart_errors(uvs, triangles, charts, energy, lightmap=None, mask=None, smooth_term=None, world_areas=None):
    """(edge, smooth, area), each (C,): the error model's terms per chart at
    the input's scale (texel error units) and the chart's UV area.

    edge: the gradient energy above its smooth part (`opening`) times
    EDGE_ERROR. smooth: the smooth part times CURVATURE_ERROR, plus, with a
    lightmap, the chart's mean smooth luminance slope times its border
    length in texels times BORDER_ERROR; both times SMOOTH_WEIGHT. Without
    a lightmap the slope term is 0 (the gradient map is blind to linear
    light). Sums over a triangle's texels use its four points
    (`triangle_texels`). smooth_term False (default: SMOOTH_TERM): edge is
    the whole gradient energy, unscaled, and smooth is 0. world_areas (T,)
    the triangles' surface areas: each triangle's sums count in surface
    units (times `texel_weights`); None: the input's texel density is taken
    as uniform (as Smart UV Project and Lightmap Pack make it)."""
    shape = energy.shape
    count = int(charts.max()) + 1 if len(charts) else 0
    area = chart_areas(uvs, triangles, charts, count)
    weight = None if world_areas is None else texel_weights(uvs, triangles, world_areas)

    def per_chart(field):
        sums = triangle_energy(uvs, triangles, field)
        return np.bincount(charts, weights=sums if weight is None else sums * weight, minlength=count)
    if not (SMOOTH_TERM if smooth_term is None else smooth_term):
        return per_chart(energy), np.zeros(count), area
    if mask is None:
        mask = energy > 0
    energy = np.where(mask, energy, 0).astype(np.float32)
    flat = opening(energy, mask)
    edge = EDGE_ERROR * per_chart(energy - flat)
    smooth = CURVATURE_ERROR * per_chart(flat)
    if lightmap is not None:
        slope = opening(luminance_slope(lightmap, mask), mask)
        slope_sum = per_chart(slope)
        texels = area * shape[0] * shape[1]
        mean_slope = np.where(texels > 0, slope_sum / np.maximum(texels, 1e-300), 0.0)
        _, perimeter = chart_outlines(uvs, triangles, charts, shape, snap=CHART_TOLERANCE)
        smooth = smooth + BORDER_ERROR * mean_slope * perimeter
    return edge, SMOOTH_WEIGHT * smooth, area


def smooth_share(uvs, triangles, charts, energy, lightmap, mask, world_areas=None):
    """The share of a layout's predicted error in its smooth light: the
    chart model with its smooth term (chart_errors, smooth_term=True), whose
    border slope term the gradient energy does not see, over the model's
    whole error. That part falls with the texel area (1/s^2), whatever a
    stretch does across the light changes. 0 without a lightmap."""
    edge, smooth, _ = chart_errors(uvs, triangles, charts, energy, lightmap, mask, smooth_term=True,
                                   world_areas=world_areas)
    total = float(edge.sum() + smooth.sum())
    return float(smooth.sum()) / total if total > 0 else 0.0


def _scales_at(edge, smooth, area, lam):
    """Each chart's minimiser of edge / s + smooth / s^2 + lam area s^2: the
    root of g(s) = 2 lam area s^4 - edge s - 2 smooth. g is convex on s > 0
    and negative below the root, so Newton's method from a start above the
    root (where 2 lam area s^4 is at least twice each of the other terms)
    falls onto it monotonically."""
    k = 2.0 * lam * area
    s = np.maximum(np.cbrt(2.0 * edge / k), (4.0 * smooth / k) ** 0.25)
    for _ in range(12):  # the start is within a factor 2 of the root: quadratic convergence
        s = s - (k * s ** 4 - edge * s - 2.0 * smooth) / (4.0 * k * s ** 3 - edge)
    return s


def _budget_scales(edge, smooth, area):
    """Scales minimising sum(edge / s + smooth / s^2) for the budget
    sum(area s^2) = sum(area) (Lagrange: one lam for all charts), by
    bisection on log lam. Every chart needs edge > 0 and area > 0."""
    budget = area.sum()
    lo, hi = -200.0, 200.0
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        used = (area * _scales_at(edge, smooth, area, np.exp(mid)) ** 2).sum()
        lo, hi = (mid, hi) if used > budget else (lo, mid)
    return _scales_at(edge, smooth, area, np.exp(0.5 * (lo + hi)))


def optimal_scales(edge, smooth, area, min_scale=0.5, max_scale=2.0):
    """Relative linear scale per chart: the model's optimum for the input's
    texel budget, with the edge density floored at ENERGY_FLOOR of its mean,
    then clamped to [min_scale, max_scale] times the median chart (the
    packer's global scale sets the level). Without smooth light this is
    (edge density)^(1/3) over its median, clamped. Charts of zero area get 1."""
    edge, smooth, area = (np.asarray(x, np.float64) for x in (edge, smooth, area))
    scales = np.ones(len(area))
    live = area > 0
    if not live.any():
        return scales
    mean = edge[live].sum() / area[live].sum()
    if not mean > 0:  # no light change anywhere: the floor comes from the smooth light
        mean = smooth[live].sum() / area[live].sum()
    if not mean > 0:
        return scales
    if not (smooth[live] > 0).any():  # the edge term alone: its closed form
        with np.errstate(divide="ignore", invalid="ignore"):
            density = np.where(live, edge / np.maximum(area, 1e-300), 0.0)
        raw = np.cbrt(density + ENERGY_FLOOR * float(np.average(density, weights=area)))
        return np.clip(raw / np.median(raw[live]), min_scale, max_scale)
    free = _budget_scales(edge[live] + ENERGY_FLOOR * mean * area[live], smooth[live], area[live])
    scales[live] = np.clip(free / np.median(free), min_scale, max_scale)
    return scales


def predicted_error(edge, smooth, scales):
    """The model's error at `scales` relative to the input's (1.0 = the same)."""
    total = edge.sum() + smooth.sum()
    if not total > 0:
        return 1.0
    s = np.maximum(np.asarray(scales, np.float64), 1e-12)
    return float((edge / s + smooth / (s * s)).sum() / total)


def chart_scales(uvs, triangles, charts, energy, min_scale=0.5, max_scale=2.0, lightmap=None, mask=None,
                 smooth_term=None, world_areas=None):
    """Relative linear scale per chart from the error model above
    (`chart_errors`, `optimal_scales`); also returns (edge, smooth, area)."""
    edge, smooth, area = chart_errors(uvs, triangles, charts, energy, lightmap, mask, smooth_term, world_areas)
    return optimal_scales(edge, smooth, area, min_scale, max_scale), edge, smooth, area


def chart_outlines(uvs, triangles, charts, shape, snap=0.0):
    """(C,) each chart's area and boundary length in texels. Edges are matched
    by their end points, exactly (snap 0: the charts must be bit-exact, as
    pack_charts' output is) or rounded to multiples of `snap` in UV units."""
    height, width = shape
    corners = uvs[triangles].astype(np.float64)
    if snap > 0:
        corners = np.round(corners / snap) * snap
    corners = corners * (width, height)  # (T, 3, 2) texel space
    start = corners.reshape(-1, 2)
    end = np.roll(corners, -1, axis=1).reshape(-1, 2)
    # An edge's key: its chart and its end points in a fixed order.
    forward = (start[:, 0] < end[:, 0]) | ((start[:, 0] == end[:, 0]) & (start[:, 1] <= end[:, 1]))
    low = np.where(forward[:, None], start, end)
    high = np.where(forward[:, None], end, start)
    edge_chart = np.repeat(charts, 3)
    keys = np.column_stack([edge_chart.astype(np.float64), low, high])
    inverse, counts = group_rows(keys)
    outline = counts[inverse] == 1
    count = int(charts.max()) + 1 if len(charts) else 0
    length = np.hypot(*(end - start).T)
    perimeter = np.bincount(edge_chart[outline], weights=length[outline], minlength=count)
    area = np.bincount(charts, weights=np.abs(signed_areas(uvs, triangles)) * width * height, minlength=count)
    return area, perimeter


def padded_utilisation(area, perimeter, padding, shape):
    """The atlas fraction the charts take with half the padding around each
    (the area of each chart grown by padding / 2: area + perimeter * padding / 2
    + pi padding^2 / 4, exact for convex charts): how densely a layout is
    packed for its padding, whatever the charts' sizes and however they sit
    on the texel grid."""
    grown = area + perimeter * (0.5 * padding) + np.pi * padding * padding / 4.0
    return float(grown[area > 0].sum() / (shape[0] * shape[1]))


def signal_scales(source_uvs, triangles, energy, min_scale, max_scale, lightmap=None, mask=None, world_areas=None):
    """repack's charts of `source_uvs` and their relative linear scales by
    their signal, with the model's terms: (charts (T,), scales (C,), edge,
    smooth). The repack packs the charts at these scales times one global
    scale (or at their square roots: `repack`); a chart keeps at least
    MIN_CHART_TEXELS texels of the map `energy` is (texel_floor)."""
    charts = find_charts(source_uvs, triangles, tolerance=CHART_TOLERANCE)
    scales, edge, smooth, area = chart_scales(source_uvs, triangles, charts, energy, min_scale, max_scale,
                                              lightmap, mask, world_areas=world_areas)
    height, width = np.shape(energy)[:2]
    return charts, texel_floor(scales, np.asarray(area, np.float64) * height * width, height * width), edge, smooth


def repack(source_uvs, refined_uvs, triangles, energy, resolution, padding, min_scale, max_scale, progress=None,
           lightmap=None, mask=None, world_areas=None, max_stretch=1.0, signal=None, source_tensors=None,
           own_packing=False):
    """Scale the charts of `refined_uvs` by their signal (measured on the
    source layout `source_uvs`, where `energy` and `lightmap` were baked;
    `mask` its coverage; `world_areas` the triangles' surface areas, or
    None for a source of uniform texel density) and pack them into one
    atlas. With a lightmap and max_stretch > 1 a second packing stretches
    each chart across its light changes (lmrefine.stretch) and is kept when
    the model predicts less error for it and it packs about as densely as
    the input; when it does not, a third turns the sheared stretched charts
    to their smallest boxes, a fourth (where a density rule refused those:
    not for own_packing) stretches each chart along its u or v axis instead
    (rectangles stay rectangles), and a fifth stretches each chart by the
    square root of its factor. A packing the model takes but the density
    rule refuses is packed again at the square roots of the scales (and
    judged the same way). `signal`: signal_scales' result for these arguments, and
    `source_tensors`: stretch.source_tensors' for lightmap, mask and
    source_uvs, when the caller has them. `own_packing`: refined_uvs's
    charts were packed at one scale by this library (the re-chart route),
    so OWN_PACKING_RULE replaces REQUIRED_GAIN and MIN_UTILISATION_KEPT.
    Returns (uvs, report); uvs is None when the packed layout is not better
    than `refined_uvs` by the error model (the report says so)."""
    charts, scales, edge, smooth = signal if signal is not None else signal_scales(
        source_uvs, triangles, energy, min_scale, max_scale, lightmap, mask, world_areas)
    # No packing can scale the charts beyond filling the whole atlas, gutters
    # aside: when the model's error at that scale is no clear gain, the
    # packer need not run (a single chart filling its atlas, for example).
    area_refined = chart_areas(refined_uvs, triangles, charts, len(scales))
    largest = 1.0 / np.sqrt(max(float((area_refined * scales ** 2).sum()), 1e-300))
    best = predicted_error(edge, smooth, largest * scales)
    rule = OWN_PACKING_RULE if own_packing else callers_rule()
    if best >= rule.required_gain:
        return None, {"charts": int(len(scales)), "used": False, "predicted_error": best,
                      "own_packing": bool(own_packing),
                      "reason": f"even filling the whole atlas the error model predicts {best:.3f} of the unpacked "
                                f"error at best (a repack needs below {rule.required_gain:g})"}
    stretched = None
    if max_stretch > 1.0 and lightmap is not None:
        stretched = _stretch_candidate(source_uvs, refined_uvs, triangles, charts, lightmap, mask, resolution,
                                       max_stretch, source_tensors)
    shares = None
    if lightmap is not None and max_stretch > 1.0:
        def shares(uvs):
            covered = coverage_mask(source_uvs, triangles, resolution) if mask is None else mask
            return axis_shares(lightmap, covered, source_uvs, uvs, triangles, charts, source_tensors)
    packed, report = _packing_at(scales, refined_uvs, triangles, charts, edge, smooth, stretched, resolution,
                                 padding, progress, rule, shares, max_stretch)
    report["own_packing"] = bool(own_packing)
    if not report["used"] and report.get("predicted_error", 1.0) < rule.required_gain:
        # Refused for its density alone: the signal's spread of chart sizes
        # costs more gutter than the input's. The scales half way to uniform
        # (in log scale) cost less, so the choice is not all or nothing.
        soft_packed, soft = _packing_at(np.sqrt(scales), refined_uvs, triangles, charts, edge, smooth, stretched,
                                        resolution, padding, _reports_done(progress), rule, shares, max_stretch)
        softened = {"used": soft["used"], "refused": {
            key: report[key] for key in ("predicted_error", "padded_utilisation_before", "padded_utilisation_after")}}
        if soft["used"]:
            return soft_packed, {**soft, "own_packing": bool(own_packing), "softened": softened}
        report["softened"] = softened
    return (packed if report["used"] else None), report


def texel_floor(scales, texels, atlas_texels):
    """`scales` (relative, the packer sets the level) raised where a chart
    of `texels` texels at scale 1 would keep fewer than MIN_CHART_TEXELS (or
    shrink, if it has fewer already). The level is estimated as the one at
    which the charts cover FLOOR_PACKING of the atlas (`atlas_texels`), or as
    many texels as they do now if that is more; charts of no area are left
    as they are."""
    texels = np.asarray(texels, np.float64)
    scales = np.asarray(scales, np.float64)
    live = texels > 0
    if not live.any():
        return scales
    kept = np.ones_like(scales)  # the linear scale a chart may shrink to
    kept[live] = np.sqrt(np.minimum(1.0, MIN_CHART_TEXELS / texels[live]))
    covered = max(float(texels[live].sum()), FLOOR_PACKING * float(atlas_texels))
    floored = scales.copy()
    for _ in range(4):  # raising a small chart barely moves the level
        level = np.sqrt(covered / (texels[live] * floored[live] ** 2).sum())
        floored = np.where(live, np.maximum(floored, kept / level), floored)
    return floored


def _reports_done(progress):
    """The progress callback of a packing after the first: it reports its
    stage as done (the caller's bar does not run back) and passes the
    caller's cancel on."""
    return None if progress is None else (lambda fraction, stage: progress(1.0, stage))


def _packing_at(scales, refined_uvs, triangles, charts, edge, smooth, stretched, resolution, padding, progress,
                rule, shares=None, max_stretch=1.0):
    """repack's packing of `refined_uvs`'s charts at relative `scales` (and of
    the `stretched` candidate, when given) and its judgement by `rule` (a
    KeepRule): (packed uvs, report). `shares(uvs)`: axis_shares in the frame
    of a layout of these charts, or None (no lightmap, or no stretch allowed:
    the fill grows charts evenly only); a chart's growth along one axis is
    held to (max_stretch / its chart stretch)^2, the texel aspect the chart
    stretch may give."""
    try:
        (packed, pack_report), stretched_pack = _pack_both(
            refined_uvs, None if stretched is None else stretched["uvs"],
            triangles, charts, scales, resolution, padding, progress)
    except ValueError as error:  # the charts do not fit at a usable scale: keep the unpacked layout
        return None, {"charts": int(len(scales)), "used": False, "reason": str(error)}
    final = pack_report["chart_scales"]  # linear scale of each chart against refined_uvs
    # Areas and outlines: the packed charts are bit-exact; the input's outlines are theirs unscaled.
    area_after, perimeter_out = chart_outlines(packed, triangles, charts, resolution)
    area_before, _ = chart_outlines(refined_uvs, triangles, charts, resolution)
    # The input's density with its gutters: its outlines are the packed ones unscaled (not so once stretched).
    padded_before = padded_utilisation(area_before, perimeter_out / final, padding, resolution)
    # Predicted error of the packed layout relative to refined_uvs (1.0 = the same), both terms.
    predicted = predicted_error(edge, smooth, final)
    stretch_report = None
    if stretched is not None:
        def packings():
            """(kind, charts turned, stretch factors, edge-term factors, packing) of each
            stretched candidate, made only when asked for: the stretched charts as they are
            (packed beside the unstretched ones); when that is refused, the sheared ones among
            them turned to their smallest boxes; then, where a density rule refused those, each
            chart stretched along its u or v axis (a chart's box keeps its shape); then each
            chart stretched by the square root of its factor (a stretch costs packing density:
            half of it costs less)."""
            from . import stretch

            def pack(uvs):
                return _pack_or_none(uvs, triangles, charts, scales, resolution, padding, _reports_done(progress))

            factor, none = stretched["factor"], np.zeros(len(scales), bool)
            yield "main", none, factor, stretched["edge_factor"], stretched_pack
            turned_uvs, turned = stretch.turn_to_smallest_boxes(stretched["uvs"], triangles, charts, factor > 1.0)
            if turned.any():
                yield "turned", turned, factor, stretched["edge_factor"], pack(turned_uvs)
            # A fallback for the density rule alone: the main direction is the model's optimum, and
            # where no density rule refuses it (the route's own packing) the stretch along the axes
            # won only by model margins of 0.5-2% and measured worse (docs/refiner.md).
            if rule.min_utilisation > 0:
                axis = _axis_candidate(stretched, refined_uvs, triangles, charts, resolution, max_stretch)
                if axis is not None:
                    yield "axes", none, axis["factor"], axis["edge_factor"], pack(axis["uvs"])
            half = np.sqrt(factor)
            yield ("half", none, half, stretch.edge_factor(half, stretched["share"]),
                   pack(stretch.stretch_charts(refined_uvs, triangles, charts, half, stretched["direction"])))

        stretch_report, kept = _judge_stretch(stretched, packings(), triangles, charts, resolution, padding,
                                              final, predicted, padded_before, rule)
        if kept is not None:
            packed, pack_report, final, area_after, perimeter_out, predicted = kept
    # The space the packing left: the charts the model counts most grow into it.
    grown, grown_report, factors, ratio, fill_report = grow_into_free_space(
        packed, triangles, charts, edge, smooth, final, resolution, padding, _reports_done(progress), area_after,
        None if shares is None else (lambda: shares(packed)), _one_way_limit(stretch_report, max_stretch, len(scales)))
    if grown is not None:
        grown_area, perimeter_out = chart_outlines(grown, triangles, charts, resolution)
        fill_report["texel_area"] = float(grown_area.sum() / max(float(area_after.sum()), 1e-300))
        fill_report["utilisation_before"] = float(pack_report["utilisation"])
        packed, area_after = grown, grown_area
        pack_report = {**grown_report, "global_scale": pack_report["global_scale"],
                       "utilisation_input": pack_report["utilisation_input"],
                       "area_utilisation_input": pack_report["area_utilisation_input"]}
        final = final * factors
        predicted *= ratio
    report = {
        "charts": int(len(scales)),
        "chart_scales": np.asarray(final, np.float64),
        "signal_scales": scales,
        "global_scale": float(pack_report["global_scale"]),
        "utilisation_before": float(pack_report["utilisation_input"]),
        "utilisation_after": float(pack_report["utilisation"]),
        "area_utilisation_before": float(pack_report["area_utilisation_input"]),
        "area_utilisation_after": float(pack_report["area_utilisation"]),
        "padding": float(padding),
        "padded_utilisation_before": padded_before,
        "padded_utilisation_after": padded_utilisation(area_after, perimeter_out, padding, resolution),
        "placement": pack_report["placement"],
        "predicted_error": predicted,
        "smooth_fraction": float(smooth.sum() / max(edge.sum() + smooth.sum(), 1e-300)),
        "stretch": stretch_report,
        "fill": fill_report,
    }
    # The model must promise a clear gain, and the packed atlas must be about
    # as dense as the input for its padding (the model does not see what the
    # gutters cost).
    # Density of the charts grown by half the padding, not texels touched: a
    # chart off the texel grid touches more texels than the same chart on it,
    # and shrunk charts need the same gutters (docs/refiner.md).
    report["used"] = bool(predicted < rule.required_gain and report["padded_utilisation_after"]
                          >= rule.min_utilisation * report["padded_utilisation_before"])
    return packed, report


def _one_way_limit(stretch_report, max_stretch, count):
    """(C,) the most each chart may grow along one axis: a chart stretched by
    a (the kept chart stretch's factor) has texels a^2 times longer one way
    than the other, and max_stretch^2 is what the chart stretch may give."""
    stretched = np.ones(count)
    if stretch_report is not None and stretch_report["used"]:
        stretched = np.asarray(stretch_report["chart_stretch"], np.float64)
    return (float(max_stretch) / stretched) ** 2


def _stretch_candidate(source_uvs, refined_uvs, triangles, charts, lightmap, mask, resolution, max_stretch,
                       source_tensors=None):
    """`refined_uvs` with its charts stretched across their light changes
    (lmrefine.stretch), with each chart's factor, edge-term factor and
    light-change weight; None when no chart stretches."""
    from . import stretch

    if mask is None:
        mask = coverage_mask(source_uvs, triangles, resolution)
    tensors = stretch.chart_tensors(lightmap, mask, source_uvs, refined_uvs, triangles, charts, source_tensors)
    factor, direction, share, weight = stretch.stretch_factors(tensors, refined_uvs, triangles, charts, resolution,
                                                               max_stretch)
    if not (factor > 1.0).any():
        return None
    return {"uvs": stretch.stretch_charts(refined_uvs, triangles, charts, factor, direction), "factor": factor,
            "tensors": tensors,
            "edge_factor": stretch.edge_factor(factor, share), "weight": weight, "direction": direction,
            "share": share,
            "report": {"charts_stretched": int((factor > 1.0).sum()), "chart_stretch": factor,
                       "largest_stretch": float(factor.max())}}


def _axis_candidate(stretched, refined_uvs, triangles, charts, resolution, max_stretch):
    """The `stretched` candidate's charts stretched along their u or v axes
    instead (rectangles stay rectangles; stretch.axis_stretch_factors), its
    factors and edge-term factors; None when no chart stretches or the
    layout is the main stretch's (light changes along the axes already).
    Made only where the stretch along the main directions was refused."""
    from . import stretch

    factor, direction, edge_factor = stretch.axis_stretch_factors(
        stretched["tensors"], stretched["weight"], refined_uvs, triangles, charts, resolution, max_stretch)
    if not (factor > 1.0).any():
        return None
    uvs = stretch.stretch_charts(refined_uvs, triangles, charts, factor, direction)
    if np.array_equal(uvs, stretched["uvs"]):
        return None
    return {"uvs": uvs, "factor": factor, "edge_factor": edge_factor}


def _judge_stretch(stretched, packings, triangles, charts, resolution, padding, final, predicted, padded_before,
                   rule):
    """The stretch's report and, when a stretched packing is kept, its (uvs,
    pack report, chart scales, chart areas, perimeters, predicted error):
    the first candidate that packs as densely as the input and predicts
    less error than the unstretched packing, by `rule` (a KeepRule; with
    rule.lowest every candidate is judged and the lowest prediction kept).
    `packings` yields each candidate's (kind, charts turned (C,) bool,
    stretch factors, edge-term factors, packing or None when it does not
    fit) and is read no further than the one kept unless rule.lowest. `final`,
    `predicted` and `padded_before` are the unstretched packing's scales
    and predicted error and the input's padded density."""
    report = {"used": False, "predicted_error_unstretched": predicted, "charts_turned": 0, **stretched["report"]}
    weight = stretched["weight"]
    before = (weight / np.maximum(np.asarray(final, np.float64), 1e-12)).sum()
    judged, kept = [], None
    for kind, turned, factor, edge_factor, packing in packings:
        entry = {"kind": kind, "charts_turned": int(turned.sum()), "largest_stretch": float(factor.max()),
                 "fits": packing is not None}
        judged.append(entry)
        if packing is None:
            continue
        uvs, pack_report = packing
        scales = np.asarray(pack_report["chart_scales"], np.float64)
        area, perimeter = chart_outlines(uvs, triangles, charts, resolution)
        # The same density rule as the unstretched packing (the model does not see the gutters).
        entry["padded_utilisation"] = padded_utilisation(area, perimeter, padding, resolution)
        entry["dense"] = bool(entry["padded_utilisation"] >= rule.min_utilisation * padded_before)
        # The stretch's edge error over the unstretched packing's, each chart weighted by its light
        # changes as the structure tensor measures them.
        after = (weight * edge_factor / np.maximum(scales, 1e-12)).sum()
        entry["predicted_error"] = predicted * (float(after / before) if before > 0 else 1.0)
        if entry["dense"] and entry["predicted_error"] < (predicted if kept is None else kept[-1]):
            kept = (uvs, pack_report, scales, area, perimeter, entry["predicted_error"])
            report.update(used=True, kind=kind, charts_turned=entry["charts_turned"], chart_stretch=factor,
                          charts_stretched=int((factor > 1.0).sum()), largest_stretch=entry["largest_stretch"])
            if not rule.lowest:
                break
    report["candidates"] = judged
    report["predicted_error"] = min((e["predicted_error"] for e in judged if "predicted_error" in e), default=None)
    if kept is not None:
        report["predicted_error"] = kept[-1]
    elif not any(e["fits"] for e in judged):
        report["reason"] = "the stretched charts do not fit"
    elif not any(e.get("dense") for e in judged):
        report["reason"] = "the stretched charts would pack less densely than the input (with their gutters)"
    else:
        best = min(e["predicted_error"] for e in judged if e.get("dense"))
        report["reason"] = f"the error model predicts {best:.3f} stretched against {predicted:.3f}"
    return report, kept


# grow_into_free_space: the charts tried (largest model term first), the
# growth a chart must fit to be grown at all, the most it may grow (linear),
# and the bisection steps between the two.
FILL_CANDIDATES = 4
FILL_SMALLEST_GROWTH = 1.05
FILL_MAX_GROWTH = 2.0
FILL_STEPS = 3
# The fill is kept only when it lowers the model's error by this share, and
# a chart is tried only when growing it FILL_MAX_GROWTH times could: a
# smaller gain is below what placing the charts anew moves a row by, and on
# layouts of thousands of small charts each try costs a tenth of a second.
FILL_MIN_GAIN = 0.01


def grow_into_free_space(packed, triangles, charts, edge, smooth, scales, resolution, padding, progress=None,
                         areas=None, shares=None, one_way_limit=None):
    """The charts of a `packed` layout (at linear `scales` against the layout
    the model's `edge` and `smooth` terms refer to) grown one at a time into
    the atlas space the packing left free, every other chart keeping its
    size: of the FILL_CANDIDATES charts whose model terms are largest, those
    whose growth could lower the model's error by FILL_MIN_GAIN, each by the
    largest factor (bisected) at which the charts still pack at the
    packing's own scale (pack_charts' fixed_scale). Returns (uvs, pack
    report, factors (C,), the predicted error's ratio, report), or (None,
    None, ones, 1.0, report) when no chart grew or the gain is below
    FILL_MIN_GAIN (the report's `ratio` says what it would have been).
    `areas`: the packed charts' texel areas (chart_outlines'), when the
    caller has them. `shares()`: each chart's share of its light changes
    across the u axis of `packed` (axis_shares), or None; given, the
    charts that could not grow evenly then grow along one axis of their
    frame where that fits (_grow_one_axis), after the others grew, each by
    at most its `one_way_limit` (C,) (None: FILL_MAX_GROWTH): a
    factor g along u divides the chart's edge term by g for that share
    alone, and its smooth term (per texel area) by g. A chart grown one way
    counts in the returned factors by its linear scale of area, sqrt(g)."""
    s = np.maximum(np.asarray(scales, np.float64), 1e-12)
    along = [np.ones(len(s)), np.ones(len(s))]  # growth along u and along v, on top of the even growth
    share_u = np.full(len(s), 0.5)

    def model(f):
        edge_factor = share_u / (f * along[0]) + (1.0 - share_u) / (f * along[1])
        return float((edge / s * edge_factor + smooth / (s * f) ** 2 / (along[0] * along[1])).sum())

    terms = edge / s + smooth / (s * s)  # each chart's model term at the packing's sizes
    factors = np.ones(len(s))
    report = {"charts_grown": 0, "charts_grown_one_way": 0, "packings": 0}
    before = float(terms.sum())
    if not before > 0:
        return None, None, factors, 1.0, report
    kept = None

    def fits(trial, uvs=packed):
        report["packings"] += 1
        return _pack_or_none(uvs, triangles, charts, trial, resolution, padding, progress, fixed_scale=1.0)

    def gain(c, g):
        """The model's error chart c's growth by g takes off."""
        return edge[c] / s[c] * (1 - 1 / g) + smooth[c] / s[c] ** 2 * (1 - 1 / g ** 2)

    # No chart grows past the atlas area the charts leave (gutters aside): a
    # bound on what each try can gain, so tries that cannot make a fill
    # worth keeping are not made (a try past it would not fit either).
    shape = (int(resolution),) * 2 if np.ndim(resolution) == 0 else tuple(resolution)
    if areas is None:
        areas = chart_outlines(packed, triangles, charts, shape)[0]
    area = np.asarray(areas, np.float64) / float(shape[0] * shape[1])
    free = max(1.0 - float(area.sum()), 0.0)

    def largest(c):
        return min(FILL_MAX_GROWTH, np.sqrt(1.0 + free / area[c])) if area[c] > 0 else FILL_MAX_GROWTH

    needed = FILL_MIN_GAIN * before
    order = [c for c in np.argsort(-terms, kind="stable")[:FILL_CANDIDATES] if gain(c, FILL_MAX_GROWTH) >= needed]
    gained, blocked = 0.0, []
    for k, c in enumerate(order):
        later = sum(gain(d, largest(d)) for d in order[k + 1:])  # what the charts after c could add
        if gained + gain(c, largest(c)) + later < needed:
            break  # a fill that cannot be kept: no more placements
        if largest(c) < FILL_SMALLEST_GROWTH:
            continue  # no room for the smallest growth
        trial = factors.copy()
        trial[c] *= FILL_SMALLEST_GROWTH
        result = fits(trial)
        if result is None:
            blocked.append(c)
            continue
        low, high = FILL_SMALLEST_GROWTH, FILL_MAX_GROWTH
        for _ in range(FILL_STEPS):
            if gained + gain(c, min(high, largest(c))) + later < needed:
                break
            g = np.sqrt(low * high)
            trial[c] = factors[c] * g
            grown = fits(trial)
            if grown is None:
                high = g
            else:
                low, result = g, grown
        factors[c] *= low
        gained += gain(c, low)
        free = max(free - area[c] * (low * low - 1.0), 0.0)
        kept = result
    if blocked and shares is not None:
        share_u = np.clip(np.asarray(shares(), np.float64), 0.0, 1.0)
        layout = packed  # with the growths along an axis so far (the even ones are `factors`, packed with it)
        for c in blocked:
            limit = FILL_MAX_GROWTH if one_way_limit is None else min(FILL_MAX_GROWTH, float(one_way_limit[c]))
            growth = _grow_one_axis(c, layout, factors, share_u, edge, smooth, s, area, free, fits, triangles, charts,
                                    gained, needed, limit)
            if growth is None:
                continue
            axis, g, kept, layout = growth
            along[axis][c] = g
            gained += _axis_gain(edge[c], smooth[c], s[c], share_u[c] if axis == 0 else 1.0 - share_u[c], g)
            free = max(free - area[c] * (g - 1.0), 0.0)
    if kept is None:
        return None, None, np.ones(len(s)), 1.0, report
    report["ratio"] = model(factors) / before
    if report["ratio"] > 1 - FILL_MIN_GAIN:
        return None, None, np.ones(len(s)), 1.0, report
    one_way = (along[0] > 1.0) | (along[1] > 1.0)
    grown_charts = np.flatnonzero((factors > 1.0) | one_way)
    report["charts_grown"] = int(len(grown_charts))
    report["charts_grown_one_way"] = int(one_way.sum())
    # Each grown chart named by its lowest triangle, which any numbering of the same charts shares: a
    # chart grown by two fills (the repack's and the triangle stretch's) is counted once from these.
    first = np.full(len(s), len(charts), np.int64)
    np.minimum.at(first, np.asarray(charts, np.int64), np.arange(len(charts), dtype=np.int64))
    report["grown_chart_triangles"] = sorted(int(t) for t in first[grown_charts])
    return kept[0], kept[1], factors * np.sqrt(along[0] * along[1]), report["ratio"], report


def grow_finished_packing(packed, source_uvs, triangles, charts, energy, resolution, padding, lightmap=None,
                          mask=None, world_areas=None, progress=None, errors=None):
    """The charts of `packed`, a packing made after the repack (the triangle
    stretch packs its charts again, at a scale of its own), grown evenly into
    the space it left (grow_into_free_space), the model's terms measured per
    chart on `source_uvs` (where `energy` and `lightmap` were baked, `mask`
    its coverage) and its scales read from the charts' areas: (uvs or None,
    report, as grow_into_free_space's with its texel_area). `errors`: the
    (edge, smooth) of chart_errors for these arguments, when the caller has
    them (signal_scales made them for the repack)."""
    if errors is None:
        edge, smooth, area = chart_errors(source_uvs, triangles, charts, energy, lightmap, mask,
                                          world_areas=world_areas)
    else:
        edge, smooth = errors
        area = chart_areas(source_uvs, triangles, charts, len(edge))  # as chart_errors measures it
    before = chart_areas(packed, triangles, charts, len(edge))
    scales = np.sqrt(before / np.maximum(np.asarray(area, np.float64), 1e-300))
    # Evenly only: a growth along one axis would stretch the triangles past the stretch's bound.
    grown, _, _, _, report = grow_into_free_space(packed, triangles, charts, edge, smooth, scales, resolution,
                                                  padding, progress)
    if grown is not None:
        report["texel_area"] = float(np.abs(signed_areas(grown, triangles)).sum() / max(float(before.sum()), 1e-300))
    return grown, report


def _axis_gain(edge, smooth, scale, share, g):
    """The model's error a chart's growth by g along one axis takes off:
    `share` of its light changes lie across that axis."""
    return (edge / scale * share + smooth / scale ** 2) * (1.0 - 1.0 / g)


def _grow_one_axis(c, layout, factors, share_u, edge, smooth, s, area, free, fits, triangles, charts, gained,
                   needed, limit=FILL_MAX_GROWTH):
    """Chart c of `layout` grown along the u or the v axis of its frame by
    the largest factor (bisected, up to `limit` and the atlas area left
    `free`) at which the charts still pack at the packing's scale
    (`fits`), the axis whose growth the model credits more: (axis, factor,
    packing, the grown layout), or None when neither grows by
    FILL_SMALLEST_GROWTH or could make a fill worth keeping (`gained` +
    its gain below `needed`)."""
    best, corners = None, np.unique(np.asarray(triangles)[np.asarray(charts) == c])
    largest = min(limit, 1.0 + free / area[c]) if area[c] > 0 else limit
    for axis in (0, 1):
        share = share_u[c] if axis == 0 else 1.0 - share_u[c]

        def gain(g):
            return _axis_gain(edge[c], smooth[c], s[c], share, g)

        if largest < FILL_SMALLEST_GROWTH or gained + gain(largest) < needed:
            continue
        grown = _axis_grown(layout, corners, axis, FILL_SMALLEST_GROWTH)
        result = fits(factors, grown)
        if result is None:
            continue
        low, high, kept = FILL_SMALLEST_GROWTH, largest, (result, grown)
        for _ in range(FILL_STEPS):
            if gained + gain(high) < needed:
                break
            g = np.sqrt(low * high)
            grown = _axis_grown(layout, corners, axis, g)
            result = fits(factors, grown)
            if result is None:
                high = g
            else:
                low, kept = g, (result, grown)
        if best is None or gain(low) > best[-1]:
            best = (axis, low, kept[0], kept[1], gain(low))
    return None if best is None else best[:4]


def _axis_grown(uvs, corners, axis, factor):
    """`uvs` with the UVs `corners` (a chart's) scaled by `factor` along `axis` about their mean."""
    out = np.array(uvs, copy=True)
    values = out[corners, axis].astype(np.float64)
    centre = values.mean()
    out[corners, axis] = centre + (values - centre) * factor
    return out


def axis_shares(lightmap, mask, source_uvs, uvs, triangles, charts, source_tensors=None):
    """(C,) each chart's share of its light changes across the u axis of
    layout `uvs` (its structure tensor's uu entry over its trace: 1 where
    the light changes along u alone, 0.5 where it has none; stretch.chart_tensors)."""
    from . import stretch

    tensors = stretch.chart_tensors(lightmap, mask, source_uvs, uvs, triangles, charts, source_tensors)
    trace = tensors[:, 0, 0] + tensors[:, 1, 1]
    return np.where(trace > 0, tensors[:, 0, 0] / np.where(trace > 0, trace, 1.0), 0.5)


def _pack_or_none(uvs, triangles, charts, scales, resolution, padding, progress, fixed_scale=None):
    """pack_charts, or None when the charts do not fit (at `fixed_scale`, when given)."""
    try:
        return pack_charts(uvs, triangles, charts, scales, resolution, padding, progress=progress,
                           fixed_scale=fixed_scale)
    except ValueError:
        return None


def _pack_both(uvs, stretched_uvs, triangles, charts, scales, resolution, padding, progress):
    """pack_charts of `uvs` (its errors raise) and, when given, of
    `stretched_uvs` at the same time in a second thread (the packer is
    mostly serial and releases the GIL; None when it does not fit). Only the
    first reports progress; cancelling it cancels both."""
    if stretched_uvs is None:
        return pack_charts(uvs, triangles, charts, scales, resolution, padding, progress=progress), None
    import threading
    from concurrent.futures import ThreadPoolExecutor

    cancelled = threading.Event()

    def first_progress(fraction, stage):
        keep_going = True if progress is None else progress(fraction, stage)
        if cancels(keep_going):
            cancelled.set()
        return keep_going

    with ThreadPoolExecutor(max_workers=1) as pool:
        future = pool.submit(_pack_or_none, stretched_uvs, triangles, charts, scales, resolution, padding,
                             lambda fraction, stage: not cancelled.is_set())
        try:
            first = pack_charts(uvs, triangles, charts, scales, resolution, padding, progress=first_progress)
        except BaseException:
            cancelled.set()
            raise
        try:
            return first, future.result()
        except Exception:
            if cancelled.is_set():  # the second pack stopped because the first one did
                return first, None
            raise
