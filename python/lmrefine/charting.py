"""rechart: a new lightmap layout from the mesh itself (docs/refiner.md, "Re-charting").

Lightmap Pack cuts one chart per face, so the refinement inside charts has
nothing to move. rechart groups neighbouring faces whose normals stay within
an angle into charts (native/src/chart/charting.cpp), unwraps each with a
least-squares conformal map (conformal_map.cpp, Eigen's sparse LDLT), scales
it to its world-space area and packs all of them with the atlas packer
(pack_charts), so every chart has the same texel density.
"""

from typing import NamedTuple

import numpy as np

from . import _native
from .metrics import uv_areas
from .packer import pack_charts

# Largest angle between a chart's face normals and its first (largest)
# face's. On a flat-shaded mesh every crease is a step in the light (a crease
# of a degrees changes N.L by up to sin a: 17% at 10 degrees), and a chart
# that spans it blurs the step across its texels; on the tuning scenes
# angles up to 17 degrees gave the lowest error, Smart UV Project's 66 the
# highest (docs/refiner.md, "Re-charting").
DEFAULT_ANGLE = 10.0
# The same across a smooth-shaded edge (when shading normals are given):
# there the light has no step to cut at, and the angle only bounds a chart's
# curvature (a cylinder's charts span up to twice this arc). Chosen a priori
# (docs/refiner.md, "Smooth-shaded meshes").
SMOOTH_ANGLE = 45.0
# The packer scales charts up by at most this (native/src/pack/packer.cpp's
# bound on the global scale). Charts come from the unwrap at their world
# size, so a mesh under 1e-24 square units of surface whose charts are all
# under 1e-12 units across was packed shrunken, or collapsed with advice
# about the padding and the resolution (found by a crash hunt).
MAX_PACK_SCALE = 1e12


class RechartResult(NamedTuple):
    """What rechart returns; unpacks as ``uvs, report = rechart(...)``.

    uvs: (3T, 2) float32 per-corner UVs, corner k of triangle t at row 3t + k.
    report: dict, see rechart.
    """

    uvs: np.ndarray
    report: dict


def corner_triangles(triangle_count):
    """(T, 3) int32 indices into per-corner UVs (3T, 2): 3t, 3t+1, 3t+2."""
    return np.arange(3 * int(triangle_count), dtype=np.int32).reshape(-1, 3)


def rechart(positions, triangles, angle=DEFAULT_ANGLE, resolution=256, padding=2.0, *, weld_tolerance=None,
            rotations=True, progress=None, normals=None, smooth_angle=SMOOTH_ANGLE, polygons=None):
    """A new lightmap layout for a triangle mesh: conformal charts, uniform texel density, packed.

    Faces sharing an edge in 3D (positions closer than ``weld_tolerance``
    are one vertex, so a mesh split along UV seams is joined again) join a
    chart while their normal is within ``angle`` of the chart's first face's
    (the largest face not yet in a chart). Each chart is flattened with a
    least-squares conformal map (angles kept; a planar chart keeps its shape
    exactly), turned to its smallest bounding box and scaled so its UV area
    is its world area; a chart whose unwrap folds or overlaps itself is
    charted again with half the angle. ``pack_charts`` then places all charts
    in [0, 1]^2 at ``resolution`` with ``padding`` texels between them.
    Deterministic.

    Args:
        positions: (V, 3) vertex positions, any real dtype. Vertices no
            triangle uses are ignored.
        triangles: (T, 3) integer indices into ``positions`` (triangulate
            quads and n-gons first). Degenerate triangles (zero area, a
            sliver, two corners at one position) are not charted with their
            neighbours: each gets a small chart of its own and is counted in
            the report.
        angle: degrees, in (0, 90).
        resolution: int or (height, width) of the lightmap the layout is for.
        padding: texels between charts, as ``check_layout`` measures it.
        weld_tolerance: distance within which positions are one vertex;
            None: 1e-6 of the diagonal of the mesh's bounding box.
        rotations: let the packer turn charts by a quarter turn.
        normals: the mesh's shading normals, (V, 3) per vertex or (T*3, 3)
            per corner, or None (every edge hard, as a flat-shaded mesh).
            An edge whose two faces have the same shading normals at both
            ends (within about a degree) is smooth-shaded: the light does
            not step there, and faces across it join within ``smooth_angle``
            instead of ``angle``. A zero or non-finite normal makes its
            edges hard.
        smooth_angle: degrees, in (0, 90).
        polygons: (T,) integer polygon id per triangle, or None (every
            triangle its own polygon). Triangles with one id are one polygon
            of the source mesh (a quad's or an n-gon's triangles, which share
            their corners' UVs in Blender) and always join one chart, so no
            chart border runs through a polygon; ``rechart_route`` passes
            them (``polygon_ids``).
        progress: callable ``progress(fraction, stage)``; returning False
            cancels (lmrefine.CancelledError). The native work runs with the
            GIL released.

    Returns:
        RechartResult ``(uvs, report)``; ``uvs`` (3T, 2) float32 per corner
        (use ``corner_triangles(T)`` as the layout's triangles). ``report``,
        measured on the output layout:

        * charts, grown_charts (charts the angle alone made), split_charts
          (charts grown again because their unwrap folded), degenerate_triangles,
          welded_vertices, angle, smooth_angle (None without normals).
        * angle_error_deg_mean / angle_error_deg_p95: the triangles' corner
          angles in UV against 3D, area-weighted mean and 95th percentile of
          the absolute difference (0 for a perfectly conformal layout).
        * density_spread: 95th over 5th percentile (area-weighted) of the
          texels per world area of the triangles (1 = uniform density).
        * texels_per_unit: texels per world unit of length, on average.
        * utilisation, area_utilisation, global_scale: the packer's.
        * layout: ``check_layout(uvs, triangles, resolution, padding)``.
        * seconds.

    Raises:
        ValueError: bad shapes or values (naming the argument), no triangle
            with an area, or a resolution too small for the charts and padding.
        TypeError: a wrong type for a scalar argument.
        lmrefine.CancelledError: the progress callback returned False.
    """
    import time

    start = time.perf_counter()
    if normals is not None and np.asarray(normals).dtype.kind == "f":
        with np.errstate(over="ignore"):  # an absurd normal becomes Inf: its edges count as hard
            normals = np.asarray(normals).astype(np.float32)
    world_uvs, charts, report = _native.rechart_mesh(positions, triangles, angle=angle,
                                                     weld_tolerance=weld_tolerance, progress=progress,
                                                     normals=normals, smooth_angle=smooth_angle,
                                                     polygons=polygons)
    layout_triangles = corner_triangles(len(charts))
    _check_world_size(world_uvs, layout_triangles)
    packed, pack_report = pack_charts(world_uvs, layout_triangles, charts, None, resolution, padding,
                                      rotations=rotations, progress=progress)
    check = _native.check_layout(packed, layout_triangles, resolution, padding)
    report["angle"] = float(angle)
    report["smooth_angle"] = None if normals is None else float(smooth_angle)
    report["padding"] = float(padding)
    report.update(_distortion(np.asarray(positions, np.float64)[np.asarray(triangles)], packed))
    height, width = pack_report["resolution"]
    report["texels_per_unit"] = float(pack_report["global_scale"] * np.sqrt(height * width))
    for key in ("utilisation", "area_utilisation", "global_scale"):
        report[key] = pack_report[key]
    report["chart_ids"] = charts
    report["layout"] = check
    report["seconds"] = time.perf_counter() - start
    return RechartResult(packed, report)


def _check_world_size(world_uvs, triangles):
    """ValueError naming the mesh's size when its charts (rechart_mesh's, at world size, each
    from the origin) are too small for the packer to scale up into the atlas."""
    area = float(uv_areas(world_uvs, triangles).sum())
    widest = float(np.asarray(world_uvs, np.float64).max(initial=0.0))
    if min(1.0 / np.sqrt(max(area, 1e-300)), 1.0 / max(widest, 1e-300)) > MAX_PACK_SCALE:
        raise ValueError(f"the mesh is too small to lay out: its {len(triangles)} triangles hold {area:.3g} square "
                         f"units of surface, its widest chart is {widest:.3g} units across, and charts keep their "
                         f"world size until the packer scales them up, by at most {MAX_PACK_SCALE:g}; scale the mesh "
                         "up (apply its object scale, or model in larger units)")


def _distortion(corners_3d, uvs):
    """Angle error and texel-density spread of a per-corner layout against its triangles in 3D."""
    uv = np.asarray(uvs, np.float64).reshape(-1, 3, 2)
    world_area = 0.5 * np.linalg.norm(np.cross(corners_3d[:, 1] - corners_3d[:, 0],
                                               corners_3d[:, 2] - corners_3d[:, 0]), axis=1)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    good = world_area > 1e-12 * max(float(world_area.max(initial=0.0)), 1e-300)
    if not good.any():
        return {"angle_error_deg_mean": 0.0, "angle_error_deg_p95": 0.0, "density_spread": 1.0}
    errors = np.abs(_corner_angles(uv[good]) - _corner_angles(corners_3d[good]))  # (G, 3)
    weights = world_area[good]
    density = uv_area[good] / world_area[good]
    return {
        "angle_error_deg_mean": float(np.degrees(np.average(errors.mean(axis=1), weights=weights))),
        "angle_error_deg_p95": float(np.degrees(_weighted_percentile(errors.max(axis=1), weights, 95))),
        "density_spread": float(_weighted_percentile(density, weights, 95) /
                                max(_weighted_percentile(density, weights, 5), 1e-300)),
    }


def _corner_angles(corners):
    """(N, 3) interior angles of triangles given as (N, 3, D) corners."""
    angles = []
    for k in range(3):
        a = corners[:, (k + 1) % 3] - corners[:, k]
        b = corners[:, (k + 2) % 3] - corners[:, k]
        cosine = np.sum(a * b, axis=1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        angles.append(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return np.stack(angles, axis=1)


def _weighted_percentile(values, weights, q):
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    return float(values[order][min(np.searchsorted(cumulative, cumulative[-1] * q / 100.0), len(values) - 1)])
