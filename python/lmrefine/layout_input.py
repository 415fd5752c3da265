"""A user's lightmap UV layout as the refiner takes it (no Blender needed).

The Blender add-on reads a UV map and a mesh into numpy and asks these
functions what to do with them, so the rules are tested here with plain
arrays: corners of one vertex that differ by a rounding error get one UV
(`weld_uvs`), broken vertices or UV triangles of zero area are found
before they reach the refiner (`geometry_problems`), and so are modifiers
that copy charts onto each other (`copied_overlap`) and closed meshes
whose normals point inward, which bake black (`inside_out_shells`). Whether a refined
layout is worse than its source is `lmrefine.backoff.failures`, the rule
refine_uvs itself applies.
"""

import numpy as np

from ._native import find_charts

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


# check_layout's counts in a user's words, (one, more); out_of_bounds counts
# UV corners, the others triangles. The add-on names failed checks with them (operators._check_words).
PROBLEM_WORDS = {"flipped": ("flipped triangle", "flipped triangles"),
                 "degenerate": ("triangle without area", "triangles without area"),
                 "overlapping": ("overlapping triangle", "overlapping triangles"),
                 "out_of_bounds": ("UV outside the map", "UVs outside the map")}


def describe_problems(check, padding):
    """The problems of a check_layout report in words read inside a warning
    ("2 flipped triangles, charts 1.50 texels apart where the padding asks
    for 2"); empty when there are none."""
    problems = [f"{check[key]} {words[check[key] != 1]}" for key, words in PROBLEM_WORDS.items() if check[key]]
    if check["min_gutter_texels"] < padding:
        problems.append(f"charts {check['min_gutter_texels']:.2f} texels apart where the padding asks for "
                        f"{padding:g}")
    return ", ".join(problems)


# Modifiers that copy faces with their UVs (the copies then share texels);
# named in the message when a layout's copies overlap.
COPYING_MODIFIERS = ("ARRAY", "MIRROR", "SOLIDIFY", "SCREW")
# More than this share of the evaluated triangles overlapping beyond the
# source layout's own share: the modifiers copied charts onto each other. A
# copy overlaps with all its triangles (a half or more of the mesh); a
# subdivided layout's rounding far fewer.
COPIED_OVERLAP_SHARE = 0.01


def copied_overlap(source_check, source_triangles, evaluated_check, evaluated_triangles):
    """Triangles of the evaluated layout (modifiers applied) that overlap
    beyond the source layout's own share, when that is more than
    COPIED_OVERLAP_SHARE of them (else 0). The checks are check_layout's of
    the same UV map before and after the modifiers."""
    if evaluated_triangles == 0:
        return 0
    expected = source_check["overlapping"] / max(source_triangles, 1) * evaluated_triangles
    extra = evaluated_check["overlapping"] - expected
    return int(round(extra)) if extra > COPIED_OVERLAP_SHARE * evaluated_triangles else 0


def inside_out_shells(positions, triangles):
    """(closed shells whose faces point inward, closed shells) of a mesh.

    positions: (V, 3) vertex positions in the mesh's own space (its winding
    makes its normals there; an object's negative scale is not a flip);
    triangles: (T, 3) vertex indices. A shell is a connected part; it is
    closed when every edge joins exactly two of its triangles, wound
    opposite ways, and then its normals point inward exactly when its signed
    volume is negative. Both bakers light the side a face's normal points
    to, so an inside-out shell bakes black. Open shells are not judged.
    """
    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(triangles) == 0:
        return 0, 0
    # find_charts joins triangles that share an index: with one distinct
    # point per vertex, its charts are the mesh's connected shells.
    points = np.zeros((len(positions), 2), np.float64)
    points[:, 0] = np.arange(len(positions))
    shell = find_charts(points, triangles.astype(np.int32))
    shells = int(shell.max()) + 1
    start, end = triangles.reshape(-1), np.roll(triangles, -1, axis=1).reshape(-1)
    count = max(len(positions), 1)
    # An edge is closed when it is used once each way: its undirected key twice, the two directions summing to 0.
    _, inverse, uses = np.unique(np.minimum(start, end) * count + np.maximum(start, end), return_inverse=True,
                                 return_counts=True)
    direction = np.where(start < end, 1.0, -1.0)
    closed_edge = (uses[inverse] == 2) & (np.bincount(inverse, weights=direction, minlength=len(uses))[inverse] == 0)
    corner_shell = np.repeat(shell, 3)
    open_shell = np.bincount(corner_shell, weights=~closed_edge, minlength=shells) > 0
    corners = positions[triangles]
    # Volume about each shell's centre, so far-away shells keep their digits.
    size = np.maximum(np.bincount(shell, minlength=shells), 1)
    centre = np.stack([np.bincount(shell, weights=corners[:, :, k].mean(axis=1), minlength=shells) / size
                       for k in range(3)], axis=1)
    local = corners - centre[shell][:, None, :]
    volume = np.bincount(shell, weights=np.einsum("ij,ij->i", local[:, 0], np.cross(local[:, 1], local[:, 2])) / 6.0,
                         minlength=shells)
    area = np.bincount(shell, weights=0.5 * np.linalg.norm(np.cross(local[:, 1] - local[:, 0],
                                                                   local[:, 2] - local[:, 0]), axis=1),
                       minlength=shells)
    # A flat closed shell (a quad doubled back to back) has no inside: not judged.
    solid = ~open_shell & (np.abs(volume) > 1e-6 * area ** 1.5)
    return int(np.count_nonzero(solid & (volume < 0))), int(np.count_nonzero(~open_shell))
