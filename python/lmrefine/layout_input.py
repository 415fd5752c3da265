"""A user's lightmap UV layout as the refiner takes it (no Blender needed).

The Blender add-on reads a UV map and a mesh into numpy and asks these
functions what to do with them, so the rules are tested here with plain
arrays: corners of one vertex that differ by a rounding error get one UV
(`weld_uvs`), and broken vertices or UV triangles of zero area are found
before they reach the refiner (`geometry_problems`). Whether a refined
layout is worse than its source is `lmrefine.backoff.failures`, the rule
refine_uvs itself applies.
"""

import numpy as np

# Blender's own tolerance for "these face corners share a UV" (STD_UV_CONNECT_LIMIT).
UV_CONNECT_LIMIT = 1e-4

# A UV triangle smaller than this (in texels) carries no texel of its own.
ZERO_UV_AREA_TEXELS = 1e-6


def weld_uvs(uvs, corner_vertex, limit=UV_CONNECT_LIMIT):
    """Corner UVs with the corners of one vertex that lie within `limit`
    of each other (per axis) joined to one UV; returns a new float array.

    Blender stores one UV per face corner, and corners a user sees as
    connected often differ in the last bits (even in Blender's primitives);
    lmrefine joins charts by bit-identical UVs, so unwelded they would read
    as many touching charts. Corners are grouped per vertex in (u, v) order:
    a corner joins the group of the previous one when both coordinates are
    within `limit` of it. UVs less than `limit` outside [0, 1] are clamped
    (packers round to 1.0000001).

    uvs: (L, 2) per corner; corner_vertex: (L,) the vertex of each corner.
    """
    uvs = np.asarray(uvs)
    corner_vertex = np.asarray(corner_vertex)
    if uvs.ndim != 2 or uvs.shape[1] != 2:
        raise ValueError(f"uvs has shape {uvs.shape}; expected (L, 2) UVs, one per face corner")
    if corner_vertex.shape != (len(uvs),):
        raise ValueError(f"corner_vertex has shape {corner_vertex.shape}; expected ({len(uvs)},), the vertex "
                         "index of each corner")
    welded = uvs.copy()
    if len(uvs) == 0:
        return welded
    order = np.lexsort((uvs[:, 1], uvs[:, 0], corner_vertex))
    sorted_uvs = uvs[order]
    new_group = np.ones(len(order), dtype=bool)
    new_group[1:] = ((corner_vertex[order][1:] != corner_vertex[order][:-1])
                     | (np.abs(np.diff(sorted_uvs, axis=0)) > limit).any(axis=1))
    first = np.flatnonzero(new_group)[np.cumsum(new_group) - 1]  # each corner's group leader
    welded[order] = sorted_uvs[first]
    edge = ((welded < 0.0) & (welded > -limit)) | ((welded > 1.0) & (welded < 1.0 + limit))
    welded[edge] = np.clip(welded[edge], 0.0, 1.0)
    return welded


# As the baker (native/src/bake/scene.cpp): a triangle has zero area in 3-D
# when twice its area is below FLAT_3D times its longest edge squared, and
# no coordinate may lie beyond MAX_COORDINATE.
FLAT_3D = 1e-7
MAX_COORDINATE = 1e9


def geometry_problems(positions, corner_vertex, uvs, triangles, resolution):
    """(triangles of zero area in 3-D, triangles of zero UV area at
    `resolution` that do have 3-D area, vertices at NaN, Inf or beyond
    MAX_COORDINATE).

    positions: (V, 3) vertex positions (world space, as baked);
    corner_vertex: (L,) the vertex of each corner; uvs (L, 2) and triangles
    (T, 3, corner indices) the layout; resolution: the lightmap's side in
    texels. Triangles of zero 3-D area need no texels (the baker skips
    them), so their UV area does not matter; a UV triangle covering less
    than ZERO_UV_AREA_TEXELS texels of a real 3-D triangle has no texel of
    its own.
    """
    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles)
    with np.errstate(all="ignore"):
        bad_vertices = int(np.count_nonzero(~(np.abs(positions) <= MAX_COORDINATE).all(axis=1)))
        corners = positions[np.asarray(corner_vertex)[triangles]]
        e1, e2, e3 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], corners[:, 2] - corners[:, 1]
        area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
        longest = np.max([np.einsum("ij,ij->i", e, e) for e in (e1, e2, e3)], axis=0) if len(e1) else area2
        flat = ~(area2 > FLAT_3D * longest)
    uv = np.asarray(uvs, np.float64)[triangles] * resolution  # texel units
    edge1, edge2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    texel_area = 0.5 * np.abs(edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0])
    zero_uv = int(np.count_nonzero((texel_area < ZERO_UV_AREA_TEXELS) & ~flat))
    return int(np.count_nonzero(flat)), zero_uv, bad_vertices


def describe_problems(check, padding):
    """The problems of a check_layout report in words ("2 flipped, charts
    1.50 texels apart, padding is 2"); empty when there are none."""
    problems = [f"{check[key]} {key}" for key in ("flipped", "degenerate", "overlapping", "out_of_bounds")
                if check[key]]
    if check["min_gutter_texels"] < padding:
        problems.append(f"charts {check['min_gutter_texels']:.2f} texels apart, padding is {padding}")
    return ", ".join(problems)
