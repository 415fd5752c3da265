"""Tessellation along light transitions (docs/refiner.md, "Tessellation").

A UV warp moves vertices, and inside a triangle the lightmap mapping is
affine: a shadow edge that crosses a triangle of many texels gains nothing
from the refinement, however the automaton deforms the grid there. So before
refining, the triangles that a strong transition crosses and that cover more
than a few texels are split, within a vertex budget.

The rule: longest-edge bisection (Rivara's). Each round takes the candidate
triangles (peak transition strength >= `threshold` somewhere inside, more
than `min_texels` texels in the lightmap layout), largest transition mass
first. A candidate's longest edge (measured in texels) is split at its
midpoint, together with every triangle across it, so the mesh stays
conforming (no T-junctions), once it is the longest edge of those triangles
too; until then the split goes to the triangle across, whose longest edge is
longer, and on along that path. So every triangle is cut along its own
longest edge and no piece becomes a sliver. A triangle is split at most
once per round; rounds repeat until no candidate is left or the budget of
new vertices is spent.

Every split puts the new vertex on the edge: positions, and every per-corner
attribute (UV maps, normals, colours) of each triangle touching the edge,
are the mean of that triangle's two corners on it. The surface is unchanged
and every UV map keeps its mapping, seams included (a seam edge's two sides
keep their own UVs).
"""

from dataclasses import dataclass, field

import numpy as np

from . import _native
from ._native import coverage_mask, gradient_map
from .allocation import texel_luminance
from .progressbar import cancels
from .rechart_route import layout_room
from .refine import transition_strength

DEFAULT_BUDGET = 0.25       # at most +25% vertices
# Triangles at or below this many texels are left alone, and a transition
# marks a triangle from this peak strength (0..1) on. Finer and softer
# than the first choice (8, 0.5): on the tuning scenes every split to 1
# texel from 0.25 gained more over the plain refinement (docs/refiner.md,
# "Where the split ends").
DEFAULT_MIN_TEXELS = 1.0
DEFAULT_THRESHOLD = 0.25
# A refinement is coarse (tessellation is its fix) when its light changes'
# triangles gained less than this in texels (refine_uvs' transition_widening)...
COARSE_WIDENING = 1.25
# ... or when their median triangle covers at least this many texels (8 x 8:
# the tuning scenes' are 4-9, a floor of 2 m quads' 300-600).
COARSE_TRIANGLE_TEXELS = 64.0
# Light changes softer than this (light_contrast) are no reason to split: the
# top decile of a nearly flat map's gradient is its noise and falloff.
COARSE_CONTRAST = 0.05
# The triangles a coarse refinement's advice counts (coarse_transitions):
# crossed by a strong transition and larger than a warp can serve. The
# split goes on below them, to DEFAULT_MIN_TEXELS.
COARSE_MIN_TEXELS = 8.0
COARSE_THRESHOLD = 0.5
MAX_ROUNDS = 32
# A budget is a fraction of the vertex count, so a floor of one quad (4
# vertices) needs a large one: it took ~270x (1,074 new vertices) to split
# every triangle a sun's shadows cross down to 8 texels (the first
# min_texels) at 512^2. The count of splits is also held to the lightmap's
# texel count.
MAX_BUDGET = 1024.0
# The largest budget a trial of the split tries to tell the budget a mesh
# needs (the add-on's Tessellate advice, evaluate's coarse note): a split
# that needs more is told so.
TRIAL_BUDGET = 64.0
_POINTS_PER_CHUNK = 1 << 20
_PROGRESS_SPLITS = 256


@dataclass
class TessellationResult:
    positions: np.ndarray           # (V', 3) float64: the original vertices first, then one per split
    triangles: np.ndarray           # (T', 3) int64 into positions
    uvs: np.ndarray                 # (3T', 2) float32 per corner: the lightmap UVs, same mapping
    corner_attributes: dict         # name -> (3T', k) per corner, interpolated
    parent: np.ndarray              # (T',) int64: the input triangle each output triangle lies in
    splits: np.ndarray              # (S, 3) int64: (a, b, new vertex) in the order applied
    report: dict = field(default_factory=dict)


def peak_strength(corner_uvs, strength):
    """(T,) the largest value of `strength` (H, W) at points about one texel
    apart inside each triangle (corner_uvs: (T, 3, 2))."""
    height, width = strength.shape
    texel = corner_uvs * np.array([width, height], np.float64)
    edges = np.linalg.norm(texel - np.roll(texel, -1, axis=1), axis=2)
    steps = np.clip(np.ceil(edges.max(axis=1)), 1, 256).astype(np.int64)
    peak = np.zeros(len(corner_uvs))
    for n in np.unique(steps):
        every = np.nonzero(steps == n)[0]
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        weights = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1) / n  # (P, 3) barycentric
        per_chunk = max(1, _POINTS_PER_CHUNK // len(weights))  # bounded memory for many large triangles
        for start in range(0, len(every), per_chunk):
            rows = every[start:start + per_chunk]
            points = weights @ corner_uvs[rows]  # (t, P, 2)
            cols = np.clip(np.floor(points[..., 0] * width), 0, width - 1).astype(np.int64)
            lines = np.clip(np.floor((1.0 - points[..., 1]) * height), 0, height - 1).astype(np.int64)
            peak[rows] = strength[lines, cols].max(axis=1)
    return peak


def _candidates(corner_uvs, strength, min_texels, threshold, previous=None, changed=()):
    """The triangles to split (indices): more than `min_texels` texels, peak strength >= `threshold`;
    with every triangle's peak strength (0 where not looked at) and texel area. `previous`: the
    peak strengths of an earlier call, still those of its triangles but the rows `changed` (rows
    past its end are new), which are all that is sampled again."""
    texels = _texel_areas(corner_uvs, strength.shape)
    peak = np.zeros(len(corner_uvs))
    look = np.ones(len(corner_uvs), bool)
    if previous is not None:
        peak[:len(previous)] = previous
        look[:len(previous)] = False
        look[np.asarray(changed, np.int64)] = True
        peak[look] = 0.0
    look &= texels > min_texels
    if look.any():
        peak[look] = peak_strength(corner_uvs[look], strength)
    large = np.nonzero(texels > min_texels)[0]
    return large[peak[large] >= threshold], peak, texels


def light_contrast(lightmap, mask):
    """How hard the light changes of `lightmap` are: the 99.9th percentile of
    the luminance steps between neighbouring texels of `mask` (across and
    down), over the median luminance of its texels (0.0 without two
    neighbouring covered texels). A shadow edge measures 0.6-2.8 on the
    bundled scenes; a plane under the sun with a point light's falloff
    0.007."""
    mask = np.asarray(mask, bool)
    luminance = texel_luminance(np.asarray(lightmap)).astype(np.float64)
    steps = np.concatenate([np.abs(np.diff(luminance, axis=0))[mask[1:] & mask[:-1]],
                            np.abs(np.diff(luminance, axis=1))[mask[:, 1:] & mask[:, :-1]]])
    if steps.size == 0:
        return 0.0
    return float(np.percentile(steps, 99.9) / max(float(np.median(luminance[mask])), 1e-6))


def coarse_refinement(report):
    """Whether a refine_uvs `report` says its light changes sit in triangles
    too large for a warp (COARSE_WIDENING, COARSE_TRIANGLE_TEXELS): then
    tessellation is what puts more texels there."""
    return (report["transition_widening"] < COARSE_WIDENING
            or report.get("transition_triangle_texels", 0.0) >= COARSE_TRIANGLE_TEXELS)


def coarse_transitions(lightmap, uvs, triangles, *, min_texels=COARSE_MIN_TEXELS, threshold=COARSE_THRESHOLD,
                       wavelet="d4", strength=None):
    """What a refinement without tessellation cannot reach: the triangles larger than `min_texels`
    that a transition of at least `threshold` crosses, given `lightmap` baked on (uvs, triangles);
    `tessellate` splits them first. Returns {"triangles": how many, "texels": the texels they cover}.
    A warp moves vertices; inside such a triangle the mapping stays affine. `strength`: the
    lightmap's transition_strength_of for this layout, when the caller has it."""
    if strength is None:
        strength = transition_strength_of(lightmap, uvs, triangles, wavelet=wavelet)
    corner_uvs = np.asarray(uvs, dtype=np.float64)[np.asarray(triangles, dtype=np.int64)]
    candidates, _, texels = _candidates(corner_uvs, strength, min_texels, threshold)
    return {"triangles": int(candidates.size), "texels": float(texels[candidates].sum())}


def _texel_areas(corner_uvs, shape):
    a, b, c = corner_uvs[:, 0], corner_uvs[:, 1], corner_uvs[:, 2]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    return 0.5 * np.abs(cross) * shape[0] * shape[1]


def _number(name, value):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    return float(value)


def _array(name, value, dtype):
    try:
        raw = np.asarray(value)
        if dtype is not None and raw.dtype != dtype:
            # Checked before converting: a huge (broadcast) input fails at once, not after a long copy.
            _native._require_memory(f"{name} as {np.dtype(dtype).name}", float(raw.size) * np.dtype(dtype).itemsize,
                                    f"pass a smaller {name}")
        return np.asarray(raw, dtype)
    except (TypeError, ValueError) as error:
        raise TypeError(f"{name} must be a numeric array: {error}") from None


# How far outside [0, 1] a lightmap UV may lie (rounding of a packed layout); the split's output
# UVs are float32, so a UV far beyond would come back as inf.
UV_SLACK = 1e-3


def _check_inputs(positions, triangles, uvs, strength, budget, min_texels, threshold, corner_attributes):
    positions = _array("positions", positions, np.float64)
    triangles = _array("triangles", triangles, None)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions must be a (V, 3) array, got shape {positions.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
        raise ValueError(f"triangles must be a (T, 3) integer array, got {triangles.dtype} {triangles.shape}")
    triangles = triangles.astype(np.int64)  # a copy: split in place below
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(positions)):
        raise ValueError(f"triangles index vertices outside 0..{len(positions) - 1}")
    if not np.isfinite(positions).all():
        raise ValueError("positions hold NaN or Inf values")
    uvs = _array("uvs", uvs, np.float64)
    if uvs.shape != (3 * len(triangles), 2):
        raise ValueError(f"uvs must be per corner, shape ({3 * len(triangles)}, 2); got {uvs.shape}")
    if not np.isfinite(uvs).all():
        raise ValueError("uvs hold NaN or Inf values")
    if uvs.size and not (uvs.min() >= -UV_SLACK and uvs.max() <= 1.0 + UV_SLACK):
        raise ValueError(f"uvs must lie in [0, 1], a lightmap layout (they span {uvs.min():.6g} to {uvs.max():.6g}): "
                         "pass the lightmap's UVs, packed into the unit square")
    strength = _array("strength", strength, np.float64)
    if strength.ndim != 2 or min(strength.shape) < 1:
        raise ValueError(f"strength must be an (H, W) array, got shape {strength.shape}")
    if not np.isfinite(strength).all():
        raise ValueError("strength holds NaN or Inf values")
    budget, min_texels, threshold = (_number(n, v) for n, v in (("budget", budget), ("min_texels", min_texels),
                                                                  ("threshold", threshold)))
    if not (0.0 <= budget <= MAX_BUDGET):
        raise ValueError(f"budget must be a fraction of the vertex count in [0, {MAX_BUDGET:g}], got {budget}")
    if not (min_texels >= 0.0 and np.isfinite(min_texels)):
        raise ValueError(f"min_texels must be 0 or more, got {min_texels}")
    if not (0.0 <= threshold <= 1.0):
        raise ValueError(f"threshold must be in [0, 1], got {threshold}")
    attributes = {}
    if corner_attributes is not None and not isinstance(corner_attributes, dict):
        raise TypeError(f"corner_attributes must be a dict of name -> (3T, k) arrays, got "
                        f"{type(corner_attributes).__name__}")
    for name, values in (corner_attributes or {}).items():
        values = _array(f"corner attribute '{name}'", values, None)
        if not np.issubdtype(values.dtype, np.number):
            raise TypeError(f"corner attribute '{name}' must be numeric, got {values.dtype}")
        if values.ndim != 2 or len(values) != 3 * len(triangles):
            raise ValueError(f"corner attribute '{name}' must be per corner, shape ({3 * len(triangles)}, k); "
                             f"got {values.shape}")
        attributes[name] = values
    return positions, triangles, uvs, strength, attributes


def tessellate(positions, triangles, uvs, strength, *, budget=DEFAULT_BUDGET, min_texels=DEFAULT_MIN_TEXELS,
               threshold=DEFAULT_THRESHOLD, corner_attributes=None, progress=None):
    """Split the triangles a strong light transition crosses (module doc).

    positions (V, 3), triangles (T, 3) vertex indices, uvs (3T, 2) the
    lightmap UVs per corner (corner k of triangle t at row 3t + k), and
    `strength` (H, W): transition strength in [0, 1] per texel of a lightmap
    baked on `uvs` (see transition_strength_of). `budget`: most new vertices,
    as a fraction of V (at most MAX_BUDGET; never more than the lightmap's
    texels). corner_attributes: name -> (3T, k) per-corner arrays
    interpolated with the UVs (other UV maps, normals: renormalise those).

    progress: callable progress(fraction, stage), called every round and
    every _PROGRESS_SPLITS splits; returning False cancels
    (lmrefine.CancelledError, nothing returned).

    Returns a TessellationResult; its report holds vertices before/after,
    triangles before/after, splits, rounds, candidates left and why it stopped.
    """
    positions, triangles, uvs, strength, attributes = _check_inputs(
        positions, triangles, uvs, strength, budget, min_texels, threshold, corner_attributes)
    vertex_count = len(positions)
    allowed = min(int(np.floor(budget * vertex_count)), strength.size)

    def report_progress():
        answer = None if progress is None else progress(min(len(splits) / max(allowed, 1), 1.0), "tessellate")
        if cancels(answer):
            raise _native.CancelledError("tessellation cancelled")
    # Copies: the caller's arrays are never modified.
    corner = {"uv": uvs.reshape(-1, 3, 2).copy()}
    corner.update({name: values.reshape(len(triangles), 3, -1).copy() for name, values in attributes.items()})
    new_positions = [positions]
    parent = np.arange(len(triangles), dtype=np.int64)
    splits = []
    rounds, stopped = 0, "no triangle crossed by a transition is larger than min_texels"
    next_vertex = vertex_count
    candidates_left = 0
    peak, changed = None, []  # a round samples the strength only in the triangles the last one split
    while rounds < MAX_ROUNDS:
        candidates, peak, texels = _candidates(corner["uv"], strength, min_texels, threshold, peak, changed)
        changed = []
        candidates_left = int(candidates.size)
        if not candidates.size:
            break
        if len(splits) >= allowed:
            stopped = "the vertex budget is spent"
            break
        report_progress()
        next_report = len(splits) + _PROGRESS_SPLITS
        rounds += 1
        order = candidates[np.argsort(-(peak[candidates] * texels[candidates]), kind="stable")]
        edge_users = _EdgeUsers(triangles)
        # Every triangle's longest edge, from the round's start: a triangle split this round is
        # touched and left alone after, so its corners are still the ones measured here.
        longest, longest_key = _longest_edges(corner["uv"] * np.array([strength.shape[1], strength.shape[0]]),
                                              edge_users)
        # A triangle that repeats a vertex is never split, nor is an edge it uses:
        # it lists that edge twice and has no interior to split.
        touched = ((triangles[:, 0] == triangles[:, 1]) | (triangles[:, 1] == triangles[:, 2])
                   | (triangles[:, 2] == triangles[:, 0]))
        new_rows = {name: [] for name in corner}
        new_triangles, new_parent, round_positions = [], [], []
        for t in order.tolist():
            if len(splits) >= allowed:
                break
            if len(splits) >= next_report:
                report_progress()
                next_report = len(splits) + _PROGRESS_SPLITS
            edge = _terminal_edge(t, triangles, longest, longest_key, edge_users, touched)
            if edge is None:
                continue
            a, b, users = edge
            m = next_vertex
            next_vertex += 1
            round_positions.append(0.5 * (_position(new_positions, a) + _position(new_positions, b)))
            splits.append((a, b, m))
            for u in users:
                touched[u] = True
                changed.append(u)
                k = int(np.nonzero(triangles[u] == a)[0][0])
                if triangles[u, (k + 1) % 3] != b:  # the edge runs b -> a in this triangle
                    k = int(np.nonzero(triangles[u] == b)[0][0])
                p, q, r = triangles[u, k], triangles[u, (k + 1) % 3], triangles[u, (k + 2) % 3]
                # (p, q, r) -> (p, m, r) in place and (m, q, r) appended: orientation kept.
                for name, values in corner.items():
                    vp, vq, vr = values[u, k], values[u, (k + 1) % 3], values[u, (k + 2) % 3]
                    vm = 0.5 * (vp + vq)
                    new_rows[name].append(np.stack([vm, vq, vr]))
                    values[u] = np.stack([vp, vm, vr])
                triangles[u] = (p, m, r)
                new_triangles.append((m, q, r))
                new_parent.append(parent[u])
        if not new_triangles:
            stopped = "the vertex budget is spent"
            break
        new_positions.append(np.array(round_positions))
        triangles = np.concatenate([triangles, np.array(new_triangles, np.int64)])
        parent = np.concatenate([parent, np.array(new_parent, np.int64)])
        for name in corner:
            corner[name] = np.concatenate([corner[name], np.array(new_rows[name])])
    else:
        stopped = f"{MAX_ROUNDS} rounds"
    if rounds and stopped.startswith("no triangle"):
        stopped = "every triangle a transition crosses is at most min_texels"
    positions_out = np.concatenate(new_positions)
    report = {
        "vertices_before": int(vertex_count), "vertices_after": int(len(positions_out)),
        "vertices_added": int(len(positions_out) - vertex_count), "vertex_budget": allowed,
        "triangles_before": int(len(uvs) // 3),
        "triangles_after": int(len(triangles)), "rounds": rounds, "candidates_left": candidates_left,
        "stopped": stopped, "min_texels": float(min_texels), "threshold": float(threshold),
    }
    return TessellationResult(
        positions=positions_out, triangles=triangles,
        uvs=corner["uv"].reshape(-1, 2).astype(np.float32),
        corner_attributes={name: corner[name].reshape(3 * len(triangles), -1).astype(attributes[name].dtype)
                           for name in attributes},
        parent=parent, splits=np.array(splits, np.int64).reshape(-1, 3), report=report)


def _longest_edges(texel_uv, edge_users):
    """(T,) the local index k of each triangle's longest edge (corners k, k + 1) in texels, and
    (T,) that edge's key. An edge's length is the largest its triangles give it (the two sides
    of a UV seam may differ), so every triangle across an edge agrees on it; equal lengths go to
    the larger edge key, so the order is total and a propagation path always ends."""
    lengths = np.linalg.norm(texel_uv - np.roll(texel_uv, -1, axis=1), axis=2)
    lengths = edge_users.edge_max(lengths)
    keys = edge_users.triangle_keys
    longest = np.where(lengths == lengths.max(axis=1, keepdims=True), keys, -1).argmax(axis=1)
    return longest, keys[np.arange(len(keys)), longest]


def _terminal_edge(t, triangles, longest, longest_key, edge_users, touched):
    """Rivara's longest-edge propagation from triangle t: the first edge along the path t ->
    the triangle across t's longest edge -> ... that is the longest edge of every triangle
    using it, as (a, b, users); None when the path reaches a triangle split this round. Splitting
    only such edges bisects every triangle along its own longest edge, which bounds the
    smallest angle of every piece by half the mesh's smallest (a neighbour cut along a
    shorter edge becomes a sliver). t itself is split in a later round if the edge is ahead."""
    current = t
    while True:
        if touched[current]:
            return None
        k = longest[current]
        a, b = triangles[current, k], triangles[current, (k + 1) % 3]
        users = edge_users(a, b)
        if touched[users].any():
            return None
        key = edge_users.key(a, b)
        ahead = users[longest_key[users] != key]
        if not ahead.size:
            return a, b, users
        current = ahead[0]  # its longest edge is longer than this one: the path climbs


def _position(chunks, index):
    for chunk in chunks:
        if index < len(chunk):
            return chunk[index]
        index -= len(chunk)
    raise IndexError(index)


class _EdgeUsers:
    """The triangles using each edge of `triangles`, looked up by the edge's
    two vertices in either order: edge_users(a, b) -> (n,) int64, in
    triangle order. One sorted array of edge keys (a dict of tuples cost
    seconds per round on a mesh of 100,000 triangles)."""

    def __init__(self, triangles):
        first = triangles.reshape(-1)
        second = np.roll(triangles, -1, axis=1).reshape(-1)  # edges (0, 1), (1, 2), (2, 0) of each triangle
        self._stride = int(triangles.max(initial=0)) + 1
        keys = np.minimum(first, second) * self._stride + np.maximum(first, second)
        self.triangle_keys = keys.reshape(-1, 3)  # (T, 3) the key of each triangle's edges (k, k + 1)
        self._order = np.argsort(keys, kind="stable")
        self._keys = keys[self._order]

    def __call__(self, a, b):
        key = self.key(a, b)
        lo, hi = np.searchsorted(self._keys, [key, key + 1])
        return self._order[lo:hi] // 3

    def key(self, a, b):
        return min(a, b) * self._stride + max(a, b)

    def edge_max(self, values):
        """(T, 3) per-edge `values` (T, 3) replaced by their largest over the edge's triangles."""
        flat = values.reshape(-1)[self._order]
        if not flat.size:
            return values.copy()
        starts = np.flatnonzero(np.r_[True, self._keys[1:] != self._keys[:-1]])
        group_max = np.maximum.reduceat(flat, starts)
        out = np.empty_like(flat)
        out[self._order] = np.repeat(group_max, np.diff(np.r_[starts, flat.size]))
        return out.reshape(values.shape)


def budget_to_end(added, vertices):
    """The budget (a fraction of `vertices`) that lets a split adding
    `added` vertices end by itself, as a user reads it: two significant
    digits, rounded up (+60 to 9 vertices: 6.7)."""
    needed = added / max(vertices, 1)
    if needed <= 0:
        return 0.0
    step = 10.0 ** (np.floor(np.log10(needed)) - 1)
    return round(float(np.ceil(needed / step - 1e-9) * step), 12)  # 2.8, not 2.8000000000000003


def transition_strength_of(lightmap, uvs, triangles, wavelet="d4"):
    """Transition strength in [0, 1] per texel of `lightmap` (H, W[, C])
    baked on the layout (uvs, triangles): its wavelet gradient map's energy
    (lmrefine.gradient_map), scaled as refine_uvs scales it."""
    raw = _array("lightmap", lightmap, None)
    if raw.ndim not in (2, 3) or min(raw.shape[:2]) < 1:
        raise ValueError(f"the lightmap must be an (H, W) or (H, W, C) array, got shape {raw.shape}")
    mask = coverage_mask(uvs, triangles, raw.shape[:2])  # validates the layout and the size first
    lightmap = np.ascontiguousarray(_array("lightmap", raw, np.float32))
    gradient = gradient_map(lightmap, mask, wavelet=wavelet)
    return transition_strength(np.where(mask, gradient.sum(axis=2), 0.0), mask)


def tessellated_refine_options(options, uvs, triangles):
    """refine_uvs keywords for a layout once tessellate has split it, from the
    keywords `options` and the layout (uvs, triangles) before the split.

    refine_uvs opens its re-chart route when the layout gives it no room
    (rechart_route.layout_room: one chart per face, as Lightmap Pack cuts).
    Splitting a face's triangles puts vertices inside its chart, so the split
    layout would read as having room and keep its one-face charts. When the
    layout before the split has none, the route is asked for
    (rechart='always'; its keep rule still decides), unless the caller
    turned it off.
    """
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict of refine_uvs keywords, got {type(options).__name__}")
    if not options.get("rechart", True) or not layout_room(uvs, triangles)["no_room"]:
        return dict(options)
    return {**options, "rechart": "always"}
