"""pack_charts: the atlas packer (docs/packer.md).

Moves whole charts into one lightmap atlas, each by its own uniform scale, a
quarter turn or none, and a translation, so every chart is as large as the
atlas allows and at least `padding` texels from every other chart. The
native kernel (native/src/pack/) fits charts by their rasterized texel
footprints, not their bounding boxes.
"""

from typing import NamedTuple

import numpy as np

from . import _native

# UV distance within which corners are one corner: find_charts joins the
# triangles (Blender's layouts are not bit-exact) and the packer snaps them
# together in its output. 1e-5 is 0.01 texel at 1024^2, well below any gutter.
CHART_TOLERANCE = 1e-5


class PackResult(NamedTuple):
    """What pack_charts returns; unpacks as ``uvs, report = pack_charts(...)``.

    uvs: (N, 2) float32, the packed per-corner UVs (a new array).
    report: dict, see pack_charts.
    """

    uvs: np.ndarray
    report: dict


def pack_charts(uvs, triangles, charts, scales, resolution, padding=2.0, rotations=True, progress=None, *,
                tolerance=CHART_TOLERANCE, subdivision=2, boxes=True, fixed_scale=None):
    """Pack a layout's charts into one atlas, [0, 1]^2, as large as it allows.

    Every chart moves as a whole: chart c is scaled by
    ``global_scale * scales[c]``, turned by a multiple of 90 degrees (if
    ``rotations``) and translated, so its triangles keep their shapes and
    orientation. The packer searches the largest ``global_scale`` at which
    every chart fits; charts are fitted by their conservative texel footprint
    at ``resolution`` (the texels ``coverage_mask`` would mark), dilated by
    ``padding``, so concave charts nest and small charts fill holes; or by
    their bounding boxes at continuous positions where that fits them larger
    (``boxes``).
    Deterministic: the same input gives the same output, whatever the
    thread count. Give all objects that share an atlas in one call.

    Args:
        uvs: (N, 2) per-corner UVs, anywhere (not only in [0, 1]).
        triangles: (T, 3) integer indices into ``uvs``.
        charts: (T,) integer chart id per triangle (ids 0..C-1 with C <= T;
            an id no triangle has is an empty chart), or None for
            ``find_charts(uvs, triangles, tolerance=tolerance)``. A chart moves
            as one piece, so a UV index may not be used by two charts.
        scales: (C,) relative linear scale per chart, finite and > 0, or None
            for all 1 (a uniform repack: every chart keeps its relative size).
        resolution: int or (height, width), the target lightmap.
        padding: smallest distance between two charts in texels, as
            ``check_layout`` measures it (exact distance between chart
            boundaries); the output passes
            ``check_layout(uvs, triangles, resolution, padding)`` whenever
            the input has no overlaps or degenerate triangles inside a chart
            (those move with their chart and stay; none is added).
        rotations: allow quarter turns.
        progress: callable ``progress(fraction, stage)``; returning False
            cancels (lmrefine.CancelledError). The native work runs with the
            GIL released.
        tolerance: UV distance within which a chart's corners are one
            corner: they are snapped together in the output (and, with
            ``charts=None``, join charts).
        subdivision: footprints and positions on a grid this many times
            finer than the texels (1-8, resolution * subdivision <= 32768):
            charts land on sub-texel positions, so small charts lose less to
            the grid; time grows about linearly.
        boxes: also place the charts as bounding boxes at continuous
            positions (shelves, then a skyline) and keep that when it
            reaches a 1% larger global scale: rectangular charts (Lightmap
            Pack's, one per face) fit exactly, where the footprint grid
            rounds up every small chart and gutter. False: footprints only.
        fixed_scale: None (search the global scale), or a global scale > 0
            to place the charts at without a search: one placement of the
            footprints, and of the boxes where that fails (``boxes``);
            ValueError when neither fits. What the atlas fill asks
            (allocation.grow_into_free_space): does a chart grown by this
            much still fit beside the others at their sizes?

    Returns:
        PackResult ``(uvs, report)``. ``uvs`` (N, 2) float32: the packed
        layout (UVs no triangle uses are copied). ``report`` (measured on
        the output layout):

        * utilisation: fraction of the atlas's texels covered by charts in
          the output (``coverage_mask``); utilisation_input: the same for
          the input (its texels inside [0, 1]^2). Texels a chart only
          touches count: a chart off the texel grid covers more texels
          than one aligned to it at the same size.
        * area_utilisation: the output's chart area over the atlas area
          (triangle areas, no texel grid): the texel density the atlas
          reaches; area_utilisation_input: the same for the input
          (overlapping triangles count twice).
        * global_scale: the scale found; scale_bound: its upper bound (total
          chart area = atlas area, and every chart's bounding box inside
          the atlas).
        * chart_scales (C,) float64: each chart's linear scale from input to
          output, ``global_scale * scales``.
        * rotations (C,) int32: quarter turns counter-clockwise on the
          image, 0 or 1 (turned in texel space, so a chart's texel shape is
          kept on a non-square atlas too).
        * transforms (C, 2, 3) float64: chart c's corner ``uv`` (after the
          tolerance snap) moves to ``transforms[c, :, :2] @ uv +
          transforms[c, :, 2]``; on a square atlas the 2 x 2 part is
          ``chart_scales[c]`` times the identity or a quarter turn.
        * offsets (C, 2) float64: ``transforms[:, :, 2]``.
        * chart_ids (T,) int32: the charts packed (``charts`` or found).
        * placement: "footprints" or "boxes", the placement kept.
        * charts, trials (placements the scale searches tried),
          footprint_texels, padding, resolution (height, width), seconds.

    Raises:
        ValueError: bad shapes or values (naming the argument), a UV index
            used by two charts, charts that do not fit even at a tiny
            scale (a resolution too small for the padding and chart count),
            or with ``fixed_scale`` at that scale.
        lmrefine.CancelledError: the progress callback returned False.
    """
    new_uvs, report = _native.pack_charts(uvs, triangles, resolution, padding, charts=charts, scales=scales,
                                          rotate=rotations, progress=progress, tolerance=tolerance,
                                          subdivision=subdivision, boxes=boxes, fixed_scale=fixed_scale)
    report["offsets"] = report["transforms"][:, :, 2]
    if _flat_count(new_uvs, triangles) > _flat_count(uvs, triangles):
        if fixed_scale is not None:
            raise ValueError(f"at fixed_scale {fixed_scale:.3g} the charts' triangles collapse to lines: give a "
                             "larger fixed_scale (or None to search the largest that fits)")
        # The scale search can end at a scale so small (absurd scales, a
        # padding wider than the atlas) that charts collapse in float32.
        raise ValueError(f"the charts fit only at a global scale of {report['global_scale']:.3g}, where their "
                         "triangles collapse to lines: lower the padding, raise the resolution or give scales "
                         "within a sane range (their ratio sets how small the smallest chart gets)")
    return PackResult(new_uvs, report)


def _flat_count(uvs, triangles):
    """Triangles check_layout calls degenerate (collinear corners, relative area below 1e-7)."""
    corners = np.asarray(uvs, np.float64)[np.asarray(triangles)]
    e1, e2, e3 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], corners[:, 2] - corners[:, 1]
    cross = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    longest = np.max([np.sum(e * e, axis=1) for e in (e1, e2, e3)], axis=0)
    return int(np.count_nonzero(~(cross > 1e-7 * longest)))
