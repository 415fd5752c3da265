"""refine_uvs: the whole refinement of a lightmap UV layout (docs/method.md §4, §5, §7).

gradient map -> energy -> cellular automaton (native, coarse-to-fine) ->
warp of every UV through the deformed grid -> validity check, backing off
towards the original layout until the result is valid. See docs/refiner.md.
"""

import functools
import time
from dataclasses import dataclass, field

import numpy as np

from . import _native, alignment, allocation, backoff, metrics, rechart_route
from .folds import find_folds
from .packer import pack_charts

BORDER_MODES = ("same", "border_rule", "extra_ring")

# Energy normalization: the gradient map's energy is divided by its 99th
# percentile over covered texels (a few outliers do not set the scale), but by
# at least a quarter of its maximum (so plain noise is not blown up to 1).
_SCALE_PERCENTILE = 99.0
_SCALE_MIN_FRACTION_OF_MAX = 0.25


@dataclass
class RefineResult:
    """What refine_uvs returns.

    uvs: (N, 2) float32, the refined per-corner UVs.
    grid: (H + 1, W + 1, 2) float32, the deformed grid's nodes in UV space
        (identity: node (i, j) at u = j / W, v = 1 - i / H).
    report: dict, see refine_uvs.
    unstretched_uvs: the layout before the triangle stretch when it was
        kept, else None: the re-chart route compares its candidates on
        these, so the stretch never changes which route is taken (the
        route's model sees texel areas, not their shapes).
    """

    uvs: np.ndarray
    grid: np.ndarray
    report: dict = field(default_factory=dict)
    unstretched_uvs: np.ndarray = field(default=None, repr=False)
    # Where the report found the light changes: (the layout refined, its
    # triangles at light changes, its first bake's structure tensors or None).
    light_changes: tuple = field(default=None, repr=False)


@dataclass
class _InCharts:
    """A refinement up to its repack (_in_charts), which _repacked finishes:
    the validated input, the source layout's analysis and check, the
    gradient energy, the automaton's run and the warp the checks kept."""

    lightmap: np.ndarray
    uvs: np.ndarray
    triangles: np.ndarray
    shape: tuple
    padding: float
    mask: np.ndarray          # the source layout's coverage
    progress: object
    options: dict
    start: float              # perf_counter at the start, for the report's seconds
    checker: object           # _native.LayoutChecker of the source layout
    original: dict            # its check_layout report
    edge_shrink_used: float
    timings: dict
    gradient_given: object    # the caller's gradient map (then the lightmap is not read), or None
    energy: np.ndarray        # scalar gradient energy per texel
    aligned: object           # alignment.layout_held's share, or None
    hold: bool                # light steps on texel boundaries: nothing moves
    no_room: bool             # every UV on its chart's border: the automaton was not run
    run: dict                 # run_automaton's result
    limited_by: list
    notes: list
    grid: np.ndarray          # the grid kept
    new_uvs: np.ndarray       # the in-chart layout kept
    check: dict               # its check_layout report
    kept: np.ndarray          # the back-off's share kept per cell
    world_areas: object       # validated world_areas, or None
    signal: tuple = None      # allocation.signal_scales, once _source_lowest has made it
    tensors: np.ndarray = None  # stretch.source_tensors of the lightmap, once _source_tensors has made it
    at_change: object = None  # _at_light_changes of the source layout, when the automaton's block was chosen


_MAX_RESOLUTION = 1 << 24  # as the native side (numpy_util.cpp parse_resolution)


def _source_tensors(stage):
    """stretch.source_tensors of the stage's lightmap on its source layout,
    made once for the chart stretch, the triangle stretch and the report;
    None when a gradient map was given instead of a lightmap."""
    from . import stretch

    if stage.gradient_given is not None:
        return None
    if stage.tensors is None:
        stage.tensors = stretch.source_tensors(stage.lightmap, stage.mask, stage.uvs, stage.triangles)
    return stage.tensors


def _signal(stage):
    """allocation.signal_scales of the stage's source layout (its charts,
    scales and the model's edge and smooth terms), made once for the
    re-chart route's bound, the repack and the triangle stretch's fill."""
    if stage.signal is None:
        options = stage.options
        stage.signal = allocation.signal_scales(
            stage.uvs, stage.triangles, stage.energy, float(options["min_chart_scale"]),
            float(options["max_chart_scale"]), stage.lightmap if stage.gradient_given is None else None,
            stage.mask, stage.world_areas)
    return stage.signal


def _resolution_side(value, name):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be positive, got {value}")
    if value > _MAX_RESOLUTION:
        raise ValueError(f"{name} must be at most {_MAX_RESOLUTION}, got {value}")
    return int(value)


def _resolution(resolution):
    if isinstance(resolution, (int, np.integer)) and not isinstance(resolution, (bool, np.bool_)):
        height = width = _resolution_side(resolution, "resolution")
    elif isinstance(resolution, (tuple, list, np.ndarray)):
        if len(resolution) != 2:
            raise ValueError(f"resolution must be an int or (height, width), got {resolution!r}")
        height = _resolution_side(resolution[0], "resolution")
        width = _resolution_side(resolution[1], "resolution")
    else:
        raise TypeError(f"resolution must be an int or (height, width), got {type(resolution).__name__}")
    return height, width


def _layout(uvs, triangles):
    uvs = np.asarray(uvs)
    triangles = np.asarray(triangles)
    if uvs.ndim != 2 or uvs.shape[1] != 2 or uvs.shape[0] == 0:
        raise ValueError(f"uvs must have shape (N, 2) with N > 0, got {uvs.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3), got {triangles.shape}")
    if not np.issubdtype(triangles.dtype, np.integer):
        raise ValueError(f"triangles must hold integer indices, got dtype {triangles.dtype}")
    uvs = uvs.astype(np.float32)  # a copy: the caller's array is never touched
    if not np.isfinite(uvs).all():
        bad = int(np.flatnonzero(~np.isfinite(uvs).all(axis=1))[0])
        raise ValueError(f"uvs[{bad}] is NaN or Inf; fix or remove the broken UVs before refining")
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(uvs)):
        bad = int(np.flatnonzero((triangles < 0).any(axis=1) | (triangles >= len(uvs)).any(axis=1))[0])
        raise ValueError(f"triangles[{bad}] = {triangles[bad].tolist()} refers to a UV outside "
                         f"[0, {len(uvs)}); indices must point into uvs")
    outside = (uvs < 0) | (uvs > 1)
    if outside.any():
        bad = int(np.flatnonzero(outside.any(axis=1))[0])
        raise ValueError(f"uvs[{bad}] = {uvs[bad].tolist()} is outside [0, 1]: a lightmap layout must lie "
                         f"inside the unit square (repack it, e.g. Blender's Lightmap Pack)")
    return uvs, np.ascontiguousarray(triangles, dtype=np.int32)


def _gradient(lightmap, gradient, mask, shape, wavelet, progress):
    if gradient is not None:
        gradient = np.asarray(gradient)
        if gradient.dtype != np.float32 or gradient.shape != shape + (4,):
            raise ValueError(f"gradient must be a float32 (H, W, 4) gradient map of the resolution "
                             f"{shape[0]}x{shape[1]}, got {gradient.dtype} {gradient.shape}")
        if not np.isfinite(gradient).all():
            raise ValueError("gradient holds NaN or Inf values")
        return np.where(mask[..., None], np.abs(gradient), 0).astype(np.float32)
    if lightmap is None:
        raise ValueError("pass a lightmap, or a gradient map with gradient=")
    lightmap = np.asarray(lightmap)
    if lightmap.ndim not in (2, 3):
        raise ValueError(f"the lightmap must be an (H, W) or (H, W, C) array, got shape {lightmap.shape}")
    if lightmap.shape[:2] != shape:
        raise ValueError(f"the lightmap is {lightmap.shape[0]}x{lightmap.shape[1]} but the resolution is "
                         f"{shape[0]}x{shape[1]}; refine at the resolution the lightmap was baked at")
    if lightmap.dtype != np.float32:
        raise ValueError(f"the lightmap must be float32, got {lightmap.dtype}; convert it with "
                         f"lightmap.astype(numpy.float32)")
    if not mask.any():
        return np.zeros(shape + (4,), np.float32)  # nothing covered: nothing to refine
    return _native.gradient_map(lightmap, mask, wavelet=wavelet, progress=progress)


def chart_separated(mask, owners):
    """`mask` (H, W) without the texels that would join two charts in the
    gradient map: texels two charts cover, and of two neighbouring texels
    (along a row or a column) of different charts the right or lower one.
    `owners`: texel_owners of the layout (-1 uncovered, -2 two charts). The
    wavelet takes an uncovered texel for a chart border, so one is enough.
    Lightmap Pack packs unrelated faces about a texel apart, their covered
    texels touch, and a map read across them shows a light change at every
    face whose neighbour is lit differently."""
    owners = np.asarray(owners)
    separated = np.asarray(mask, bool) & (owners != -2)
    for before, after, target in ((owners[:, :-1], owners[:, 1:], separated[:, 1:]),
                                  (owners[:-1], owners[1:], separated[1:])):
        target &= ~((before >= 0) & (after >= 0) & (before != after))
    return separated


def transition_strength(raw, mask):
    """Gradient energy `raw` (H, W) or (H, W, C) scaled to [0, 1]: 1 at the
    strongest light changes of the covered texels (the 99th percentile, or a
    quarter of the largest value if that is higher), 0 where light is flat."""
    covered = raw[mask]
    scale = 0.0
    if covered.size:
        scale = max(float(np.percentile(covered, _SCALE_PERCENTILE)),
                    _SCALE_MIN_FRACTION_OF_MAX * float(covered.max()))
    return np.clip(raw / scale, 0, 1) if scale > 0 else np.zeros_like(raw)


def _energy(gradient, mask, strength, directional):
    """Energy in [1 / (1 + strength), 1]: 1 where light changes fastest.
    Returns (energy, the gradient energy per texel: the channel sum)."""
    total = gradient.sum(axis=2)
    normalized = transition_strength(gradient if directional else total, mask)
    return ((1 + strength * normalized) / (1 + strength)).astype(np.float32), total


# The automaton's finest cells are at most this fraction of the side of the
# small triangles at light changes (those holding the smallest
# SMALL_TRIANGLE_SHARE of their texels): measured on the tuning scenes,
# finer cells paid where those triangles spanned 2.5-5 texels and not where
# they spanned 10 (docs/refiner.md, "The finest level").
FINEST_BLOCK_TRIANGLE_SHARE = 0.25
SMALL_TRIANGLE_SHARE = 0.1


def automaton_block(uvs, triangles, resolution, at_change=None):
    """The automaton's finest cell side in texels: the largest power of two
    at most FINEST_BLOCK_TRIANGLE_SHARE of the side sqrt(2 x texel area) of
    the triangle below which lie SMALL_TRIANGLE_SHARE of the texels of the
    triangles at light changes (`at_change`, (T,) bool; None: every
    triangle). Where the light changes is where the deformation has to be
    fine: a tessellation's small triangles there decide, not the large flat
    ones around them. 1 for triangles with no area."""
    height, width = _resolution(resolution)
    areas = metrics.uv_areas(uvs, triangles)
    if at_change is not None and np.any(at_change):
        areas = areas[np.asarray(at_change, bool)]
    areas = np.sort(areas) * (float(height) * width)
    cumulative = np.cumsum(areas)
    if not len(areas) or not cumulative[-1] > 0:
        return 1
    small = areas[min(int(np.searchsorted(cumulative, SMALL_TRIANGLE_SHARE * cumulative[-1])), len(areas) - 1)]
    size = FINEST_BLOCK_TRIANGLE_SHARE * np.sqrt(2.0 * small)
    block = 1
    while 2 * block <= min(size, 1024):
        block *= 2
    return block


def identity_grid(resolution):
    """The undeformed (H + 1, W + 1, 2) grid: node (i, j) at u = j / W, v = 1 - i / H."""
    height, width = _resolution(resolution)
    _native._require_memory(f"an identity grid of {height}x{width} texels", 24.0 * (height + 1) * (width + 1),
                            "pass a smaller resolution")
    u = np.arange(width + 1) / width
    v = 1 - np.arange(height + 1) / height
    return np.stack(np.broadcast_arrays(u[None, :], v[:, None]), axis=-1).astype(np.float32)


def refine_uvs(lightmap, uvs, triangles, resolution, padding=2, mask=None, *, gradient=None, strength=24.0,
               max_magnification=8.0, min_shrink=0.15, edge_shrink=0.6, delta=0.02, passes=1, border="same",
               directional=False, wavelet="d4", diffusion=0.05, max_steps=8, progress=None, repack=True,
               min_chart_scale=0.5, max_chart_scale=4.0, positions=None, rechart=True, world_areas=None,
               normals=None, max_stretch=2.0, polygons=None, triangle_stretch=2.0, finest_block=None):
    """Refine a lightmap UV layout: more texels where light changes fast.

    Args:
        lightmap: (H, W[, C]) float32 baked lightmap, or None with gradient=.
        uvs: (N, 2) per-corner UVs inside [0, 1]; never modified.
        triangles: (T, 3) integer indices into uvs.
        resolution: the lightmap's int or (height, width).
        padding: the gutter between charts, in texels, the result must
            keep; a chart pair the original packed closer keeps its
            original distance instead (docs/method.md §7).
        mask: (H, W) bool chart coverage; default coverage_mask(uvs, ...).
        gradient: a (H, W, 4) float32 gradient map to use instead of
            computing one from the lightmap.
        strength: >= 0; a texel of the strongest light change wants
            (1 + strength) times the area of a flat one. 0 = identity.
        max_magnification, min_shrink: bounds on a covered texel's area
            change (texel-density ratio).
        edge_shrink: in (0, 1]; a chart's edge texels facing the gutter
            shrink to at most this times their area (1 = rigid); only
            when every chart pair is at least padding + 0.5 texels apart.
        delta: the automaton stops when neighbour densities differ by less
            than delta (relative to the mean).
        passes: >= 1; each extra pass reruns the finest level with fresh
            energies, deforming further.
        border: 'same' (default), 'border_rule' or 'extra_ring'.
        directional: use the four-spring variant (one energy per channel).
        wavelet: passed to gradient_map.
        diffusion, max_steps: automaton details (see run_automaton).
        finest_block: texels per cell side of the automaton's finest level
            that steps, a power of two in [1, 1024]; None (default): from
            the small triangles at light changes (automaton_block), 1
            unless they span many texels. A warp moves only vertices, so
            cells much smaller than the triangles buy nothing
            (docs/refiner.md, "The finest level").
        progress: callable progress(fraction, stage); returning False cancels.
        repack: after the in-chart refinement, scale each chart by its
            signal (the error model in docs/refiner.md, "Chart scaling":
            light changes from the gradient map; with
            allocation.SMOOTH_TERM also smooth light from the lightmap's
            slope, not read when gradient= is given)
            and pack all charts into one atlas with lmrefine.pack_charts
            (rotations, at least `padding` texels apart, or the input's
            gutter where that is narrower, but at least a texel); then the
            charts the model counts most grow into the space the packing
            left, the others keeping their sizes, a chart with no room to
            grow evenly along one axis where max_stretch allows
            (report["repack"]["fill"]; docs/refiner.md, "The space the
            packing left"). Kept only
            if the model predicts less error than the unpacked result, the
            packed atlas is about as dense as the input and the packed
            layout passes the same checks; report["repack"] says
            what happened (None when off). `grid` stays the automaton's
            in-chart deformation, before the charts are scaled and moved.
        min_chart_scale, max_chart_scale: bounds on a chart's linear scale
            relative to the median chart, for repack.
        max_stretch: >= 1; with repack and a lightmap, a chart whose light
            changes run mostly one way may be stretched across them by up
            to this and squeezed along them by as much, its texel area kept
            (lmrefine.stretch; docs/refiner.md, "Chart stretch"); kept only
            when the error model predicts less error than the unstretched
            packing. 1 = off. report["repack"]["stretch"] says what happened.
        triangle_stretch: in [1, 16]; with repack and a lightmap, after the
            repack each triangle whose light changes run one way is
            stretched across them by up to this and squeezed along them, its
            area kept, the chart's triangles fitted to those shapes
            together, and the charts packed again at their sizes
            (lmrefine.stretch.triangle_stretch; docs/refiner.md, "Triangle
            stretch"). Kept when that layout passes the checks and the
            chart model predicts less edge error for it, the packing's loss
            of scale counted; its charts then grow evenly into the space
            that packing left (report["triangle_stretch"]["fill"]). 1 = off.
            report["triangle_stretch"] says what happened (None when off,
            or when the repack is).
        positions: (N, 3) the 3-D position of each UV (the uvs' indexing),
            or None. With positions and rechart, a source layout that gives
            the refiner no room (rechart_route.layout_room: one chart per
            face or nearly, as Lightmap Pack makes), or whose charts fold
            over creases sharper than rechart_route.ANGLE (lmrefine.folds:
            Smart UV Project joins faces up to 66 degrees apart), is
            re-charted from the
            mesh (lmrefine.rechart), the lightmap carried over to the new
            layout and that layout refined; kept when the error model
            predicts clearly less error than the source layout (below
            rechart_route.REQUIRED_GAIN; docs/refiner.md, "The re-chart
            route"), else the source layout's own refinement is returned.
            report["rechart"] says what happened: used, room (the rule's
            figures), folds (count, length, smooth (how many are
            smooth-shaded), energy_fraction; None when not looked for), reason when not used, the new layout's charts and
            the model's predicted_error when re-charted, predicted_error_source_route
            (the source layout's own refinement; None when its repack was
            not made: source_route_bound, the least the model can predict
            for any repack of the source's refined charts, is above the
            re-charted layout's prediction), edge_room (None,
            or whether charts packed farther apart were kept after the
            automaton's fit reset a region: rechart_route.refine_recharted)
            (None without positions).
            The result keeps the input's indexing: result.uvs (N, 2) for
            the same triangles.
        rechart: False turns the re-chart route off (the source layout
            is refined as without positions); 'always' tries it whatever
            the layout's room and folds (the keep rule still decides), for
            a layout whose charts were one face each before its triangles
            were split (lmrefine.tessellate adds vertices inside them);
            report["rechart"]["always"] is then True.
        normals: (N, 3) the shading normal of each UV (the uvs' indexing),
            or None (flat shading: every crease is a step in the light).
            Used with positions: where the mesh is smooth-shaded across a
            fold (the same normals on both sides at both its ends) the
            light does not step, so the error model does not count the
            fold's light changes as removable by a cut, and the re-chart
            route joins faces across such edges within
            charting.SMOOTH_ANGLE (docs/refiner.md, "Smooth-shaded
            meshes"). A zero or non-finite normal makes its edges count as
            hard.
        polygons: (T,) integer face id per triangle (the face of the mesh
            each triangle was cut from: Blender's loop_triangles'
            polygon_index), or None. Used with positions: the re-chart route
            keeps each face's triangles in one chart, so a curved quad is
            not cut along its diagonal. Triangles that share UV indices (a
            per-loop layout, as the add-on passes) are one face anyway; a
            per-corner layout shares none, so only this tells its faces.
        world_areas: (T,) the triangles' surface areas (any unit), for
            repack: a chart's light changes count on the surface its
            texels cover, so a layout whose texel density is not uniform
            (one refined before: a further stage) is scaled towards the
            model's optimum instead of compounding the last scaling. None
            (default): the input's texel density is taken as uniform, as
            Smart UV Project makes it (the compounding measured better
            over two stages: docs/refiner.md, "Light changes per surface").

    Returns:
        RefineResult with uvs, grid and report. Its figures are measured on
        the layout returned, never on the automaton's grid: moved (False
        when the output equals the input; notes then say why),
        transition_widening (summed new / old UV area of the triangles on
        the top decile of gradient energy; 1.0 when nothing moved),
        transition_triangle_texels (the texel area, in the input layout,
        of the triangle under the median of their texels: far above a few texels, only
        tessellation puts more texels at their light changes),
        density_min, density_max (smallest and largest new / old UV area
        of a triangle), triangle_density (T,) new / old UV area, steps,
        levels, converged, backoff (the smallest fraction of the full
        deformation kept anywhere; 1.0 = none backed off), backoff_area
        (fraction of grid nodes that backed off), strength_used (strength x
        backoff), limited_by (list of what held the result back: 'flipped',
        'overlapping', 'gutter', 'degenerate', 'grid' (a blend made a cell
        invalid), 'step_cap', 'max_magnification', 'min_shrink',
        'original_gutter' (the original is tighter than padding),
        'aligned_steps' (below); empty if nothing), aligned_steps (the share
        of the lightmap's light steps on texel boundaries the layout's edges
        run along, lmrefine.alignment; at its ALIGNED_STEP_SHARE or more the
        layout is returned as it is; None with gradient= or strength 0),
        notes (list of sentences, e.g. on the original's gutter),
        passes, finest_block (the value used), edge_shrink (the value
        used: 1.0 on a tight pack),
        border, seconds (timings: setup (the original's coverage, gutter
        texels and check), gradient_map, automaton, warp_and_check),
        original_check and check (check_layout reports).

    Raises:
        ValueError: bad shapes, indices out of range, NaN UVs, UVs outside
            [0, 1], zero resolution, bad options.
    """
    options = {"strength": strength, "max_magnification": max_magnification, "min_shrink": min_shrink,
               "edge_shrink": edge_shrink, "delta": delta, "passes": passes, "border": border,
               "directional": directional, "wavelet": wavelet, "diffusion": diffusion, "max_steps": max_steps,
               "repack": repack, "min_chart_scale": min_chart_scale, "max_chart_scale": max_chart_scale,
               "world_areas": world_areas, "max_stretch": max_stretch, "triangle_stretch": triangle_stretch,
               "finest_block": finest_block}
    if not isinstance(rechart, (bool, np.bool_, str)):
        raise TypeError(f"rechart must be True, False or 'always', got {rechart!r}")
    if isinstance(rechart, str) and rechart != "always":  # the right type, a value it does not know
        raise ValueError(f"rechart must be True, False or 'always', got {rechart!r}")
    if isinstance(triangle_stretch, (bool, np.bool_)) or not isinstance(triangle_stretch, (int, float, np.number)) \
            or not 1.0 <= float(triangle_stretch) <= MAX_TRIANGLE_STRETCH:
        raise ValueError(f"triangle_stretch must be a number in [1, {MAX_TRIANGLE_STRETCH:g}] (1 = none), got "
                         f"{triangle_stretch!r}")
    for name, value in (("normals", normals), ("polygons", polygons)):
        if value is not None and positions is None:
            raise ValueError(f"{name}= is read only with positions= (the re-chart route): pass the UVs' 3-D "
                             f"positions too, or leave {name} out")
    if positions is None:
        result = _repacked(_in_charts(lightmap, uvs, triangles, resolution, padding, mask, gradient, progress,
                                      options))
        result.report["rechart"] = None
        return result
    start = time.perf_counter()
    uvs, triangles = _layout(uvs, triangles)
    positions = rechart_route.positions_array(positions, len(uvs))
    if normals is not None:
        normals = rechart_route.normals_array(normals, len(uvs))
    if polygons is not None:
        polygons = rechart_route.polygons_array(polygons, len(triangles))
    room = rechart_route.layout_room(uvs, triangles)
    # 'always': the caller knows the layout's charts are one face each under its split triangles.
    opened = room["no_room"] or rechart == "always"
    stage = _in_charts(lightmap, uvs, triangles, resolution, padding, mask, gradient, progress, options, room)
    energy, source_mask = stage.energy, stage.mask

    @functools.lru_cache(maxsize=None)
    def source_route():
        """The source layout's own refinement up to its repack, finished
        where it is returned: made only when asked for (the re-chart route
        may win without it)."""
        return _Unfinished(stage, False)

    folds = None
    if rechart and not opened and gradient is None and lightmap is not None:
        folds = find_folds(uvs, triangles, positions, rechart_route.ANGLE, energy, source_mask, normals)
    # Any fold opens the route; the keep rule decides (a re-charted layout
    # also changes charts and packing, so a fold's share alone does not).
    folded = folds is not None and len(folds.faces) > 0
    if not rechart:
        info = {"used": False, "room": room, "reason": "re-charting is off (rechart=False)"}
    elif not opened and not folded:
        info = {"used": False, "room": room, "folds": rechart_route.fold_report(folds),
                "reason": f"the source layout has room ({room['room_fraction']:.0%} of its area is in triangles "
                f"with a UV inside their chart) and its charts fold over no crease sharper than "
                f"{rechart_route.ANGLE:g} degrees"}
    elif gradient is not None or lightmap is None:
        info = {"used": False, "room": room, "reason": "re-charting needs the lightmap (not a gradient map)"}
    elif strength == 0:
        info = {"used": False, "room": room, "reason": "strength is 0"}
    else:
        shape = _resolution(resolution)
        recharted, info = rechart_route.refine_recharted(
            lambda carried, new_uvs, new_mask, new_padding: _Unfinished(_in_charts(
                carried, new_uvs, triangles, shape, new_padding, new_mask, None, progress, options), True),
            lightmap, uvs, triangles, shape, padding, positions, room, energy, lambda: source_route().compared,
            stage.original, progress, folds, normals, polygons, source_lowest=_source_lowest(stage))
        if rechart == "always":
            info["always"] = True
        if recharted is not None:
            result = _recharted_result(recharted, stage.original, uvs, triangles, energy, source_mask, info,
                                       lightmap if gradient is None else None)
    if not info["used"]:
        result = source_route().finished()
    if not info["used"] and (opened or folded) and rechart:
        result.report["notes"].append(f"not re-charted: {info['reason']}")
    result.report["rechart"] = info
    result.report["seconds"] = time.perf_counter() - start
    return result


def _source_lowest(stage):
    """None, or for the source refinement's in-chart `stage` (_in_charts)
    without overlaps: model -> the least error the ErrorModel `model` can
    predict for the source layout's refinement made from it: the in-chart
    layout itself, or its charts packed whole at the repack's scales or
    their square roots (ErrorModel.lowest_packed), stretched by at most the
    chart stretch's bound. The scales are kept for its repack."""
    options = stage.options
    if stage.check["overlapping"]:
        return None
    repacks = options["repack"] and options["strength"] > 0 and not stage.hold

    def lowest(model):
        unpacked = model.relative(stage.new_uvs)
        if not repacks:
            return unpacked
        scales = _signal(stage)[1]
        padding = pack_padding(stage.padding, stage.original)
        stretch = max(1.0, float(options["max_stretch"]))
        bounds = [model.lowest_packed(stage.shape, padding, variant, stage.new_uvs, stretch)
                  for variant in (scales, np.sqrt(scales))]
        return None if None in bounds else min([unpacked] + bounds)

    return lowest


def _recharted_result(recharted, original, uvs, triangles, energy, mask, info, lightmap):
    """The re-charted refinement's result, its figures measured against the
    source layout (the user's, `original` its check; `lightmap` its first
    bake, or None), its notes saying why it was re-charted."""
    report = recharted.report
    # The light changes as the re-charted refinement found them, in the map
    # carried to its layout: read within its charts, where the source's own
    # charts may be too small to show them (Lightmap Pack's few texels).
    report.update(_layout_figures(uvs, recharted.uvs, triangles, energy, mask, lightmap,
                                  *_found_light_changes(recharted.light_changes, uvs, triangles)))
    room = info["room"]
    notes = [note.replace("nothing moved:", "the re-charted layout's own refinement moved nothing:")
             for note in report["notes"]]
    if room["no_room"]:
        why = (f"the source layout gives the refiner no room ({room['charts']} charts for {room['triangles']} "
               f"triangles, {room['room_fraction']:.0%} of its area in triangles with a UV inside their chart)")
    elif info.get("always"):
        charts = f"{room['charts']} chart" + ("s were" if room["charts"] != 1 else " was")
        why = (f"the source layout's {charts} asked to be re-charted (rechart='always': one face each before "
               "the tessellation split their triangles)")
    else:
        folds = info["folds"]
        smooth = f", {folds['smooth']} of them smooth-shaded" if folds.get("smooth") else ""
        why = (f"the source layout's charts fold over {folds['count']} creases sharper than {info['angle']:g} "
               f"degrees ({folds['length']:.3g} world units{smooth}), which hold {folds['energy_fraction']:.0%} "
               f"of its light changes")
    roomier = (", packed half a texel farther apart than the padding so that their edge texels could shrink"
               if info.get("edge_room") else "")
    notes.insert(0, f"re-charted: {why}, so the mesh was re-charted ({info['charts']} charts at "
                    f"{info['angle']:g} degrees{roomier}) and refined; the error model predicts "
                    f"{info['predicted_error']:.2f} of the source layout's error "
                    + (f"(refining the source layout: {info['predicted_error_source_route']:.2f})"
                       if info["predicted_error_source_route"] is not None else
                       f"(refining the source layout: at least {info['source_route_bound']:.2f}, so its repack "
                       f"was not made)"))
    report.update({"moved": True, "notes": notes, "original_check": original})
    return recharted


def _in_charts(lightmap, uvs, triangles, resolution, padding, mask, gradient, progress, options, room=None):
    """refine_uvs without the re-chart route up to the repack: the gradient
    map, the automaton and the warp kept by the checks, as the _InCharts
    _repacked finishes."""
    strength, max_magnification, min_shrink = options["strength"], options["max_magnification"], \
        options["min_shrink"]
    edge_shrink, delta, passes, border = options["edge_shrink"], options["delta"], options["passes"], \
        options["border"]
    directional, wavelet, diffusion, max_steps = options["directional"], options["wavelet"], \
        options["diffusion"], options["max_steps"]
    world_areas = options["world_areas"]
    start = time.perf_counter()
    shape = _resolution(resolution)
    uvs, triangles = _layout(uvs, triangles)
    for name, value in (("strength", strength), ("edge_shrink", edge_shrink), ("padding", padding)):
        if isinstance(value, (bool, str, bytes)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    if not strength >= 0:
        raise ValueError(f"strength must be >= 0, got {strength}")
    if not isinstance(border, str):
        raise TypeError(f"border must be a str, one of {BORDER_MODES}, got {type(border).__name__}")
    if border not in BORDER_MODES:
        raise ValueError(f"border must be one of {BORDER_MODES}, got {border!r}")
    if not isinstance(passes, (int, np.integer)) or isinstance(passes, bool):
        raise TypeError(f"passes must be an int, got {type(passes).__name__}")
    if not 1 <= passes <= 64:
        raise ValueError(f"passes must be in [1, 64], got {passes!r}")
    if not 0 < edge_shrink <= 1:
        raise ValueError(f"edge_shrink must be in (0, 1] (1: chart edges keep their size), got {edge_shrink}")
    finest_block = options["finest_block"]
    if finest_block is not None and (isinstance(finest_block, bool) or not isinstance(finest_block, (int, np.integer))
                                     or not 1 <= finest_block <= 1024 or finest_block & (finest_block - 1)):
        raise ValueError(f"finest_block must be None or a power of two in [1, 1024], got {finest_block!r}")
    if world_areas is not None:
        world_areas = np.asarray(world_areas)
        if world_areas.shape != (len(triangles),) or not (np.issubdtype(world_areas.dtype, np.integer)
                                                           or np.issubdtype(world_areas.dtype, np.floating)):
            raise ValueError(f"world_areas must hold one number per triangle, shape ({len(triangles)},), got "
                             f"{world_areas.dtype} {world_areas.shape}; pass the triangles' surface areas or None")
        if not (np.isfinite(world_areas).all() and (world_areas >= 0).all()):
            raise ValueError("world_areas must be finite and >= 0 (surface areas of the triangles)")
    # The original is analysed once (charts, rasterization, chart distances)
    # for its coverage, gutter texels and check and every back-off round.
    checker = _native.LayoutChecker(uvs, triangles, shape, padding)
    if mask is None:
        mask = checker.coverage_mask()
    else:
        mask = np.asarray(mask)
        if mask.shape != shape:
            raise ValueError(f"mask must have shape {shape} (the resolution), got {mask.shape}")
        mask = mask.astype(bool)
    # Texels between charts only shift, chart edges facing the gutter shrink to
    # edge_shrink at most (if the gutter is wide): chart pairs keep their distance.
    rigid = checker.gutter_texels()
    original = checker.check(failing_charts=True)  # its overlapping charts: what a refinement must not add to
    original.pop("failing_charts")
    original["overlapping_charts"] = original["overlapping_charts"].tolist()
    edge_shrink_used = (float(edge_shrink) if original["min_gutter_texels"] >= padding + backoff.EDGE_SHRINK_GUTTER_MARGIN
                        else 1.0)
    timings = {"setup": time.perf_counter() - start}
    clock = time.perf_counter()
    gradient_given = gradient  # with a gradient map the lightmap is not read (nor checked)
    # A given gradient map is the caller's; one read from the lightmap stops at chart borders.
    gradient = _gradient(lightmap, gradient, mask if gradient is not None else
                         chart_separated(mask, checker.texel_owners()), shape, wavelet, progress)
    energy, scalar_energy = _energy(gradient, mask, float(strength), directional)
    timings["gradient_map"] = time.perf_counter() - clock
    clock = time.perf_counter()
    identity = identity_grid(shape)
    # Light steps on texel boundaries the layout's edges run along: moving a vertex puts them inside texels.
    aligned, hold = (alignment.layout_held(lightmap, uvs, triangles, mask)
                     if gradient_given is None and strength > 0 else (None, False))
    # Every UV on its chart's border (one chart per face, as Lightmap Pack
    # makes): the warp can only reshape each chart's one affine map, which
    # puts no more texels where the light changes inside it (scaling whole
    # charts is the repack's job), so the automaton is not run
    # (docs/refiner.md, "Layouts without room").
    no_room = not hold and (room or rechart_route.layout_room(uvs, triangles))["room_fraction"] == 0.0
    at_change = None
    if hold or no_room:
        run = {"grid": identity, "steps": 0, "levels": [], "converged": True, "finest_block": None}
    else:
        if finest_block is None:
            at_change = _at_light_changes(uvs, triangles, scalar_energy, mask)
        block = automaton_block(uvs, triangles, shape, at_change) if finest_block is None else int(finest_block)
        run = _native.run_automaton(energy, mask, rigid=rigid, diffusion=diffusion, delta=delta,
                                    max_steps=max_steps, min_shrink=min_shrink, max_magnification=max_magnification,
                                    edge_shrink=edge_shrink_used, border=border, passes=int(passes),
                                    finest_block=block, progress=progress)
        run["finest_block"] = min(block, run["levels"][0]["block"])  # the coarsest level at most
    full = run["grid"]
    timings["automaton"] = time.perf_counter() - clock
    clock = time.perf_counter()

    limited_by, notes = [], []
    if hold:
        limited_by.append("aligned_steps")
    if not run["converged"]:
        limited_by.append("step_cap")
    if original["min_gutter_texels"] < padding:
        # docs/method.md §7: keep the gutter the original had; pairs packed tighter
        # than the padding keep their own distance (backoff.accept).
        limited_by.append("original_gutter")
        notes.append(f"original gutter {original['min_gutter_texels']:.2f} texels < padding {padding:g}: "
                     f"chart pairs closer than the padding keep their original distance")

    if np.array_equal(full, identity):
        grid, new_uvs, check, kept = identity, uvs.copy(), original, np.ones(identity.shape[:2], np.float32)
    else:
        grid, new_uvs, check, kept, failed = backoff.accept(full, identity, uvs, triangles, shape, padding, original,
                                                          checker)
        limited_by += failed

    timings["warp_and_check"] = time.perf_counter() - clock
    return _InCharts(lightmap=lightmap, uvs=uvs, triangles=triangles, shape=shape, padding=padding, mask=mask,
                     progress=progress, options=options, start=start, checker=checker, original=original,
                     edge_shrink_used=edge_shrink_used, timings=timings, gradient_given=gradient_given,
                     energy=scalar_energy, aligned=aligned, hold=hold, no_room=no_room, run=run,
                     limited_by=limited_by, notes=notes, grid=grid, new_uvs=new_uvs, check=check, kept=kept,
                     world_areas=world_areas, at_change=at_change)


# The largest triangle_stretch refine_uvs takes: a triangle 16 times wider
# across its light changes is 1/16 as long along them.
MAX_TRIANGLE_STRETCH = 16.0
# The triangle stretch is kept when the chart model's error of its packed
# layout is below this share of the refined layout's.
TRIANGLE_STRETCH_REQUIRED_GAIN = 1.0


def triangle_stretch_error(edge_error, texel_area, smooth_share):
    """The chart model's error of a triangle-stretched layout packed again,
    relative to the refined layout's: its edge term's prediction
    (stretch.triangle_edge_error, the stretch against the packing's loss of
    scale) for the share of the error across light changes, and the texel
    area's inverse for the share in smooth light (allocation.smooth_share),
    which a stretch does not serve and a lost texel costs (docs/refiner.md,
    "Smooth light priced")."""
    return (1.0 - smooth_share) * edge_error + smooth_share / max(texel_area, 1e-12)


def _triangle_stretched(stage, new_uvs, check, analysed=None):
    """The triangle stretch (stretch.triangle_stretch) of the refined layout
    `new_uvs` (its check_layout report `check`; `analysed`: its
    LayoutChecker and the set of charts failing that check, when the caller
    has them), packed again at its charts' sizes: (uvs, check, report), the
    input's own when the stretch is not kept. A chart of the packed layout
    that fails the checks (where it did not in `new_uvs`) keeps less of its
    stretch, and the charts are fitted and packed again; the layout is
    kept when it passes and the chart model's edge term
    (stretch.triangle_edge_error: the stretch against the packing's loss of
    scale) is below TRIANGLE_STRETCH_REQUIRED_GAIN. When
    the stretch of every chart is not, the stretch of the charts it serves
    best (_best_served) is packed and judged the same way, the best kept."""
    from . import stretch

    factor = stage.options["triangle_stretch"]  # checked by refine_uvs
    report = {"used": False, "max_stretch": float(factor)}
    if stage.gradient_given is not None:
        report["reason"] = "a gradient map was given instead of a lightmap"
        return new_uvs, check, report
    triangles, shape, padding = stage.triangles, stage.shape, pack_padding(stage.padding, stage.original)
    if analysed is None:
        checker = _native.LayoutChecker(new_uvs, triangles, shape, stage.padding)
        analysed = checker, set(checker.check(failing_charts=True)["failing_charts"].tolist())
    checker, failing_before = analysed
    charts = checker.charts
    kept = None
    for _ in range(len(stretch.TRIANGLE_BACKOFF) + 1):
        stretched, kept, figures, model = stretch.triangle_stretch(
            stage.lightmap, stage.mask, stage.uvs, new_uvs, triangles, charts, shape, float(factor), kept,
            _source_tensors(stage))
        report.update(figures)
        if np.array_equal(stretched, new_uvs):
            report["reason"] = "no triangle holds light changes that run one way"
            return new_uvs, check, report
        try:
            packed, packed_check, worse, failing = _packed_again(stage, checker, failing_before, stretched, padding)
        except ValueError as error:
            report["reason"] = f"the stretched charts do not pack ({error})"
            return new_uvs, check, report
        if not worse:
            break
        report["reason"] = f"the stretched layout failed {', '.join(worse)}"
        backing = np.array(sorted(failing), np.int64)
        if not len(backing) or not (kept[backing] > 0).any():
            return new_uvs, check, report
        kept[backing] = stretch.smaller_share(kept[backing])
    else:
        return new_uvs, check, report
    report.pop("reason", None)
    predicted = stretch.triangle_edge_error(model, new_uvs, packed, triangles)
    report["every_chart_edge_error"] = predicted
    if predicted >= TRIANGLE_STRETCH_REQUIRED_GAIN:
        # The charts that gain least may cost the packing more than they give:
        # the stretch of fewer charts, those it serves best, is judged too.
        gains = stretch.chart_gains(model, new_uvs, stretched, triangles, charts)
        for selected in _best_served(gains, kept > 0):
            if np.array_equal(selected, kept > 0):
                continue  # the stretch of every chart, judged above
            layout = _with_charts(new_uvs, stretched, triangles, charts, selected)
            if np.array_equal(layout, stretched):
                continue  # the charts left out do not stretch: the layout judged above, packed the same
            try:
                candidate, candidate_check, worse, _ = _packed_again(stage, checker, failing_before, layout, padding)
            except ValueError:
                continue
            if worse:
                continue
            error = stretch.triangle_edge_error(model, new_uvs, candidate, triangles)
            if error < predicted:
                packed, packed_check, predicted = candidate, candidate_check, error
                kept = np.where(selected, kept, 0.0)
    report["texel_area"] = float(metrics.uv_areas(packed, triangles).sum() /
                                 max(metrics.uv_areas(new_uvs, triangles).sum(), 1e-300))
    report["predicted_edge_error"] = predicted
    if predicted >= TRIANGLE_STRETCH_REQUIRED_GAIN:
        fewer = (f" with every chart stretched, {predicted:.3f} at best with fewer"
                 if predicted < report["every_chart_edge_error"] else "")
        report["reason"] = (f"the error model predicts {report['every_chart_edge_error']:.3f} of the refined "
                            f"layout's edge error once packed again{fewer} (needed: below "
                            f"{TRIANGLE_STRETCH_REQUIRED_GAIN:g})")
        return new_uvs, check, report
    report["smooth_share"] = allocation.smooth_share(stage.uvs, triangles, charts, stage.energy,
                                                     stage.lightmap, stage.mask, stage.world_areas)
    report["predicted_error"] = triangle_stretch_error(predicted, report["texel_area"], report["smooth_share"])
    if report["predicted_error"] >= TRIANGLE_STRETCH_REQUIRED_GAIN:
        report["reason"] = (f"the error model predicts {report['predicted_error']:.3f} of the refined layout's "
                            f"error once packed again: {predicted:.3f} of its edge error, and its smooth light "
                            f"({report['smooth_share']:.0%} of the error) on {report['texel_area']:.0%} of the "
                            f"texels (needed: below {TRIANGLE_STRETCH_REQUIRED_GAIN:g})")
        return new_uvs, check, report
    report["used"] = True
    report["charts_stretched"] = int((kept > 0).sum())
    # The repack's signal holds the fill's chart errors, when its charts are the checker's.
    signal_charts, _, edge, smooth = _signal(stage)
    grown, report["fill"] = allocation.grow_finished_packing(
        packed, stage.uvs, triangles, charts, stage.energy, shape, padding, stage.lightmap, stage.mask,
        stage.world_areas, allocation._reports_done(stage.progress),
        errors=(edge, smooth) if np.array_equal(signal_charts, charts) else None)
    report["fill"]["used"] = False
    if grown is not None:
        grown_check, worse, _ = _checked(stage, checker, failing_before, grown)
        report["fill"]["used"] = not worse
        if worse:
            report["fill"]["reason"] = f"the grown layout failed {', '.join(worse)}"
        else:
            packed, packed_check = grown, grown_check
    # Measured on the output: the fit meets each triangle's target only in the least-squares sense.
    report.update(stretch.measured_stretch_figures(new_uvs, packed, triangles))
    return packed, packed_check, report


def _packed_again(stage, checker, failing_before, layout, padding):
    """`layout`'s charts (checker.charts) packed again at their sizes: (the
    packed layout, its check_layout report, the checks it fails that the
    refined layout passed, the charts failing that did not before);
    ValueError when they do not pack. The packing moves whole charts, so
    the refined layout's charts are the packed layout's: the checker's
    report is check_layout's."""
    packed, _ = pack_charts(layout, stage.triangles, checker.charts, None, stage.shape, padding,
                            progress=allocation._reports_done(stage.progress))
    return (packed, *_checked(stage, checker, failing_before, packed))


def _checked(stage, checker, failing_before, packed):
    """A packing of the refined layout's charts (checker.charts) checked:
    (its check_layout report, the checks it fails that the refined layout
    passed, the charts failing that did not before)."""
    packed_check = checker.check(packed, failing_charts=True)
    worse = backoff.failures(packed_check, stage.original, stage.padding)
    return packed_check, worse, backoff.without_chart_lists(packed_check) - failing_before


# When the stretch of every chart is refused, the stretch of the charts it
# serves best is tried: those holding these shares of its summed gain.
TRIANGLE_SUBSET_SHARES = (1.0, 0.75, 0.5, 0.25)


def _best_served(gains, candidates):
    """Chart subsets (C,) bool to try the triangle stretch on: of the
    `candidates` charts whose stretch lowers their edge term (`gains` > 0),
    the fewest, largest gains first, holding each of TRIANGLE_SUBSET_SHARES
    of the summed gain; each subset once."""
    order = np.flatnonzero(candidates & (gains > 0))
    order = order[np.argsort(-gains[order], kind="stable")]
    if not len(order):
        return []
    cumulative = np.cumsum(gains[order])
    subsets, seen = [], set()
    for share in TRIANGLE_SUBSET_SHARES:
        # A hair below the share: the whole sum, rounded, still takes every chart.
        count = int(np.searchsorted(cumulative, share * cumulative[-1] * (1 - 1e-12))) + 1
        count = min(count, len(order))
        if count in seen:
            continue
        seen.add(count)
        selected = np.zeros(len(gains), bool)
        selected[order[:count]] = True
        subsets.append(selected)
    return subsets


def _with_charts(base_uvs, chart_uvs, triangles, charts, selected):
    """`base_uvs` with the corners of the `selected` charts (C,) bool taken from `chart_uvs`."""
    corners = np.zeros(len(base_uvs), bool)
    corners[np.asarray(triangles).ravel()] = np.repeat(selected[charts], 3)
    return np.where(corners[:, None], chart_uvs, base_uvs)


def pack_padding(padding, original):
    """The gutter the repack packs at: the padding, or the input's gutter
    (`original`, its check_layout report) where that is narrower
    (backoff.allowed_gutter), never below a texel unless the padding is
    (dilation needs a texel between charts). evaluate's uniform repack packs
    at it too."""
    return min(float(padding), max(float(original["min_gutter_texels"]), min(float(padding), 1.0)))


def _repacked(stage):
    """refine_uvs without the re-chart route from the in-chart `stage`
    (_in_charts) on: the chart repack, the triangle stretch, the figures and
    the report (a RefineResult)."""
    return _finished(stage, _repack_stage(stage))


@dataclass
class _Repacked:
    """The in-chart layout after its chart repack (_repack_stage), before the
    triangle stretch (_finished): what the re-chart route's model compares."""

    uvs: np.ndarray
    check: dict
    analysed: object          # (LayoutChecker, failing charts) of the packed layout, or None
    report: object            # allocation.repack's report, or None when the repack was not run


class _Unfinished:
    """A refinement of the in-chart `stage` repacked (`own_packing`: the
    re-chart route's layout), finished (_finished: its triangle stretch,
    figures and report) when first asked for: the route compares layouts
    before the triangle stretch, and finishes only those it may return."""

    def __init__(self, stage, own_packing):
        self.stage = stage
        self.repacked = _repack_stage(stage, own_packing)
        self._result = None

    @property
    def compared(self):
        """The layout the route's model compares (before the triangle stretch)."""
        return self.repacked.uvs

    @property
    def fit_reset(self):
        """Whether the automaton's finest level started with a fit that sent a
        region back to rest (rechart_route.fit_reset)."""
        return rechart_route.fit_reset(self.stage.run["levels"])

    @property
    def edge_shrink(self):
        return self.stage.edge_shrink_used

    def finished(self):
        """The RefineResult."""
        if self._result is None:
            self._result = _finished(self.stage, self.repacked)
        return self._result


def _repack_stage(stage, own_packing=False):
    """The chart repack of the in-chart `stage` (_in_charts): a _Repacked
    (the stage's own layout when the repack is off or not kept; its notes
    say why)."""
    options, uvs, triangles, shape, mask, original = \
        stage.options, stage.uvs, stage.triangles, stage.shape, stage.mask, stage.original
    scalar_energy, notes, timings = stage.energy, stage.notes, stage.timings
    new_uvs, check = stage.new_uvs, stage.check
    padding, progress = stage.padding, stage.progress
    strength = options["strength"]
    repack, min_chart_scale, max_chart_scale = options["repack"], options["min_chart_scale"], \
        options["max_chart_scale"]
    max_stretch = options["max_stretch"]
    repack_report = analysed = None
    if repack and strength > 0 and not stage.hold:
        clock = time.perf_counter()
        if not 0 < min_chart_scale <= 1 <= max_chart_scale < np.inf:
            raise ValueError(f"need 0 < min_chart_scale <= 1 <= max_chart_scale (finite), got {min_chart_scale} "
                             f"and {max_chart_scale}")
        if isinstance(max_stretch, (bool, np.bool_)) or not isinstance(max_stretch, (int, float, np.number)) \
                or not 1.0 <= float(max_stretch) < np.inf:
            raise ValueError(f"max_stretch must be a finite number >= 1 (1 = no stretch), got {max_stretch!r}")
        packed, repack_report = allocation.repack(uvs, new_uvs, triangles, scalar_energy, shape,
                                                  pack_padding(padding, original),
                                                  float(min_chart_scale), float(max_chart_scale), progress,
                                                  lightmap=stage.lightmap if stage.gradient_given is None else None,
                                                  mask=mask,
                                                  world_areas=stage.world_areas, max_stretch=float(max_stretch),
                                                  signal=_signal(stage), source_tensors=_source_tensors(stage),
                                                  own_packing=own_packing)
        if packed is not None:
            # Analysed once: the triangle stretch packs this layout's charts again.
            packed_checker = _native.LayoutChecker(packed, triangles, shape, padding)
            packed_check = packed_checker.check(failing_charts=True)
            worse = backoff.failures(packed_check, original, padding)
            failing = backoff.without_chart_lists(packed_check)
            if worse:
                repack_report["used"] = False
                notes.append(f"repack not used: the packed layout failed {', '.join(worse)}")
            else:
                new_uvs, check, analysed = packed, packed_check, (packed_checker, failing)
                softened = repack_report.get("softened")
                if softened:
                    refused = softened["refused"]
                    notes.append(f"charts scaled by the square roots of the model's scales: at its scales the "
                                 f"atlas would be {refused['padded_utilisation_after']:.0%} full with its gutters "
                                 f"(the input: {refused['padded_utilisation_before']:.0%})")
        elif "reason" in repack_report:
            notes.append(f"repack not used: {repack_report['reason']}")
        elif own_packing:
            notes.append(f"repack not used: the error model predicts {repack_report['predicted_error']:.3f} of the "
                         f"unpacked error (needed: below {allocation.OWN_PACKING_RULE.required_gain:g})")
        else:
            notes.append(f"repack not used: the error model predicts {repack_report['predicted_error']:.3f} of the "
                         f"unpacked error and the packed atlas would be "
                         f"{repack_report['padded_utilisation_after']:.0%} full with its gutters "
                         f"(the input: {repack_report['padded_utilisation_before']:.0%})")
        timings["repack"] = time.perf_counter() - clock
    return _Repacked(uvs=new_uvs, check=check, analysed=analysed, report=repack_report)


def _finished(stage, repacked):
    """_repacked from the `repacked` stage on: the triangle stretch, the
    figures and the report (a RefineResult)."""
    options, uvs, triangles, mask = stage.options, stage.uvs, stage.triangles, stage.mask
    scalar_energy, limited_by, notes, timings = stage.energy, stage.limited_by, stage.notes, stage.timings
    grid, kept = stage.grid, stage.kept
    strength, max_magnification, min_shrink = options["strength"], options["max_magnification"], \
        options["min_shrink"]
    repack, passes, border = options["repack"], options["passes"], options["border"]
    new_uvs, check, analysed, repack_report = repacked.uvs, repacked.check, repacked.analysed, repacked.report
    triangle_report, unstretched = None, None
    if options["triangle_stretch"] != 1.0 and repack and strength > 0 and not stage.hold:
        clock = time.perf_counter()
        unstretched = new_uvs
        new_uvs, check, triangle_report = _triangle_stretched(stage, new_uvs, check, analysed)
        if not triangle_report["used"]:
            notes.append(f"triangle stretch not used: {triangle_report['reason']}")
        timings["triangle_stretch"] = time.perf_counter() - clock
    areas = _native.grid_cell_areas(grid)
    covered_areas = areas[mask] if mask.any() else np.ones(1, np.float32)
    if covered_areas.max() >= max_magnification * 0.999:
        limited_by.append("max_magnification")
    if covered_areas.min() <= min_shrink * 1.001:
        limited_by.append("min_shrink")
    # Every figure is measured on the layout returned (triangle UV areas), not on the grid.
    at_change = stage.at_change if stage.at_change is not None else \
        _at_light_changes(uvs, triangles, scalar_energy, mask)
    figures = _layout_figures(uvs, new_uvs, triangles, scalar_energy, mask,
                              stage.lightmap if stage.gradient_given is None else None, _source_tensors(stage),
                              at_change)
    moved = not np.array_equal(new_uvs, uvs)
    if not moved:
        broke = [kind for kind in limited_by if kind in ("flipped", "overlapping", "gutter", "degenerate", "grid")]
        why = ("strength is 0" if strength == 0 else
               f"{stage.aligned:.0%} of the first lightmap's light steps lie on texel boundaries that the layout's "
               "edges run along (a flat-shaded mesh on a grid-aligned map), where no texel mixes two sides of a "
               "step; moving the vertices would put the steps inside texels" if stage.hold else
               "the lightmap has no light change inside the charts"
               if not np.any(scalar_energy[mask] > 0) else
               "every deformation broke the layout and was backed off (" + ", ".join(broke) + ")" if broke else
               "every UV lies on its chart's border (small charts, e.g. one per face), where a warp could only "
               "reshape each chart's one affine map, so the automaton was not run" if stage.no_room else
               "the automaton's deformation moved no UV")
        notes.append(f"nothing moved: {why}; the layout returned is the input")

    report = {
        "moved": moved,
        "aligned_steps": stage.aligned,
        **figures,
        "steps": int(stage.run["steps"]),
        "levels": stage.run["levels"],
        "finest_block": stage.run["finest_block"],
        "converged": bool(stage.run["converged"]),
        "strength_used": float(strength) * float(kept.min()),
        "backoff": float(kept.min()),
        "backoff_area": float((kept < 1).mean()),
        "limited_by": limited_by,
        "notes": notes,
        "passes": int(passes),
        "edge_shrink": stage.edge_shrink_used,
        "border": border,
        "seconds": time.perf_counter() - stage.start,
        "timings": timings,
        "original_check": stage.original,
        "check": check,
        "repack": repack_report,
        "triangle_stretch": triangle_report,
    }
    kept_stretch = triangle_report is not None and triangle_report["used"]
    return RefineResult(uvs=new_uvs, grid=grid, report=report, unstretched_uvs=unstretched if kept_stretch else None,
                        light_changes=(uvs, at_change, _source_tensors(stage)))


def _found_light_changes(light_changes, uvs, triangles):
    """(tensors, at_change) for _layout_figures from a RefineResult's
    `light_changes`, its structure tensors mapped into the frame of `uvs`
    (the same triangles)."""
    from . import stretch

    refined_from, at_change, tensors = light_changes
    if tensors is not None:
        tensors = stretch.triangle_tensors(None, None, refined_from, uvs, triangles, source=tensors)
    return tensors, at_change


def layout_figures(lightmap, old_uvs, new_uvs, triangles, wavelet="d4", light_changes=None):
    """The report's figures of a layout `new_uvs` made from `old_uvs` (one
    refinement or several in a row) at the light changes of `lightmap`,
    baked on `old_uvs`: transition_widening, density_min, density_max and
    triangle_density, as refine_uvs defines them. `light_changes`: the
    first refinement's RefineResult.light_changes, to count the light
    changes where it found them (a re-charted refinement: in the map carried
    to its layout) rather than in `lightmap`."""
    old_uvs, triangles = _layout(old_uvs, triangles)
    new_uvs = np.asarray(new_uvs, np.float32)
    if new_uvs.shape != old_uvs.shape:
        raise ValueError(f"new_uvs must have the shape of old_uvs {old_uvs.shape}, got {new_uvs.shape}")
    lightmap = np.asarray(lightmap)
    shape = tuple(lightmap.shape[:2]) if lightmap.ndim in (2, 3) else None
    if shape is None:
        raise ValueError(f"the lightmap must be an (H, W) or (H, W, C) array, got shape {lightmap.shape}")
    checker = _native.LayoutChecker(old_uvs, triangles, shape, 0.0)
    mask = checker.coverage_mask()
    if light_changes is not None:
        # The light changes are known: the energy that would find them is not needed (only its shape is read).
        return _layout_figures(old_uvs, new_uvs, triangles, np.zeros(shape, np.float32), mask, lightmap,
                               *_found_light_changes(light_changes, old_uvs, triangles))
    gradient = _gradient(lightmap, None, chart_separated(mask, checker.texel_owners()), shape, wavelet, None)
    return _layout_figures(old_uvs, new_uvs, triangles, gradient.sum(axis=2), mask, lightmap)


def _layout_figures(old, new, triangles, energy, mask, lightmap=None, tensors=None, at_change=None):
    """The report's figures of the layout `new` made from `old` (lightmap
    its first bake, or None; `tensors`: stretch.source_tensors' of it, and
    `at_change`: _at_light_changes', when the caller has them)."""
    density = _triangle_density(old, new, triangles)
    measured = density[np.isfinite(density) & (density > 0)]
    if at_change is None:
        at_change = _at_light_changes(old, triangles, energy, mask)
    widening, triangle_texels = _transition_figures(old, new, triangles, energy, at_change)
    return {
        "transition_widening": widening,
        "transition_widening_across": _transition_across(old, new, triangles, mask, at_change, lightmap, tensors),
        "transition_triangle_texels": triangle_texels,
        "density_min": float(measured.min()) if measured.size else 1.0,
        "density_max": float(measured.max()) if measured.size else 1.0,
        "triangle_density": density,
    }


def _transition_figures(old, new, triangles, energy, at_change):
    """(transition widening, median texels of a triangle at light changes).

    A triangle is at a light change when one of four points inside it (its
    centroid and the midpoints towards its corners, in the input layout)
    falls on a covered texel whose gradient energy is in the top decile of
    the covered texels. The widening is their summed new UV area over their
    summed old area, on the output layout (1.0 when no covered texel has
    gradient energy or no triangle lies on one); the second figure is the
    texel area, in the input layout, of the triangle under the median of
    their texels (their areas' median weighted by area; 0.0 then): a
    triangle's texels stay evenly spread, so one of many texels keeps a
    light change at the input's texel density whatever the warp does.
    Weighted, so that a finely cut object at a light change (Suzanne under
    a Subdivision Surface: thousands of triangles under a texel) does not
    hide a floor of large ones beside it. `at_change`: _at_light_changes'
    triangles."""
    if at_change is None:
        return 1.0, 0.0
    # Unsigned: a layout may wind a chart either way (the re-chart route's
    # charts need not keep the source's), and texels count the same.
    before = np.abs(allocation.signed_areas(old, triangles)[at_change])
    after = np.abs(allocation.signed_areas(new, triangles)[at_change])
    keep = before > 0
    if not keep.any():
        return 1.0, 0.0
    texels = _weighted_median(before[keep]) * energy.shape[0] * energy.shape[1]
    return float(after[keep].sum() / before[keep].sum()), texels


def _weighted_median(areas):
    """The value of `areas` (K,) > 0 at half their sum, each weighted by itself: the area of the
    triangle under the median point of their union."""
    ordered = np.sort(areas)
    total = np.cumsum(ordered)
    return float(ordered[min(int(np.searchsorted(total, 0.5 * total[-1])), len(ordered) - 1)])


def _at_light_changes(old, triangles, energy, mask):
    """(T,) bool: the triangles at a light change, as _transition_figures
    defines them; None when no covered texel has gradient energy."""
    covered = energy[mask]
    if covered.size == 0 or covered.max() <= 0 or len(triangles) == 0:
        return None
    threshold = max(float(np.percentile(covered, 90.0)), np.finfo(np.float32).tiny)
    rows, cols = allocation.triangle_texels(old, triangles, energy.shape)
    return (mask[rows, cols] & (energy[rows, cols] >= threshold)).any(axis=1)


def _transition_across(old, new, triangles, mask, at_change, lightmap, tensors=None):
    """The texels across the light changes at the triangles at a light
    change (_transition_figures' triangles), new over old: each triangle's
    linear scale |A e1| along the main direction e1 of its first bake's
    luminance gradient (stretch.source_tensors, in the input layout; A
    its map input -> output), averaged with the input areas as weights.
    The figure a stretch raises while it keeps the area (1.0 when nothing
    is at a light change; None without a lightmap). `at_change`:
    _at_light_changes' triangles; `tensors`: stretch.source_tensors' for
    lightmap, mask and old, when the caller has them."""
    from . import stretch

    if lightmap is None:
        return None
    if at_change is None or not at_change.any():
        return 1.0
    changing = triangles[at_change]
    # In the input layout's own frame the tensors need no mapping.
    values, vectors = np.linalg.eigh(stretch.source_tensors(lightmap, mask, old, changing) if tensors is None
                                     else tensors[at_change])
    maps, has_area = stretch.triangle_maps(old, new, changing)
    lit = values[:, 1] > 0
    maps, good = maps[lit[has_area]], has_area & lit
    if not good.any():
        return 1.0
    area = np.abs(allocation.signed_areas(np.asarray(old), changing))[good]
    across = np.linalg.norm(np.einsum("tij,tj->ti", maps, vectors[good, :, 1]), axis=1)
    return float((across * area).sum() / area.sum())


def _triangle_density(old, new, triangles):
    """New UV area / old UV area per triangle, unsigned (NaN where the old
    area is 0)."""
    before = np.abs(allocation.signed_areas(old, triangles))
    after = np.abs(allocation.signed_areas(new, triangles))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(before != 0, after / before, np.nan)
