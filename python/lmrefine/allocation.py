"""Chart-level texel allocation: each chart's scale from its signal, then one packed atlas.

The error model (docs/refiner.md, "Chart scaling"): a chart c whose linear
texel scale is s_c (texels per UV unit, relative to the input layout) has a
reconstruction error dominated by its light changes, which falls as
E_c / s_c, where E_c is the gradient energy the chart covers in the first
bake. For a fixed texel budget sum_c A_c s_c^2 (A_c the chart's UV area) the
error sum_c E_c / s_c is smallest at s_c proportional to (E_c / A_c)^(1/3)
(Lagrange). Flat charts would shrink to nothing: a floor on the energy
density and bounds on the relative scale keep every chart large enough for
bilinear lookup and dilation. The packer (lmrefine.pack_charts) then finds
the largest global scale at which all charts fit.
"""

import numpy as np

from .packer import CHART_TOLERANCE, pack_charts
from ._native import find_charts

# Energy-density floor, relative to the mean over charts: a flat chart is
# treated as if it had this much light change, so it shrinks by at most
# (FLOOR)^(1/3) before the scale bounds apply.
ENERGY_FLOOR = 0.05
# repack is kept when the model predicts at most this fraction of the
# unpacked error, and the packed atlas is at least this fraction as dense as
# the input, charts grown by half the padding (padded_utilisation;
# docs/refiner.md, "Chart scaling").
REQUIRED_GAIN = 0.95
MIN_UTILISATION_KEPT = 0.95


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


def triangle_energy(uvs, triangles, energy):
    """Gradient energy each triangle covers: the mean energy at its four
    points (triangle_texels) times its area in texels."""
    rows, cols = triangle_texels(uvs, triangles, energy.shape)
    texels = np.abs(signed_areas(uvs, triangles)) * energy.shape[0] * energy.shape[1]
    return energy[rows, cols].astype(np.float64).mean(axis=1) * texels


def chart_scales(uvs, triangles, charts, energy, min_scale=0.5, max_scale=2.0):
    """Relative linear scale per chart from the error model above, clamped to
    [min_scale, max_scale] around the median chart; also returns (E_c, A_c)."""
    count = int(charts.max()) + 1 if len(charts) else 0
    chart_energy = np.bincount(charts, weights=triangle_energy(uvs, triangles, energy), minlength=count)
    chart_area = np.bincount(charts, weights=np.abs(signed_areas(uvs, triangles)), minlength=count)
    with np.errstate(divide="ignore", invalid="ignore"):
        density = np.where(chart_area > 0, chart_energy / np.maximum(chart_area, 1e-300), 0.0)
    mean = float(np.average(density, weights=chart_area)) if chart_area.sum() > 0 else 0.0
    if not mean > 0:
        return np.ones(count), chart_energy, chart_area
    raw = np.cbrt(density + ENERGY_FLOOR * mean)
    scales = raw / np.median(raw[chart_area > 0])
    return np.clip(scales, min_scale, max_scale), chart_energy, chart_area


def chart_outlines(uvs, triangles, charts, shape):
    """(C,) each chart's area and boundary length in texels. Edges are matched
    by their exact end points, so the layout's charts must be bit-exact
    (pack_charts' output is)."""
    height, width = shape
    corners = uvs[triangles].astype(np.float64) * (width, height)  # (T, 3, 2) texel space
    start = corners.reshape(-1, 2)
    end = np.roll(corners, -1, axis=1).reshape(-1, 2)
    # An edge's key: its chart and its end points in a fixed order.
    forward = (start[:, 0] < end[:, 0]) | ((start[:, 0] == end[:, 0]) & (start[:, 1] <= end[:, 1]))
    low = np.where(forward[:, None], start, end)
    high = np.where(forward[:, None], end, start)
    edge_chart = np.repeat(charts, 3)
    keys = np.column_stack([edge_chart.astype(np.float64), low, high])
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    outline = counts[inverse.ravel()] == 1
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


def repack(source_uvs, refined_uvs, triangles, energy, resolution, padding, min_scale, max_scale, progress=None):
    """Scale the charts of `refined_uvs` by their signal (measured on the
    source layout `source_uvs`, where `energy` was baked) and pack them into
    one atlas. Returns (uvs, report); uvs is None when the packed layout is
    not better than `refined_uvs` by the error model (the report says so)."""
    charts = find_charts(source_uvs, triangles, tolerance=CHART_TOLERANCE)
    scales, chart_energy, _ = chart_scales(source_uvs, triangles, charts, energy, min_scale, max_scale)
    total = chart_energy.sum()
    # No packing can scale the charts beyond filling the whole atlas, gutters
    # aside: when the model's error at that scale is no clear gain, the
    # packer need not run (a single chart filling its atlas, for example).
    area_refined = np.bincount(charts, weights=np.abs(signed_areas(refined_uvs, triangles)), minlength=len(scales))
    largest = 1.0 / np.sqrt(max(float((area_refined * scales ** 2).sum()), 1e-300))
    best = float((chart_energy / (largest * scales)).sum() / total) if total > 0 else 1.0
    if best >= REQUIRED_GAIN:
        return None, {"charts": int(len(scales)), "used": False, "predicted_error": best,
                      "reason": f"even filling the whole atlas the error model predicts {best:.3f} of the unpacked "
                                f"error at best (a repack needs below {REQUIRED_GAIN})"}
    try:
        packed, pack_report = pack_charts(refined_uvs, triangles, charts, scales, resolution, padding,
                                          progress=progress)
    except ValueError as error:  # the charts do not fit at a usable scale: keep the unpacked layout
        return None, {"charts": int(len(scales)), "used": False, "reason": str(error)}
    final = pack_report["chart_scales"]  # linear scale of each chart against refined_uvs
    # Areas and outlines: the packed charts are bit-exact; the input's outlines are theirs unscaled.
    area_after, perimeter_out = chart_outlines(packed, triangles, charts, resolution)
    area_before, _ = chart_outlines(refined_uvs, triangles, charts, resolution)
    # Predicted error of the packed layout relative to refined_uvs (1.0 = the same).
    predicted = float((chart_energy / np.maximum(final, 1e-12)).sum() / total) if total > 0 else 1.0
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
        "padded_utilisation_before": padded_utilisation(area_before, perimeter_out / final, padding, resolution),
        "padded_utilisation_after": padded_utilisation(area_after, perimeter_out, padding, resolution),
        "placement": pack_report["placement"],
        "predicted_error": predicted,
    }
    # The model sees only the edge term: it misses what a packing that wastes
    # the atlas costs the flat charts, so it must promise a clear gain, and
    # the packed atlas must be about as dense as the input for its padding.
    # Density of the charts grown by half the padding, not texels touched: a
    # chart off the texel grid touches more texels than the same chart on it,
    # and shrunk charts need the same gutters (docs/refiner.md).
    report["used"] = bool(predicted < REQUIRED_GAIN and report["padded_utilisation_after"]
                          >= MIN_UTILISATION_KEPT * report["padded_utilisation_before"])
    return (packed if report["used"] else None), report
