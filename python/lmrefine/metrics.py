"""Quality metrics of a baked lightmap, measured in world space (no bpy).

Definitions (docs/evaluation.md gives the reasoning):

* **Surface samples**: points drawn uniformly by world area over the receiver
  triangles with a fixed seed (:func:`sample_surface`); each keeps its
  triangle and barycentric coordinates, so its UV in any layout of the same
  triangles is known.
* **Lightmap value at a point**: bilinear lookup at the point's UV with the
  texel_space convention (row 0 = top = v=1; texel (i, j) centred at
  ((j+.5)/W, 1-(i+.5)/H); clamped at the image border), what a GPU sampler
  does at run time (:func:`bilinear_lookup`).
* **Error**: RMSE and MAE over all colour channels of all points, against a
  ground truth evaluated at the points themselves (lmrefine.evaluate with many
  samples).
* **Transition points**: the top decile of the ground truth's gradient
  magnitude along the surface (luminance; finite differences over a step of
  about half a baseline texel inside the point's own triangle, so no step
  crosses a crease into a wall; :func:`surface_gradient`,
  :func:`transition_mask`).
* **Texel density**: texels per square metre of each triangle, UV area x R^2
  over world area; **transition widening**: refined density over baseline
  density, averaged over the transition points (the thesis' figure of merit,
  in area; its square root is the widening of an edge in texels). The
  pictures and the add-on's overlay show its square root, **texels per
  metre** (:func:`texels_per_metre`, per face).
* **Equal-error resolution**: the resolution (as a multiple of R) at which the
  uniform baseline's error equals the refined map's error at R, interpolated
  linearly in error against log-resolution (:func:`equal_error_resolution`);
  undefined when the baseline's error hardly falls with resolution (noise).
* **Ground-truth noise**: the truth is the mean of two independent
  evaluations; half the RMS of their difference is its own noise
  (:func:`truth_noise`).
"""

from dataclasses import dataclass

import numpy as np

from . import _native

# Rec. 709 luminance weights: the transition detector looks at brightness.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)
TRANSITION_FRACTION = 0.1


@dataclass
class SurfaceSamples:
    triangle: np.ndarray     # (P,) int triangle index
    bary: np.ndarray         # (P, 3) float64 barycentric coordinates
    points: np.ndarray       # (P, 3) float32 world positions
    normals: np.ndarray      # (P, 3) float32 unit shading normals

    def __len__(self):
        return len(self.triangle)


def triangle_areas(positions, triangles):
    p = np.asarray(positions, np.float64)[np.asarray(triangles)]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def uv_areas(uvs, triangles):
    """(T,) area of every UV triangle, in units of the whole atlas."""
    uv = np.asarray(uvs, np.float64)[np.asarray(triangles)]
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


# A further refinement stage (bake, refine, bake again) is kept only if its
# layout moves texels by at least this much against the previous stage's
# (layout_change): the rule needs no ground truth, so `evaluate --stages` and
# the add-on's Stages setting stop on the same rule.
STAGE_MIN_CHANGE = 0.05
# ... and, from stage STAGE_BACKOFF_FROM on, only if its refinement kept at
# least this share of its deformation everywhere (refine_uvs'
# report["backoff"]). On the tuning scenes eight of ten third stages below it
# measured worse than the second, by up to 8%; second stages below it (at 16
# bake samples) measured 5-8% better than the first (docs/refiner.md,
# "Stages that back off stop").
STAGE_MIN_BACKOFF = 0.1
STAGE_BACKOFF_FROM = 3
# ... and only if it gave its light changes more texels than the layout it
# refined had there (refine_uvs' report["transition_widening"] above 1): a
# stage that takes texels from them is not refining (the plaza's second stage,
# 0.99x, measured 25% worse than its first).
STAGE_MIN_WIDENING = 1.0


def layout_change(previous_uvs, uvs, triangles):
    """How much a layout moved texels: the median over the triangles of
    |new / old texel density - 1| between two layouts of the same triangles
    (world areas and resolution cancel: it is the UV area ratio). Triangles
    without UV area in `previous_uvs` are left out; 0 when none has area."""
    before, after = uv_areas(previous_uvs, triangles), uv_areas(uvs, triangles)
    has_area = before > 0
    return float(np.median(np.abs(after[has_area] / before[has_area] - 1))) if has_area.any() else 0.0


def stage_entry(stage, report, change=None):
    """What the stop rule reads of refinement stage `stage`, from its
    refine_uvs report (and `change`, its layout_change, from stage 2 on):
    moved, backoff, widening (report["transition_widening"])."""
    entry = {"stage": stage, "moved": bool(report["moved"]), "backoff": float(report.get("backoff", 1.0)),
             "widening": report.get("transition_widening")}
    if change is not None:
        entry["layout_change"] = change
    return entry


def stage_stop_kind(stage, moved, change, backoff=1.0, widening=None):
    """None when refinement stage `stage` (2, 3, ...) is kept: it moved the
    layout by `change` (layout_change) of at least STAGE_MIN_CHANGE, its
    refinement kept at least STAGE_MIN_BACKOFF of its deformation (`backoff`,
    refine_uvs' report["backoff"]; from stage STAGE_BACKOFF_FROM on) and gave
    its light changes more texels (`widening`, report["transition_widening"];
    None: not known); else which rule stopped it: "settled", "backed off" or
    "no edge gain"."""
    if not (moved and change >= STAGE_MIN_CHANGE):
        return "settled"
    if stage >= STAGE_BACKOFF_FROM and backoff < STAGE_MIN_BACKOFF:
        return "backed off"
    if widening is not None and widening <= STAGE_MIN_WIDENING:
        return "no edge gain"
    return None


def stage_stop_reason(stage, moved, change, backoff=1.0, widening=None):
    """None when refinement stage `stage` is kept (stage_stop_kind); else why
    the stages stop there, as a sentence (stage - 1 is the last one kept)."""
    kind = stage_stop_kind(stage, moved, change, backoff, widening)
    if kind == "settled":
        return (f"stage {stage} changed the layout by {change:.1%} (median texel density), under "
                f"{STAGE_MIN_CHANGE:.0%}: stage {stage - 1} kept")
    if kind == "backed off":
        return (f"stage {stage} kept only {backoff:.0%} of its deformation in places (the rest flipped or "
                f"overlapped and was backed off), under {STAGE_MIN_BACKOFF:.0%}: stage {stage - 1} kept")
    if kind == "no edge gain":
        return (f"stage {stage} gave its light changes {widening:.2f}x the texels the stage before gave them, "
                f"no more: stage {stage - 1} kept")
    return None


def further_stage_options(first_report):
    """refine_uvs keywords that stages 2, 3, ... add to the user's, from
    stage 1's report: on a source layout with no room (Lightmap Pack's one
    chart per face; report["rechart"]["room"], so only when stage 1 had the
    positions, or rechart='always': such a layout tessellated) stage 1's
    gain is its charts' scales, re-charted or not, and scaling them again
    from a bake on that non-uniform layout loses, so the
    later stages refine inside the charts only (docs/refiner.md,
    "Multi-stage refinement"). Every other layout repacks as stage 1 did."""
    rechart = (first_report or {}).get("rechart") or {}
    if (rechart.get("room") or {}).get("no_room") or rechart.get("always"):
        return {"repack": False}
    return {}


def interpolate_corners(per_corner, triangle, bary):
    """Values given per corner (3T, K) (corner k of triangle t at 3t+k) at
    points (triangle, barycentric coordinates)."""
    values = np.asarray(per_corner, np.float64).reshape(-1, 3, np.shape(per_corner)[-1])[triangle]
    return np.einsum("pk,pkc->pc", bary, values)


def sample_surface(positions, triangles, count, normals=None, seed=0):
    """`count` points uniformly distributed by area over the triangles (fixed
    `seed`: the same points for every layout and resolution). `normals` are
    per corner (3T, 3) and interpolated; without them, face normals."""
    positions = np.asarray(positions, np.float64)
    triangles = np.asarray(triangles)
    if count <= 0:
        raise ValueError(f"count must be positive, got {count}")
    areas = triangle_areas(positions, triangles)
    if not np.isfinite(areas).all() or areas.sum() <= 0:
        raise ValueError("the triangles have no area to sample; check positions and triangles")
    rng = np.random.default_rng(seed)
    triangle = rng.choice(len(triangles), size=count, p=areas / areas.sum())
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    bary = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    corners = positions[triangles[triangle]]
    points = np.einsum("pk,pkc->pc", bary, corners)
    if normals is not None:
        shading = interpolate_corners(normals, triangle, bary)
    else:
        shading = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    shading /= np.maximum(np.linalg.norm(shading, axis=1, keepdims=True), 1e-30)
    return SurfaceSamples(triangle, bary, points.astype(np.float32), shading.astype(np.float32))


def bilinear_lookup(image, uv):
    """Bilinear sample of an (H, W[, C]) image at UVs (P, 2), texel centres at
    ((j+.5)/W, 1-(i+.5)/H), clamped to the border. Returns (P, C) float64.

    Native (lmrefine._native.bilinear_lookup, all cores, the GIL released):
    a float32 image is read in place, any other real dtype as float64, which
    is how numpy's arithmetic promotes it; bit-identical to the plain numpy
    reference in tests/test_metrics.py. A NaN UV raises ValueError."""
    image = np.asarray(image)
    if image.dtype != np.float32:
        image = image.astype(np.float64)
    return _native.bilinear_lookup(image, np.asarray(uv))


def error_stats(values, truth, where=None):
    """{"rmse", "mae"} over every colour channel of the selected points."""
    difference = np.asarray(values, np.float64) - np.asarray(truth, np.float64)
    if where is not None:
        difference = difference[where]
    if difference.size == 0:
        return {"rmse": float("nan"), "mae": float("nan")}
    return {"rmse": float(np.sqrt(np.mean(difference ** 2))), "mae": float(np.mean(np.abs(difference)))}


def truth_noise(first, second):
    """RMS noise of the mean of two independent, equally noisy estimates
    (P, C) of the same values: half the RMS of their difference."""
    difference = np.asarray(first, np.float64) - np.asarray(second, np.float64)
    return float(np.sqrt(np.mean(difference ** 2)) / 2) if difference.size else float("nan")


# The relative noise (noise_level) above which a first lightmap is called noisy. Gaussian noise added
# to a clean 64-sample bake of each tuning scene's Smart UV map at 256^2, read as 1.7-1.8%, takes off
# this share of their refinement's gain at the light changes (the texel area of the triangles under
# the clean map's top 5% of gradient energy): courtyard 36%, game_level 26%, fence_and_tree 5%; read
# as 2.5%: 45%, 34%, 14% (docs/refiner.md, "A noisy first lightmap").
NOISY_FIRST_MAP = 0.02


def noise_level(lightmap, mask):
    """The noise of a lightmap (H, W[, C]) relative to its light: the standard deviation of its
    luminance noise, estimated from the residual of each covered texel against the mean of its four
    covered neighbours (median absolute value / 0.6745, the residual of white noise having 1.25 times
    its variance; light changes are few texels, so the median does not see them), over the median
    luminance of the covered texels (`mask` (H, W) bool). 0 for a map with no interior texel or no light."""
    from .allocation import texel_luminance

    lum = texel_luminance(lightmap)
    covered = np.asarray(mask, bool)
    inner = np.zeros_like(covered)
    inner[1:-1, 1:-1] = (covered[1:-1, 1:-1] & covered[:-2, 1:-1] & covered[2:, 1:-1]
                         & covered[1:-1, :-2] & covered[1:-1, 2:])
    level = float(np.median(lum[covered])) if covered.any() else 0.0
    if not inner.any() or not level > 0:
        return 0.0
    residual = lum[1:-1, 1:-1] - 0.25 * (lum[:-2, 1:-1] + lum[2:, 1:-1] + lum[1:-1, :-2] + lum[1:-1, 2:])
    sigma = float(np.median(np.abs(residual[inner[1:-1, 1:-1]]))) / 0.6745 / np.sqrt(1.25)
    return sigma / level


def luminance(rgb):
    return np.asarray(rgb, np.float64)[:, :3] @ LUMINANCE.astype(np.float64)


def gradient_stencil(positions, triangles, samples, step, normals=None):
    """Two neighbours of every sample point along two orthogonal directions of
    its triangle's plane, at most `step` away and always inside the same
    triangle (forwards, or backwards when that leaves more room), so a step
    never crosses a crease (floor into wall). Returns (points (2P, 3), normals
    (2P, 3), distances (2P,)) for :func:`surface_gradient`."""
    positions = np.asarray(positions, np.float64)
    triangles = np.asarray(triangles)
    corners = positions[triangles[samples.triangle]]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    face_normal = np.cross(e1, e2)
    face_normal /= np.linalg.norm(face_normal, axis=1, keepdims=True)
    t1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    t2 = np.cross(face_normal, t1)
    # Barycentric change per unit move along a direction d in the plane:
    # solve [e1 e2] (b1, b2) = d by least squares (exact in the plane).
    basis = np.stack([e1, e2], axis=2)                       # (P, 3, 2)
    gram_inv = np.linalg.inv(np.einsum("pci,pcj->pij", basis, basis))
    out_points, out_normals, out_dist = [], [], []
    for direction in (t1, t2):
        db12 = np.einsum("pij,pcj,pc->pi", gram_inv, basis, direction)
        db = np.stack([-db12[:, 0] - db12[:, 1], db12[:, 0], db12[:, 1]], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            room_forward = np.where(db < 0, -samples.bary / db, np.inf).min(axis=1)
            room_backward = np.where(db > 0, samples.bary / db, np.inf).min(axis=1)
        sign = np.where(room_forward >= room_backward, 1.0, -1.0)
        distance = np.minimum(step, np.maximum(room_forward, room_backward))
        bary = samples.bary + (sign * distance)[:, None] * db
        bary = np.clip(bary, 0.0, 1.0)
        bary /= bary.sum(axis=1, keepdims=True)
        out_points.append(np.einsum("pk,pkc->pc", bary, corners))
        if normals is not None:
            n = interpolate_corners(normals, samples.triangle, bary)
            n /= np.linalg.norm(n, axis=1, keepdims=True)
        else:
            n = face_normal
        out_normals.append(n)
        out_dist.append(distance)
    return (np.concatenate(out_points).astype(np.float32), np.concatenate(out_normals).astype(np.float32),
            np.concatenate(out_dist))


def surface_gradient(truth, neighbour_truth, distances):
    """Gradient magnitude of the luminance along the surface (per metre) from
    the truth at the points (P, 3) and at their two stencil neighbours (2P, 3)."""
    count = len(truth)
    base = luminance(truth)
    neighbours = luminance(neighbour_truth).reshape(2, count)
    d = np.maximum(np.asarray(distances, np.float64).reshape(2, count), 1e-12)
    return np.sqrt((((neighbours - base) / d) ** 2).sum(axis=0))


def transition_mask(gradient, fraction=TRANSITION_FRACTION):
    """The points in the top `fraction` of gradient magnitude (ties at the
    threshold included; points where the light does not change at all are
    never transitions). At least one point when any gradient is non-zero."""
    gradient = np.asarray(gradient, np.float64)
    if not 0 < fraction <= 1:
        raise ValueError(f"fraction must be in (0, 1], got {fraction}")
    if gradient.size == 0 or gradient.max() <= 0:
        return np.zeros(gradient.shape, bool)
    threshold = np.quantile(gradient, 1.0 - fraction)
    return (gradient >= threshold) & (gradient > 0)


def texel_density(uvs, triangles, world_areas, resolution):
    """(T,) texels per square metre of every triangle at `resolution`
    (int or (height, width)): UV area x H x W over world area."""
    height, width = (resolution, resolution) if np.isscalar(resolution) else resolution
    world_areas = np.asarray(world_areas, np.float64)
    return uv_areas(uvs, triangles) * height * width / np.maximum(world_areas, 1e-30)


def texels_per_metre(uvs, triangles, world_areas, resolution, faces=None):
    """(T,) texels per metre along the surface of every triangle's face at
    `resolution` (int or (height, width)): the square root of the face's
    texels (UV area x H x W, summed over its triangles) over its world area.
    `faces` (T,) names the face of each triangle (an n-gon's triangles share
    one value); None makes every triangle its own face, sqrt(texel_density).
    NaN where a face has no (or no finite) world area or UV area."""
    height, width = (resolution, resolution) if np.isscalar(resolution) else resolution
    world = np.asarray(world_areas, np.float64)
    with np.errstate(all="ignore"):
        texels = uv_areas(uvs, triangles) * height * width
    if faces is not None:
        _, face = np.unique(np.asarray(faces), return_inverse=True)
        face = face.ravel()
        with np.errstate(all="ignore"):
            texels = np.bincount(face, texels, minlength=face.max(initial=-1) + 1)[face]
            world = np.bincount(face, world, minlength=face.max(initial=-1) + 1)[face]
    with np.errstate(all="ignore"):
        value = np.sqrt(texels / world)
    value[~(np.isfinite(world) & (world > 0) & np.isfinite(texels))] = np.nan
    return value


def surface_gradient_direction(points, truth, stencil_points, neighbour_truth):
    """(P, 3) unit direction of the luminance gradient along the surface at
    each point, from the truth at its two stencil neighbours (orthogonal
    steps in its triangle's plane, `gradient_stencil`); 0 where the light
    does not change."""
    points = np.asarray(points, np.float64)
    count = len(points)
    base = luminance(truth)
    steps = np.asarray(stencil_points, np.float64).reshape(2, count, 3) - points
    change = luminance(neighbour_truth).reshape(2, count) - base
    squared = np.maximum((steps ** 2).sum(axis=2), 1e-24)
    # Each step's directional derivative times its unit direction; the two directions are orthogonal.
    gradient = ((change / squared)[..., None] * steps).sum(axis=0)
    norm = np.linalg.norm(gradient, axis=1, keepdims=True)
    return np.where(norm > 0, gradient / np.maximum(norm, 1e-300), 0.0)


def texels_across(corner_positions, corner_uvs, point_triangle, directions, resolution):
    """(P,) texels per metre of the layout along each point's surface
    direction `directions` (P, 3): |J d| x resolution, with J the point's
    triangle's map from its plane to UV. corner_positions (T, 3, 3), corner_uvs
    (T, 3, 2). 0 on triangles without area."""
    height, width = (resolution, resolution) if np.isscalar(resolution) else resolution
    corners = np.asarray(corner_positions, np.float64)[point_triangle]
    uvs = np.asarray(corner_uvs, np.float64)[point_triangle] * np.array([width, height])
    edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)  # (P, 3, 2)
    uv_edges = np.stack([uvs[:, 1] - uvs[:, 0], uvs[:, 2] - uvs[:, 0]], axis=2)              # (P, 2, 2)
    gram = np.einsum("pci,pcj->pij", edges, edges)
    det = gram[:, 0, 0] * gram[:, 1, 1] - gram[:, 0, 1] ** 2
    good = det > 1e-24 * np.maximum(gram[:, 0, 0] * gram[:, 1, 1], 1e-300)
    inverse = np.zeros_like(gram)
    inverse[good] = np.linalg.inv(gram[good])
    # The direction's coordinates on the two edges (least squares: exact in the plane), then into UV.
    coefficients = np.einsum("pij,pcj,pc->pi", inverse, edges, np.asarray(directions, np.float64))
    across = np.einsum("pij,pj->pi", uv_edges, coefficients)
    return np.where(good, np.linalg.norm(across, axis=1), 0.0)


def transition_widening_across(corner_positions, uvs_baseline, uvs_refined, point_triangle, directions,
                               transitions, resolution):
    """Refined over baseline texels per metre across the light change
    (`texels_across` along the surface gradient's direction), averaged over
    the transition points: the gain in texels across an edge as the layouts
    give it, stretched charts included. NaN when there are none."""
    selected = np.asarray(transitions, bool) & (np.linalg.norm(directions, axis=1) > 0)
    if not selected.any():
        return float("nan")
    triangle, direction = np.asarray(point_triangle)[selected], np.asarray(directions)[selected]
    before = texels_across(corner_positions, uvs_baseline, triangle, direction, resolution)
    after = texels_across(corner_positions, uvs_refined, triangle, direction, resolution)
    keep = before > 0
    return float((after[keep] / before[keep]).mean()) if keep.any() else float("nan")


def transition_widening(density_baseline, density_refined, point_triangle, transitions):
    """Refined over baseline texel density at the transition points, averaged
    (area ratio; `transition_widening_across` gives the gain in texels
    across the edges). NaN when there are no transition points."""
    ratio = np.asarray(density_refined, np.float64) / np.maximum(np.asarray(density_baseline, np.float64), 1e-30)
    selected = ratio[np.asarray(point_triangle)[np.asarray(transitions, bool)]]
    return float(selected.mean()) if selected.size else float("nan")


# equal_error_interval: the refined map's error +-this fraction, and the
# spread of ratios over which the interval calls its ratio ill-determined.
INTERVAL_TOLERANCE = 0.02
ILL_DETERMINED_SPREAD = 1.25


def equal_error_interval(multipliers, errors, target, tolerance=INTERVAL_TOLERANCE):
    """The equal-error resolutions (equal_error_resolution) of the errors
    `target` x (1 + tolerance) and `target` x (1 - tolerance): (low, high).
    Where the baseline's error hardly falls between two multipliers (a bake
    noise floor, a light the extra texels do not resolve), a 2% change of
    the refined map's error moves its ratio across that whole stretch; a
    wide interval says the ratio is ill-determined there. NaNs when the
    ratio is undefined or the curve flat."""
    low, low_status = equal_error_resolution(multipliers, errors, target * (1.0 + tolerance))
    high, high_status = equal_error_resolution(multipliers, errors, target * (1.0 - tolerance))
    if "flat" in (low_status, high_status) or "undefined" in (low_status, high_status):
        return float("nan"), float("nan")
    return low, high


def equal_error_resolution(multipliers, errors, target, min_drop=0.1):
    """Where does the uniform baseline's error, measured at resolutions
    R x `multipliers` (ascending, the first one 1), reach `target` (the
    refined map's error at R)? Linear interpolation of error against
    log-resolution at the first crossing.

    Returns (ratio, status): status "within" (ratio in the tested range),
    "below" (the refined map is worse than the baseline at R: ratio < 1,
    extrapolated along the first segment, at least multipliers[0] / 4) or
    "above" (better than the baseline at the largest multiplier: ratio is
    that multiplier, a lower bound). When the baseline's error drops by less
    than `min_drop` (a fraction) over the whole range, resolution is not what
    limits it (noise is): (NaN, "flat")."""
    m = np.asarray(multipliers, np.float64)
    e = np.asarray(errors, np.float64)
    if m.ndim != 1 or m.shape != e.shape or len(m) < 2 or np.any(np.diff(m) <= 0) or m[0] <= 0:
        raise ValueError("multipliers must be ascending positive numbers, at least two, one error per multiplier")
    if not np.isfinite(target) or not np.isfinite(e).all():
        return float("nan"), "undefined"
    log_m = np.log(m)
    if e[-1] > (1.0 - min_drop) * e[0]:
        return float("nan"), "flat"
    if target > e[0]:
        slope = (e[1] - e[0]) / (log_m[1] - log_m[0])
        if slope >= 0:
            return float(m[0] / 4), "below"
        ratio = float(np.exp(log_m[0] + (target - e[0]) / slope))
        return max(ratio, float(m[0] / 4)), "below"
    for k in range(1, len(m)):
        if e[k] <= target:
            if e[k - 1] == e[k]:
                return float(m[k - 1]), "within"
            t = (e[k - 1] - target) / (e[k - 1] - e[k])
            return float(np.exp(log_m[k - 1] + t * (log_m[k] - log_m[k - 1]))), "within"
    return float(m[-1]), "above"
