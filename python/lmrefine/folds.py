"""Charts folded over creases: where a source layout's charts bend over sharp mesh edges.

A chart that spans a crease (two faces whose normals differ by more than the
re-chart angle) gets a lightmap that changes abruptly there: the two faces
face the light differently. Inside a chart the bake blurs that step over the
texels that straddle the crease, like a shadow edge, and a refinement only
narrows the blur; where a layout cuts the chart at the crease, each side is
baked and dilated on its own and the step costs nothing. Blender's Smart UV
Project joins faces up to 66 degrees apart into one chart, so its atlases
fold over many creases that lmrefine.rechart cuts. The error model of the
re-chart route (rechart_route.predicted_error) counts the folds' light
changes only in layouts that keep them inside a chart. Where the mesh is
smooth-shaded across a fold (the same shading normals on both sides) the
light does not step: such a fold still opens the route (Smart UV's charts
span it), but its light changes are not counted as the fold's.
docs/refiner.md, "Smooth-shaded meshes".
"""

from dataclasses import dataclass

import numpy as np

from . import _native
from .packer import CHART_TOLERANCE
from .rows import group_rows

# Texels on either side of a fold's UV segment whose light changes are the
# fold's: the bake's step spreads over the texels that straddle the crease
# and its neighbours (the gradient map's filter is two texels wide).
BAND_TEXELS = 1.5
# The folds' texel bounding boxes searched at most, in atlases: folds inside
# the charts of a layout that does not overlap itself stay far below.
MAX_SEARCH_TEXELS = 64
# Shading normals this close (as native/src/chart/charting.cpp) at both ends
# of an edge: the mesh is smooth-shaded there, and the light has no step.
SMOOTH_COS = 0.9999


@dataclass
class Folds:
    """Creases inside the charts of a source layout.

    faces: (F, 2) the two triangles of each fold; corner: (F,) the corner of
    faces[:, 0] at which the fold's edge starts; length: (F,) world length;
    energy: (F,) gradient energy of the source bake in the fold's band (0
    for a smooth-shaded fold); band: (H, W) bool, the texels of every
    flat-shaded fold's band; total_energy: the source bake's gradient energy
    over the layout; smooth: (F,) bool, the mesh smooth-shaded across the
    fold (no step in the light; all False without shading normals)."""
    faces: np.ndarray
    corner: np.ndarray
    length: np.ndarray
    energy: np.ndarray
    band: np.ndarray
    total_energy: float
    smooth: np.ndarray = None

    @property
    def energy_fraction(self):
        return float(self.energy.sum() / self.total_energy) if self.total_energy > 0 else 0.0

    def energy_removed(self, layout_uvs, triangles):
        """Per triangle, the fold energy that `layout_uvs` no longer holds
        inside a chart (folds it cuts), half to each of the fold's faces."""
        removed = np.zeros(len(triangles))
        if not len(self.faces):
            return removed
        charts = _native.find_charts(layout_uvs, triangles, tolerance=CHART_TOLERANCE)
        cut = charts[self.faces[:, 0]] != charts[self.faces[:, 1]]
        for side in (0, 1):
            np.add.at(removed, self.faces[cut, side], 0.5 * self.energy[cut])
        return removed


def creases(positions, triangles, angle):
    """Mesh edges between two triangles whose normals differ by more than
    `angle` degrees. `positions` (N, 3) per UV index; corners at the same
    position are one vertex. Returns (faces (C, 2), corner (C,), length
    (C,)): the corner of faces[:, 0] where the edge starts. Triangles with no
    area and edges used by more than two triangles are left out."""
    triangles = np.asarray(triangles, np.int64)
    count = len(triangles)
    empty = (np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0))
    if count == 0:
        return empty
    corners = np.asarray(positions, np.float64)[triangles]  # (T, 3, 3)
    with np.errstate(over="ignore", invalid="ignore"):  # absurd positions: no normal, left out
        face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        norms = np.linalg.norm(face_normals, axis=1)
    usable = np.isfinite(norms) & (norms > 0)
    face_normals = face_normals / np.where(usable, norms, 1.0)[:, None]
    vertex = group_rows(corners.reshape(-1, 3))[0].reshape(count, 3)
    ends = np.stack([vertex, np.roll(vertex, -1, axis=1)], axis=2).reshape(-1, 2)
    edges = np.sort(ends, axis=1)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    ordered = edges[order]
    same = np.all(ordered[1:] == ordered[:-1], axis=1)
    # An edge used exactly twice: the pair (i, i + 1) with neither neighbour equal.
    twice = same.copy()
    twice[1:] &= ~same[:-1]
    twice[:-1] &= ~same[1:]
    first = order[np.flatnonzero(twice)]
    second = order[np.flatnonzero(twice) + 1]
    faces = np.column_stack([first // 3, second // 3])
    keep = (usable[faces[:, 0]] & usable[faces[:, 1]] & (faces[:, 0] != faces[:, 1])
            & ((face_normals[faces[:, 0]] * face_normals[faces[:, 1]]).sum(axis=1) < np.cos(np.radians(angle))))
    faces, corner = faces[keep], (first % 3)[keep]
    start = corners[faces[:, 0], corner]
    end = corners[faces[:, 0], (corner + 1) % 3]
    with np.errstate(over="ignore", invalid="ignore"):
        return faces, corner, np.linalg.norm(end - start, axis=1)


def smooth_shaded(positions, triangles, normals, faces, corner):
    """Per edge (faces (E, 2), starting at `corner` of faces[:, 0], as
    `creases` gives them): whether the mesh is smooth-shaded across it, the
    two faces' shading `normals` (N, 3, the positions' indexing) the same at
    each of its ends. A zero or non-finite normal agrees with nothing."""
    triangles = np.asarray(triangles, np.int64)
    positions = np.asarray(positions)
    normals = np.asarray(normals, np.float64)
    f, g = faces[:, 0], faces[:, 1]
    count = np.arange(len(faces))
    agree = np.ones(len(faces), bool)
    for end in (corner, (corner + 1) % 3):
        here = triangles[f, end]
        # The corner of the other face at the same position (corners at one position are one vertex).
        at = (positions[triangles[g]] == positions[here][:, None, :]).all(axis=2)
        there = triangles[g, np.argmax(at, axis=1)]
        na, nb = normals[here], normals[there]
        with np.errstate(over="ignore", invalid="ignore"):
            lengths = np.sqrt((na * na).sum(axis=1) * (nb * nb).sum(axis=1))
            same = (na * nb).sum(axis=1) >= SMOOTH_COS * lengths
        agree &= same & np.isfinite(lengths) & (lengths > 0) & at[count, np.argmax(at, axis=1)]
    return agree


def fold_faces(uvs, triangles, positions, angle):
    """The creases sharper than `angle` degrees that lie inside a chart of
    the layout (uvs, triangles): (faces (F, 2), corner (F,), length (F,)) as
    `creases` gives them. Geometry only, no bake: whether a layout can take
    the folds route at all."""
    faces, corner, length = creases(positions, triangles, angle)
    if len(faces):
        charts = _native.find_charts(uvs, triangles, tolerance=CHART_TOLERANCE)
        inside = charts[faces[:, 0]] == charts[faces[:, 1]]
        faces, corner, length = faces[inside], corner[inside], length[inside]
    return faces, corner, length


def find_folds(uvs, triangles, positions, angle, energy, mask=None, normals=None):
    """The creases sharper than `angle` degrees that lie inside a chart of
    the layout (uvs, triangles), with the gradient `energy` (H, W) of the
    bake on that layout in a band of BAND_TEXELS around each (a texel near
    two folds counts for the nearer). `normals` (N, 3): the shading normals
    per UV, or None (flat-shaded): a fold the mesh is smooth-shaded across
    (`smooth_shaded`) has no step in the light, and its band holds nothing."""
    uvs = np.asarray(uvs)
    triangles = np.asarray(triangles, np.int64)
    energy = np.asarray(energy)
    shape = energy.shape
    faces, corner, length = fold_faces(uvs, triangles, positions, angle)
    smooth = (np.zeros(len(faces), bool) if normals is None or not len(faces)
              else smooth_shaded(positions, triangles, normals, faces, corner))
    covered = mask if mask is not None else _native.coverage_mask(uvs, triangles, shape)
    hard = ~smooth
    band_energy = np.zeros(len(faces))
    band_energy[hard], band = _band(uvs, triangles, faces[hard, 0], corner[hard], np.where(covered, energy, 0.0))
    return Folds(faces=faces, corner=corner, length=length, energy=band_energy, band=band,
                 total_energy=float(np.asarray(energy, np.float64)[covered].sum()), smooth=smooth)


def _band(uvs, triangles, face, corner, energy, chunk=1 << 21):
    """Each fold's energy within BAND_TEXELS of its UV segment (a texel
    goes to its nearest fold) and the band's texels."""
    height, width = energy.shape
    band = np.zeros((height, width), bool)
    count = len(face)
    if count == 0:
        return np.zeros(0), band
    uv = np.asarray(uvs, np.float64)[np.asarray(triangles)[face]]  # (F, 3, 2)
    start = uv[np.arange(count), corner] * (width, height)
    end = uv[np.arange(count), (corner + 1) % 3] * (width, height)
    start[:, 1] = height - start[:, 1]
    end[:, 1] = height - end[:, 1]
    low = np.clip(np.floor(np.minimum(start, end) - BAND_TEXELS), 0, (width - 1, height - 1)).astype(np.int64)
    high = np.clip(np.floor(np.maximum(start, end) + BAND_TEXELS), 0, (width - 1, height - 1)).astype(np.int64)
    sizes = (high - low + 1).prod(axis=1)
    if sizes.sum() > MAX_SEARCH_TEXELS * height * width:
        # Long folds crossing each other over the atlas: an overlapping
        # (texture-like) layout, not one to re-chart for its folds. Counted
        # as holding no light changes rather than searched at length.
        return np.zeros(count), band
    best = np.full(height * width, np.inf)
    owner = np.full(height * width, -1, np.int64)
    bounds = np.searchsorted(np.cumsum(sizes), np.arange(chunk, int(sizes.sum()) + chunk, chunk), side="right")
    first = 0
    for last in np.unique(np.append(np.maximum(bounds, 1), count)):
        if last <= first:
            continue
        part = np.arange(first, last)
        first = last
        which = np.repeat(part, sizes[part])
        offset = np.arange(len(which)) - np.repeat(np.cumsum(sizes[part]) - sizes[part], sizes[part])
        span = high[which, 0] - low[which, 0] + 1
        col = low[which, 0] + offset % span
        row = low[which, 1] + offset // span
        point = np.column_stack([col + 0.5, row + 0.5])
        direction = end[which] - start[which]
        squared = np.maximum((direction * direction).sum(axis=1), 1e-300)
        along = np.clip(((point - start[which]) * direction).sum(axis=1) / squared, 0.0, 1.0)
        distance = np.linalg.norm(point - start[which] - along[:, None] * direction, axis=1)
        near = distance <= BAND_TEXELS
        texel = (row * width + col)[near]
        distance, which = distance[near], which[near]
        closer = distance < best[texel]
        # Several candidates for one texel in this chunk: the nearest wins.
        sort = np.lexsort((distance[closer], texel[closer]))
        texel, distance, which = texel[closer][sort], distance[closer][sort], which[closer][sort]
        unique = np.ones(len(texel), bool)
        unique[1:] = texel[1:] != texel[:-1]
        best[texel[unique]] = distance[unique]
        owner[texel[unique]] = which[unique]
    claimed = owner >= 0
    band.ravel()[:] = claimed
    fold_energy = np.bincount(owner[claimed], weights=np.asarray(energy, np.float64).ravel()[claimed],
                              minlength=count)
    return fold_energy, band
