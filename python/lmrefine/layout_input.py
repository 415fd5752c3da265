"""A user's lightmap UV layout as the refiner takes it (no Blender needed).

The Blender add-on reads a UV map and a mesh into numpy and asks these
functions what to do with them, so the rules are tested here with plain
arrays: corners of one vertex that differ by a rounding error get one UV
(`weld_uvs`), and faces or UV triangles of zero area are refused before they
reach the refiner (`zero_area_counts`). Whether a refined layout is worse
than its source is `lmrefine.backoff.failures`, the rule refine_uvs itself
applies.
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


def zero_area_counts(face_areas, uvs, triangles, resolution):
    """(faces of zero 3-D area, UV triangles of zero area at `resolution`).

    face_areas: (F,) the mesh's face areas; uvs (L, 2) and triangles (T, 3)
    the layout; resolution: the lightmap's side in texels. A UV triangle
    counts as zero when it covers less than ZERO_UV_AREA_TEXELS texels."""
    zero_3d = int(np.count_nonzero(np.asarray(face_areas) <= 0.0))
    corners = np.asarray(uvs, np.float64)[np.asarray(triangles)] * resolution  # texel units
    edge1 = corners[:, 1] - corners[:, 0]
    edge2 = corners[:, 2] - corners[:, 0]
    texel_area = 0.5 * np.abs(edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0])
    return zero_3d, int(np.count_nonzero(texel_area < ZERO_UV_AREA_TEXELS))


def describe_problems(check, padding):
    """The problems of a check_layout report in words ("2 flipped, charts
    1.50 texels apart, padding is 2"); empty when there are none."""
    problems = [f"{check[key]} {key}" for key in ("flipped", "degenerate", "overlapping", "out_of_bounds")
                if check[key]]
    if check["min_gutter_texels"] < padding:
        problems.append(f"charts {check['min_gutter_texels']:.2f} texels apart, padding is {padding}")
    return ", ".join(problems)
