"""Chart stretch: more texels across a chart's light changes, fewer along them.

A chart scale (lmrefine.allocation) gives a chart texels in both directions
alike. Shadows of beams, pickets and railings are stripes: the bake blurs a
stripe over the texels across it, and texels along it buy nothing. When a
chart's light changes mostly run one way, stretching the chart across them
by a and squeezing it along them by 1/a keeps its texel area and narrows the
texels where the error is (docs/refiner.md, "Chart stretch").

The direction comes from the structure tensor of the first bake's luminance
gradient, J = sum over the chart's texels of g g^T (g = grad L). With its
eigenvalues l1 >= l2 the chart's light changes split into a part across the
main direction e1 and a part along it, in the ratio sqrt(l1) : sqrt(l2)
(w1 : w2, summing to 1). The edge term of the chart model (error falling
with the texel size across an edge) then changes by the factor

    f(a) = w1 / a + w2 a,

least at a = sqrt(w1 / w2) = (l1 / l2)^(1/4): `stretch_factors` uses that,
bounded by `max_stretch` and by the chart's width, for the charts that hold
more light changes than the mean chart. allocation.repack packs the
stretched charts as a second candidate and keeps it when its edge error,
each chart weighted by sqrt(l1) + sqrt(l2), is lower than the unstretched
packing's and it packs about as densely as the input. When it does not
pack densely enough, the stretched charts that a stretch along a diagonal
sheared are turned to their smallest boxes (`turn_to_smallest_boxes`) and
packed once more; then each chart is stretched along the u or the v axis
of its frame instead (`axis_stretch_factors`: a rectangle stays a
rectangle, for less gain, `tensor_edge_factor`), judged by the same rules.

The triangle stretch (`triangle_stretch`, called by refine_uvs after the
repack) does the same per triangle: each triangle's tensor, averaged with
its neighbours', gives its own stretch and direction; the chart's
triangles are fitted to those shapes together (lmrefine._native._fit_shapes,
least squares), the charts packed again, and `triangle_edge_error` (the
same edge term, per triangle, the packing's scale included) judges it
(docs/refiner.md, "Triangle stretch").
"""

import numpy as np

from . import _native
from .allocation import signed_areas, texel_luminance, triangle_samples

# A chart is never squeezed to fewer texels across than this (its extent
# along the squeezed direction in the layout being stretched): bilinear
# lookup and dilation need a few texels.
MIN_WIDTH_TEXELS = 4.0
# Stretches below this are left out (the packing they would change costs
# more than they can give).
MIN_STRETCH = 1.01
# A stretched chart is turned to its smallest bounding box only when that box
# is at most this share of the box it has (a smaller turn only reshuffles the
# packing).
TURN_GAIN = 0.9


def luminance_gradient(lightmap, mask):
    """(H, W, 2) float32: the luminance gradient (d/du, d/dv) per covered
    texel in texels, each component the mean of the differences to the
    covered neighbours along it (0 where it has none)."""
    lum = texel_luminance(lightmap)
    out = np.zeros(lum.shape + (2,), np.float32)
    # u runs along the columns; v runs up, against the rows.
    for channel, axis, sign in ((0, 1, 1.0), (1, 0, -1.0)):
        head, tail = [slice(None)] * 2, [slice(None)] * 2
        head[axis], tail[axis] = slice(1, None), slice(None, -1)
        both = mask[tuple(head)] & mask[tuple(tail)]
        step = np.where(both, lum[tuple(head)] - lum[tuple(tail)], np.float32(0))
        total, count = np.zeros(lum.shape, np.float32), np.zeros(lum.shape, np.float32)
        total[tuple(head)] += step
        total[tuple(tail)] += step
        count[tuple(head)] += both
        count[tuple(tail)] += both
        out[..., channel] = sign * total / np.maximum(count, 1)
    return np.where(mask[..., None], out, np.float32(0))


def chart_tensors(lightmap, mask, source_uvs, uvs, triangles, charts, source=None):
    """(C, 2, 2) float64: each chart's structure tensor of the luminance
    gradient of `lightmap` (baked on `source_uvs`, `mask` its coverage;
    the gradient scaled by its largest component, all zero without one), in
    the frame of layout `uvs` (the same triangles, each an affine image of
    its source triangle: a gradient g maps to A^-T g). Triangles without
    area in either layout add nothing. `source`: source_tensors' result for
    these arguments, when the caller has it."""
    count = int(charts.max()) + 1 if len(charts) else 0
    mapped = triangle_tensors(lightmap, mask, source_uvs, uvs, triangles, source)
    out = np.zeros((count, 2, 2))
    for i in range(2):
        for j in range(2):
            out[:, i, j] = np.bincount(charts, weights=mapped[:, i, j], minlength=count)
    return out


def source_tensors(lightmap, mask, source_uvs, triangles):
    """(T, 2, 2) float64: each triangle's structure tensor of the luminance
    gradient of `lightmap` (the sum over its texels), in the frame of the
    layout `source_uvs` it was baked on (chart_tensors' gradient, scaled
    the same way). Several layouts made from one source read it through
    triangle_tensors' `source`: the gradient is read once."""
    gradient = luminance_gradient(lightmap, mask)
    # Only directions and ratios matter: scaled to at most 1, huge light cannot overflow the squares.
    peak = float(np.abs(gradient).max(initial=0.0))
    if not (np.isfinite(peak) and peak > 0):
        return np.zeros((len(triangles), 2, 2))
    # Per triangle, in the source frame: sums over its texels (allocation's
    # four points per triangle, as triangle_energy), read at those points only.
    samples, texels = triangle_samples(source_uvs, triangles, gradient)
    sampled = samples.astype(np.float64) / peak  # (T, 4, 2)
    gu, gv = sampled[..., 0], sampled[..., 1]
    parts = [field.mean(axis=1) * texels for field in (gu * gu, gu * gv, gv * gv)]
    return np.stack([np.stack([parts[0], parts[1]], -1), np.stack([parts[1], parts[2]], -1)], -2)


def triangle_tensors(lightmap, mask, source_uvs, uvs, triangles, source=None):
    """(T, 2, 2) float64: chart_tensors' structure tensor per triangle (the
    sum over its texels), in the frame of layout `uvs`. `source`:
    source_tensors' result for these arguments, when the caller has it."""
    tensor = source_tensors(lightmap, mask, source_uvs, triangles) if source is None else source
    if not tensor.any():
        return np.zeros((len(triangles), 2, 2))
    corners = np.asarray(source_uvs, np.float64)[triangles]
    target = np.asarray(uvs, np.float64)[triangles]
    before = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], -1)  # columns: edge vectors
    after = np.stack([target[:, 1] - target[:, 0], target[:, 2] - target[:, 0]], -1)
    det_before = before[:, 0, 0] * before[:, 1, 1] - before[:, 0, 1] * before[:, 1, 0]
    det_after = after[:, 0, 0] * after[:, 1, 1] - after[:, 0, 1] * after[:, 1, 0]
    scale = np.maximum(np.abs(before).max(axis=(1, 2)), np.abs(after).max(axis=(1, 2)))
    good = (np.abs(det_before) > 1e-12 * scale ** 2) & (np.abs(det_after) > 1e-12 * scale ** 2)
    # A^-1 = before after^-1 (A maps source edges onto layout edges).
    inverse = np.zeros_like(after)
    inverse[good] = before[good] @ np.linalg.inv(after[good])
    mapped = np.transpose(inverse, (0, 2, 1)) @ tensor @ inverse
    mapped[~good] = 0.0
    return mapped


def stretch_factors(tensors, uvs, triangles, charts, resolution, max_stretch):
    """Per chart (factor a >= 1, direction e1 (C, 2), share w1 of its light
    changes across e1, light changes sqrt(l1) + sqrt(l2)): the model's best
    stretch (l1 / l2)^(1/4), bounded by `max_stretch` and by
    MIN_WIDTH_TEXELS across the squeezed direction; 1 below MIN_STRETCH,
    without light changes, or for a chart with fewer light changes than the
    mean chart (a stretched chart costs packing density whatever it holds;
    only the charts that hold the light changes pay it back)."""
    count = len(tensors)
    if count == 0:
        return np.ones(0), np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    values, vectors = np.linalg.eigh(tensors)  # ascending eigenvalues
    low, high = np.maximum(values[:, 0], 0.0), np.maximum(values[:, 1], 0.0)
    direction = vectors[:, :, 1]
    roots = np.sqrt(high) + np.sqrt(low)
    share = np.where(roots > 0, np.sqrt(high) / np.maximum(roots, 1e-300), 0.5)
    factor = _bounded_factors(high, low, direction, roots, uvs, triangles, charts, resolution, max_stretch)
    return factor, direction, share, roots


def axis_stretch_factors(tensors, roots, uvs, triangles, charts, resolution, max_stretch):
    """Per chart (factor a >= 1, direction (C, 2), edge-term factor): the
    stretch along the u or the v axis of `uvs`, whichever the chart's light
    changes cross more (J_uu against J_vv), by the model's best (J_aa /
    J_bb)^(1/4) (it minimises tensor_edge_factor along that axis), bounded
    and selected as stretch_factors bounds and selects (`roots`: its
    sqrt(l1) + sqrt(l2) per chart). A chart stretched
    along an axis of its frame keeps a rectangular box rectangular, where a
    stretch along a diagonal shears it: it may pack as densely as the input
    where the stretch along the main direction does not."""
    uu, vv = np.maximum(tensors[:, 0, 0], 0.0), np.maximum(tensors[:, 1, 1], 0.0)
    along_u = uu >= vv
    direction = np.where(along_u[:, None], np.array([1.0, 0.0]), np.array([0.0, 1.0]))
    factor = _bounded_factors(np.where(along_u, uu, vv), np.where(along_u, vv, uu), direction, roots, uvs,
                              triangles, charts, resolution, max_stretch)
    return factor, direction, tensor_edge_factor(tensors, factor, direction)


def _bounded_factors(high, low, direction, roots, uvs, triangles, charts, resolution, max_stretch):
    """The stretch along `direction` minimising the edge term, (high / low)^(1/4)
    (`high` and `low` the tensor's entries along and across it), bounded by
    `max_stretch` and by MIN_WIDTH_TEXELS across the squeezed direction; 1
    below MIN_STRETCH and for charts whose light changes `roots` are below
    the mean chart's."""
    with np.errstate(divide="ignore", invalid="ignore"):
        best = np.where(low > 0, (high / np.maximum(low, 1e-300)) ** 0.25, np.inf)
    factor = np.where(high > 0, np.minimum(best, max_stretch), 1.0)
    # The chart's extent across the squeezed direction e2 (perpendicular to e1), in texels.
    height, width = resolution
    corner_uvs = np.asarray(uvs, np.float64)[triangles] * np.array([width, height])
    along = np.stack([-direction[:, 1], direction[:, 0]], -1)[charts]  # (T, 2)
    projected = np.einsum("tkc,tc->tk", corner_uvs, along)
    count = len(roots)
    lo = np.full(count, np.inf)
    hi = np.full(count, -np.inf)
    np.minimum.at(lo, charts, projected.min(axis=1))
    np.maximum.at(hi, charts, projected.max(axis=1))
    extent = np.where(hi >= lo, hi - lo, 0.0)
    factor = np.minimum(factor, np.maximum(extent / MIN_WIDTH_TEXELS, 1.0))
    return np.where((factor >= MIN_STRETCH) & (roots >= roots.mean()), factor, 1.0)


def tensor_edge_factor(tensors, factor, direction):
    """The chart model's edge-term factor of stretching each chart by
    `factor` along `direction` and squeezing it by 1 / factor across it:
    tr sqrt(J') / tr sqrt(J), J' the structure tensor in the stretched
    frame (entries J_11 / a^2 and J_22 a^2 along and across the direction,
    the same determinant; tr sqrt(M) = sqrt(tr M + 2 sqrt(det M)) for a 2 x 2
    M >= 0). Along the tensor's main direction it is edge_factor."""
    e1 = np.asarray(direction, np.float64)
    e2 = np.stack([-e1[:, 1], e1[:, 0]], -1)
    a2 = np.asarray(factor, np.float64) ** 2
    along = np.einsum("ci,cij,cj->c", e1, tensors, e1)
    across = np.einsum("ci,cij,cj->c", e2, tensors, e2)
    twice_root_det = 2.0 * np.sqrt(np.maximum(np.linalg.det(tensors), 0.0))
    before = np.sqrt(np.maximum(along + across + twice_root_det, 0.0))
    after = np.sqrt(np.maximum(along / a2 + across * a2 + twice_root_det, 0.0))
    return np.where(before > 0, after / np.maximum(before, 1e-300), 1.0)


def edge_factor(factor, share):
    """The chart model's edge-term factor of a stretch: share / a + (1 - share) a."""
    return share / factor + (1.0 - share) * factor


def _chart_centres(uvs, triangles, charts, count):
    """(owner (N,) chart of each UV index, -1 when unused; centre (count, 2)
    each chart's mean UV over the indices it owns). A UV index used by two
    charts belongs to its first (pack_charts refuses such layouts anyway)."""
    owner = np.full(len(uvs), -1, np.int64)
    flat = np.asarray(triangles).reshape(-1)
    corner_chart = np.repeat(np.asarray(charts), 3)
    used_uvs, first = np.unique(flat, return_index=True)
    owner[used_uvs] = corner_chart[first]
    used = owner >= 0
    weight = np.bincount(owner[used], minlength=count).astype(np.float64)
    centre = np.stack([np.bincount(owner[used], weights=uvs[used, k], minlength=count) for k in range(2)], -1)
    return owner, centre / np.maximum(weight, 1.0)[:, None]


def stretch_charts(uvs, triangles, charts, factor, direction):
    """`uvs` with every chart c stretched by factor[c] along direction[c] and
    squeezed by 1 / factor[c] across it, about its mean UV (area and
    orientation kept: the map has determinant 1). UVs of unstretched charts
    are unchanged."""
    out = np.asarray(uvs, np.float64).copy()
    owner, centre = _chart_centres(out, triangles, charts, len(factor))
    moved = (owner >= 0) & (factor[np.maximum(owner, 0)] > 1.0)
    if not moved.any():
        return np.asarray(uvs).copy()
    index = np.flatnonzero(moved)
    chart = owner[index]
    e1 = direction[chart]
    a = factor[chart][:, None]
    offset = out[index] - centre[chart]
    along = (offset * e1).sum(axis=1, keepdims=True)
    # offset = along e1 + across e2: the e1 part grows by a, the e2 part shrinks by 1 / a.
    out[index] = centre[chart] + a * along * e1 + (offset - along * e1) / a
    return out.astype(np.asarray(uvs).dtype)


def _box_areas(uvs, triangles, charts, count):
    """(count,) each chart's axis-aligned bounding box area."""
    corners = np.asarray(uvs, np.float64)[triangles]  # (T, 3, 2)
    lo = np.full((count, 2), np.inf)
    hi = np.full((count, 2), -np.inf)
    np.minimum.at(lo, charts, corners.min(axis=1))
    np.maximum.at(hi, charts, corners.max(axis=1))
    size = np.where(hi >= lo, hi - lo, 0.0)
    return size[:, 0] * size[:, 1]


def turn_to_smallest_boxes(uvs, triangles, charts, which):
    """(uvs, turned): `uvs` with each chart c in `which` ((C,) bool) turned
    about its mean UV so its axis-aligned bounding box is smallest, where
    that box is at most TURN_GAIN of the one it has (a stretch along a
    diagonal makes a sheared chart the packer would place by its larger
    box); turned (C,) bool, the charts turned. UVs of other charts are
    unchanged."""
    count = len(which)
    out = np.asarray(uvs, np.float64).copy()
    turned = np.zeros(count, bool)
    if not np.any(which) or len(triangles) == 0:
        return np.asarray(uvs).copy(), turned
    turns = _native.smallest_box_turns(out, triangles, charts)
    turns = np.concatenate([turns, np.tile([[1.0, 0.0]], (count - len(turns), 1))])
    owner, centre = _chart_centres(out, triangles, charts, count)
    index = np.flatnonzero((owner >= 0) & np.asarray(which)[np.maximum(owner, 0)])
    chart = owner[index]
    cos, sin = turns[chart, 0:1], turns[chart, 1:2]
    offset = out[index] - centre[chart]
    candidate = out.copy()
    candidate[index] = centre[chart] + np.concatenate([cos * offset[:, :1] - sin * offset[:, 1:],
                                                       sin * offset[:, :1] + cos * offset[:, 1:]], axis=1)
    turned = np.asarray(which) & (_box_areas(candidate, triangles, charts, count)
                                  <= TURN_GAIN * _box_areas(out, triangles, charts, count))
    keep = turned[chart]
    out[index[keep]] = candidate[index[keep]]
    return out.astype(np.asarray(uvs).dtype), turned


# The triangle stretch (docs/refiner.md, "Triangle stretch"): the chart
# stretch made local. Rounds of averaging each triangle's structure tensor
# with its neighbours' (triangles a few texels large read few texels):
TRIANGLE_SMOOTHING = 2
# A triangle's stretch grows with its light changes up to this quantile of
# the triangles' (per texel), so flat triangles, whose tensor is noise, keep
# their shape.
TRIANGLE_STRENGTH_QUANTILE = 90
# The share of the stretch a chart keeps when it flips a triangle, in turn;
# a chart that flips one at the last keeps its shape.
TRIANGLE_BACKOFF = (1.0, 0.5, 0.25)
# Before its whole chart steps down TRIANGLE_BACKOFF, a flip halves the
# stretch of the triangles within this many rings of it, up to this many
# times: a chart of thousands of triangles need not give up its stretch for
# two flipped ones (docs/refiner.md, "Local back-off").
LOCAL_BACKOFF_RINGS = 2
LOCAL_BACKOFF_ROUNDS = 4
# A triangle of the output counts as stretched when its map from the refined
# layout is this much longer one way than the other (1%).
MEASURED_STRETCH = 1.01
# UV corners of one chart this close (in UV units, rounded) are one vertex of the fit.
WELD_STEP = 2.0 ** -20


def _welded(uvs, triangles, charts):
    """(vertex per corner index (N,), vertex count): the corners of one
    chart at the same UV (to WELD_STEP) are one vertex."""
    corner_chart = np.full(len(uvs), -1, np.int64)
    corner_chart[triangles.ravel()] = np.repeat(charts, 3)
    key = np.column_stack([corner_chart, np.round(np.asarray(uvs, np.float64) / WELD_STEP).astype(np.int64)])
    _, vertex = np.unique(key, axis=0, return_inverse=True)
    vertex = vertex.ravel()
    return vertex, int(vertex.max()) + 1 if len(vertex) else 0


def _smoothed(values, vertex_triangles, vertices, rounds):
    """Per-triangle `values` (T, ...) averaged `rounds` times over the
    triangles that share a vertex with each."""
    flat = values.reshape(len(values), -1)
    for _ in range(rounds):
        total = np.zeros((vertices, flat.shape[1]))
        count = np.zeros(vertices)
        for k in range(3):
            np.add.at(total, vertex_triangles[:, k], flat)
            np.add.at(count, vertex_triangles[:, k], 1.0)
        mean = total / np.maximum(count, 1.0)[:, None]
        flat = sum(mean[vertex_triangles[:, k]] for k in range(3)) / 3.0
    return flat.reshape(values.shape)


def triangle_targets(tensors, uvs, triangles, resolution, max_stretch):
    """Per triangle, from its structure tensor in the frame of `uvs`: the
    stretch a >= 1 (T,), the target map a e1 e1^T + e2 e2^T / a (T, 2, 2)
    (area kept: wider across the light changes, narrower along them), the
    direction e1 (T, 2), the share of its light changes across e1 and its
    light changes sqrt(l1) + sqrt(l2) (the chart stretch's weights, per
    triangle). The stretch is the model's best, (l1 / l2)^(1/4)
    (stretch_factors), bounded by `max_stretch` and ramped down with the
    light changes per texel below the TRIANGLE_STRENGTH_QUANTILE-th
    percentile."""
    height, width = resolution
    values, vectors = np.linalg.eigh(tensors)
    low, high = np.maximum(values[:, 0], 0.0), np.maximum(values[:, 1], 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        best = np.where(low > 0, (high / np.maximum(low, 1e-300)) ** 0.25, np.inf)
    texels = np.abs(signed_areas(uvs, triangles)) * width * height
    strength = np.sqrt((high + low) / np.maximum(texels, 1e-12))
    live = strength[(high > 0) & (texels > 0)]
    reference = float(np.percentile(live, TRIANGLE_STRENGTH_QUANTILE)) if live.size else 0.0
    ramp = np.clip(strength / reference, 0.0, 1.0) if reference > 0 else np.zeros_like(strength)
    factor = 1.0 + (np.minimum(best, max_stretch) - 1.0) * ramp
    factor = np.where((high > 0) & np.isfinite(factor), factor, 1.0)
    across, along = vectors[:, :, 1], vectors[:, :, 0]
    targets = (factor[:, None, None] * across[:, :, None] * across[:, None, :]
               + (1.0 / factor)[:, None, None] * along[:, :, None] * along[:, None, :])
    roots = np.sqrt(high) + np.sqrt(low)
    share = np.where(roots > 0, np.sqrt(high) / np.maximum(roots, 1e-300), 0.5)
    return factor, targets, across, share, roots


def triangle_stretch(lightmap, mask, source_uvs, uvs, triangles, charts, resolution, max_stretch, kept=None,
                     source=None):
    """`uvs` with each triangle stretched across the light changes of
    `lightmap` (baked on `source_uvs`) and squeezed along them, the chart's
    triangles fitted to those shapes together (lmrefine._native._fit_shapes).
    `kept`: the share of its stretch each chart may keep (C,), 1 for all by
    default. A chart that would flip a triangle first halves the stretch
    around the flipped triangles (LOCAL_BACKOFF_RINGS, up to
    LOCAL_BACKOFF_ROUNDS times), then keeps the next smaller share of
    TRIANGLE_BACKOFF, none after the last. The charts stay where they were
    and need packing again. Returns (uvs, kept shares (C,), report, model:
    the per-triangle `direction`, `share` and `weight` triangle_edge_error
    reads, the `factor` of each triangle's stretch and the `local` share
    (T,) of its chart's it keeps). `source`:
    source_tensors' result for lightmap, mask, source_uvs and triangles,
    when the caller has it."""
    triangles = np.asarray(triangles)
    charts = np.asarray(charts)
    count = int(charts.max()) + 1 if len(charts) else 0
    kept = np.ones(count) if kept is None else np.asarray(kept, np.float64).copy()
    vertex, vertices = _welded(uvs, triangles, charts)
    vertex_triangles = vertex[triangles]
    tensors = _smoothed(triangle_tensors(lightmap, mask, source_uvs, uvs, triangles, source), vertex_triangles,
                        vertices, TRIANGLE_SMOOTHING)
    factor, targets, direction, share, weight = triangle_targets(tensors, uvs, triangles, resolution, max_stretch)
    start = np.zeros((vertices, 2))
    start[vertex] = np.asarray(uvs, np.float64)
    before = signed_areas(uvs, triangles)
    identity = np.eye(2)
    out = np.asarray(uvs, np.float64).copy()
    local = np.ones(len(triangles))
    local_rounds = np.zeros(count, np.int64)  # local back-offs of each chart at its present share
    while True:
        trying = kept > 0
        if not trying.any():
            break
        scale = (kept[charts] * local)[:, None, None]
        fitted = _native._fit_shapes(start, vertex_triangles, identity + scale * (targets - identity))[vertex]
        after = signed_areas(fitted, triangles)
        # A triangle without area in the input has no orientation to keep.
        flips = (before != 0) & ((before > 0) != (after > 0))
        flipped = np.zeros(count, bool)
        np.logical_or.at(flipped, charts, flips)
        good = trying & ~flipped
        corner_good = np.zeros(len(uvs), bool)
        corner_good[triangles.ravel()] = np.repeat(good[charts], 3)
        out[corner_good] = fitted[corner_good]
        failing = trying & flipped
        if not failing.any():
            break
        around = failing & (local_rounds < LOCAL_BACKOFF_ROUNDS)
        local[_rings(flips & around[charts], vertex_triangles, vertices, LOCAL_BACKOFF_RINGS)] *= 0.5
        local_rounds[around] += 1
        whole = failing & ~around
        kept[whole] = smaller_share(kept[whole])
        local[whole[charts]] = 1.0
        local_rounds[whole] = 0
    local[kept[charts] == 0] = 1.0  # a chart that keeps its shape has no triangle backed off
    report = {**stretch_figures(factor, kept[charts] * local),
              "charts_backed_off": int(((kept > 0) & (kept < 1)).sum()), "charts_kept_shape": int((kept == 0).sum()),
              "triangles_backed_off": int((local < 1).sum())}
    return out.astype(np.asarray(uvs).dtype), kept, report, {"direction": direction, "share": share,
                                                            "weight": weight, "factor": factor, "local": local}


def _rings(selected, vertex_triangles, vertices, rings):
    """`selected` (T,) bool grown by `rings` rings of the triangles sharing a vertex."""
    for _ in range(rings):
        marked = np.zeros(vertices, bool)
        marked[vertex_triangles[selected].ravel()] = True
        selected = marked[vertex_triangles].any(axis=1)
    return selected


def stretch_figures(factor, kept):
    """The report's figures of triangles stretched by `factor` (T,), each
    keeping the share `kept` (T,) of its stretch: how many, the largest and
    the mean stretch of those stretched."""
    return _figures(1.0 + (np.asarray(factor) - 1.0) * np.asarray(kept), 1.0)


def measured_stretch_figures(before_uvs, after_uvs, triangles):
    """stretch_figures measured on the output: each triangle's stretch is
    sqrt(s1 / s2) of its affine map from `before_uvs` to `after_uvs` (s1 >=
    s2 its singular values; a chart's uniform scale and turn leave it at 1),
    and a triangle counts as stretched above MEASURED_STRETCH (the fit's
    compromise bends its neighbours by less)."""
    maps, has_area = triangle_maps(before_uvs, after_uvs, triangles)
    values = np.linalg.svd(maps, compute_uv=False) if len(maps) else np.ones((0, 2))
    measured = np.ones(len(has_area))
    measured[has_area] = np.sqrt(values[:, 0] / np.maximum(values[:, 1], 1e-300))
    return _figures(measured, MEASURED_STRETCH)


def _figures(stretches, above):
    stretched = stretches > above
    return {"triangles_stretched": int(stretched.sum()), "largest_stretch": float(stretches.max(initial=1.0)),
            "mean_stretch": float(stretches[stretched].mean()) if stretched.any() else 1.0}


def smaller_share(shares):
    """The next share of TRIANGLE_BACKOFF below each of `shares` (0 after the last)."""
    steps = np.array(TRIANGLE_BACKOFF + (0.0,))
    return np.array([steps[steps < share].max(initial=0.0) for share in np.atleast_1d(shares)])


def triangle_maps(before_uvs, after_uvs, triangles):
    """Each triangle's affine map from layout `before_uvs` to `after_uvs`
    (the same triangles): (maps (K, 2, 2) of the K triangles with area in
    `before_uvs`, that mask (T,))."""
    before = np.asarray(before_uvs, np.float64)[triangles]
    after = np.asarray(after_uvs, np.float64)[triangles]
    edges_before = np.stack([before[:, 1] - before[:, 0], before[:, 2] - before[:, 0]], -1)
    edges_after = np.stack([after[:, 1] - after[:, 0], after[:, 2] - after[:, 0]], -1)
    det = edges_before[:, 0, 0] * edges_before[:, 1, 1] - edges_before[:, 0, 1] * edges_before[:, 1, 0]
    good = np.abs(det) > 1e-12 * np.abs(edges_before).max(axis=(1, 2)) ** 2
    return edges_after[good] @ np.linalg.inv(edges_before[good]), good


def triangle_edge_terms(model, before_uvs, after_uvs, triangles):
    """Per triangle, the chart model's edge term of `after_uvs` made from
    `before_uvs` (triangle_edge_error's sum, before the sum): (weights w
    (T,), terms w (s / |A e1| + (1 - s) / |A e2|) (T,)); a triangle without
    light changes or without area in `before_uvs` has weight 0 and term 0."""
    weight = np.asarray(model["weight"], np.float64)
    maps, has_area = triangle_maps(before_uvs, after_uvs, triangles)
    good = has_area & (weight > 0)
    weights, terms = np.zeros(len(weight)), np.zeros(len(weight))
    if not good.any():
        return weights, terms
    maps = maps[good[has_area]]
    e1 = np.asarray(model["direction"], np.float64)[good]
    e2 = np.stack([-e1[:, 1], e1[:, 0]], -1)
    across = np.linalg.norm(np.einsum("tij,tj->ti", maps, e1), axis=1)
    along = np.linalg.norm(np.einsum("tij,tj->ti", maps, e2), axis=1)
    share = np.asarray(model["share"], np.float64)[good]
    weights[good] = weight[good]
    terms[good] = weight[good] * (share / np.maximum(across, 1e-12) + (1.0 - share) / np.maximum(along, 1e-12))
    return weights, terms


def triangle_edge_error(model, before_uvs, after_uvs, triangles):
    """The chart model's edge term of a layout `after_uvs` made from
    `before_uvs` (the same triangles, each an affine image), relative to
    `before_uvs`'s: each triangle's light changes split into `share` across
    its `direction` e1 and the rest along e2, each falling with the texel
    size across it, weighted by the triangle's light changes: sum w (s / |A
    e1| + (1 - s) / |A e2|) / sum w, A the triangle's map before -> after.
    1.0 = the same; the packing's global scale is in A."""
    weights, terms = triangle_edge_terms(model, before_uvs, after_uvs, triangles)
    total = weights.sum()
    return float(terms.sum() / total) if total > 0 else 1.0


def chart_gains(model, before_uvs, after_uvs, triangles, charts):
    """What each chart's stretch `before_uvs` -> `after_uvs` (before any
    packing) takes off the model's summed edge term: sum over the chart's
    triangles of w - w (s / |A e1| + (1 - s) / |A e2|) (C,); negative for a
    chart the stretch serves worse."""
    weights, terms = triangle_edge_terms(model, before_uvs, after_uvs, triangles)
    count = int(np.max(charts)) + 1 if len(charts) else 0
    return np.bincount(charts, weights - terms, minlength=count)
