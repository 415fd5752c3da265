"""Layouts and gradient maps shaped like real ones, for the refiner's tests
and benchmark (numpy only; no Blender)."""

import numpy as np

# refine_uvs keywords for the small synthetic atlases whose decisions (a packing dense enough or not,
# the re-chart route kept or not) were sized with chart scales within 2x the median chart's, the
# bound before max_chart_scale 4 (docs/refiner.md, "Chosen for the weakest tuning row").
SCALES_WITHIN_2 = {"max_chart_scale": 2.0}


def grid_chart(n, lo=(0.0, 0.0), hi=(1.0, 1.0)):
    """A square chart of n x n quads (2 n^2 triangles) over [lo, hi], per-corner
    UVs (every triangle has its own three UV entries, as Blender's loops)."""
    u = np.linspace(lo[0], hi[0], n + 1)
    v = np.linspace(lo[1], hi[1], n + 1)
    tris = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = (u[j], v[i]), (u[j + 1], v[i]), (u[j + 1], v[i + 1]), (u[j], v[i + 1])
            tris += [(a, b, c), (a, c, d)]  # counter-clockwise in UV
    uvs = np.array(tris, np.float32).reshape(-1, 2)
    return uvs, np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)


def fan_chart(centre, radius, span_degrees, pieces=5):
    """One chart: `pieces` counter-clockwise triangles around `centre`, together spanning `span_degrees`
    (past 360 the last ones lie over the first: a chart that overlaps itself with no triangle flipped, as
    Smart UV Project leaves one where an island folds, on Suzanne)."""
    angles = np.radians(np.linspace(0.0, span_degrees, pieces + 1))
    rim = np.stack([np.cos(angles), np.sin(angles)], -1) * radius * np.linspace(1.0, 0.9, pieces + 1)[:, None]
    points = np.vstack([centre, np.asarray(centre) + rim]).astype(np.float32)
    uvs = points[[(0, k + 1, k + 2) for k in range(pieces)]].reshape(-1, 2)  # per corner, as grid_chart
    return uvs, np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)


def merge(*layouts):
    uvs, triangles, offset = [], [], 0
    for u, t in layouts:
        uvs.append(u)
        triangles.append(t + offset)
        offset += len(u)
    return np.concatenate(uvs), np.concatenate(triangles)


def floor_grid(cells, half):
    """A floor of cells x cells quads over [-half, half]^2 at z = 0, facing +z:
    positions (V, 3) float32 and triangles (T, 3) int32, two per quad."""
    xs = np.linspace(-half, half, cells + 1)
    positions = np.array([(x, y, 0.0) for y in xs for x in xs], np.float32)
    triangles = []
    for j in range(cells):
        for i in range(cells):
            a, b = j * (cells + 1) + i, j * (cells + 1) + i + 1
            c, d = (j + 1) * (cells + 1) + i + 1, (j + 1) * (cells + 1) + i
            triangles += [(a, b, c), (a, c, d)]
    return positions, np.array(triangles, np.int32)


def plane(n=64, margin=0.05):
    """One finely tessellated chart: a plane of n x n quads with a margin."""
    return grid_chart(n, (margin, margin), (1 - margin, 1 - margin))


def lightmap_pack(charts_across=16, margin_texels=2, resolution=256, quads=1, seed=0):
    """Like Blender's Lightmap Pack: many small square charts in rows with a
    margin of `margin_texels` between them (and at the border)."""
    rng = np.random.default_rng(seed)
    margin = margin_texels / resolution
    cell = (1 - margin) / charts_across
    layouts = []
    for i in range(charts_across):
        for j in range(charts_across):
            lo = (margin + j * cell, margin + i * cell)
            size = (cell - margin) * rng.uniform(0.7, 1.0)
            layouts.append(grid_chart(quads, lo, (lo[0] + size, lo[1] + size)))
    return merge(*layouts)


def smart_uv(resolution=256, margin_texels=4, n=24):
    """Like Smart UV Project: a few large charts of different sizes."""
    m = margin_texels / resolution
    boxes = [((m, m), (0.6, 0.6)), ((0.6 + m, m), (1 - m, 0.45)), ((0.6 + m, 0.45 + m), (1 - m, 1 - m)),
             ((m, 0.6 + m), (0.3, 1 - m)), ((0.3 + m, 0.6 + m), (0.6, 1 - m))]
    return merge(*(grid_chart(n, lo, hi) for lo, hi in boxes))


def finite_difference_gradient(lightmap, mask=None):
    """A stand-in for gradient_map: absolute light differences to the next
    texel, one channel per direction and sense (r: +row, g: +column,
    b: -row, a: -column), 0 on uncovered texels."""
    lm = np.asarray(lightmap, np.float64)
    g = np.zeros(lm.shape + (4,))
    g[:-1, :, 0] = np.abs(lm[1:] - lm[:-1])
    g[:, :-1, 1] = np.abs(lm[:, 1:] - lm[:, :-1])
    g[1:, :, 2] = np.abs(lm[1:] - lm[:-1])
    g[:, 1:, 3] = np.abs(lm[:, 1:] - lm[:, :-1])
    if mask is not None:
        g[~mask] = 0
    return g.astype(np.float32)


def shadow_edge_lightmap(resolution, position=0.5, angle=0.3):
    """Lit on one side of a straight line, dark on the other (a hard shadow)."""
    y, x = np.mgrid[0:resolution, 0:resolution] + 0.5
    side = (x - position * resolution) * np.cos(angle) + (y - position * resolution) * np.sin(angle)
    return np.where(side > 0, 1.0, 0.1).astype(np.float32)
