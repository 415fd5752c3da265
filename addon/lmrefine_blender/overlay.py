"""The Texel Density overlay: texels per metre of a lightmap UV map, drawn on the surfaces in the 3D viewport.

Each face gets one colour from `lmrefine.metrics.texels_per_metre` (the
square root of the face's texels at the panel's Resolution over its world
area, as the bake sees the object: after its modifiers and transform), the
figure the evaluation reports picture. Nothing is written into the scene:
the numbers live in a cache here, per object and UV map, dropped when a
depsgraph update says the object's geometry or transform changed, and
recomputed on a timer, never while drawing. The draw callbacks only draw
what `refresh` prepared, and never raise (an exception there would repeat
every frame): the first error is printed once and the overlay goes quiet
until the next refresh.

The colour scale is fixed (docs/blender.md, "Texel density overlay"): the
colour says how many times the reference density a face has, on a log scale
from 1/4x (blue) through 1x (green) to 4x (red), the reference being the
median, by surface area, of the source maps of the objects drawn. Faces
with no texels (a zero UV area) are magenta.
"""

import math
import traceback
from dataclasses import dataclass, field

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import bridge
from .errors import UserError
from .pipeline import REFINED_SUFFIX

# Octaves of density either side of the reference that the colours span.
OCTAVES = 2.0
# (log2 of density / reference, colour) stops of the ramp.
RAMP = ((-2.0, (0.15, 0.35, 1.0)), (-1.0, (0.1, 0.8, 0.95)), (0.0, (0.2, 0.85, 0.2)), (1.0, (1.0, 0.85, 0.1)),
        (2.0, (1.0, 0.15, 0.1)))
NO_TEXELS = (1.0, 0.0, 1.0)
# Opaque enough to read the colours, thin enough to keep the viewport's shading visible underneath.
ALPHA = 0.8
# How far the surface is pulled towards the camera so it wins the depth test
# against the mesh it covers: a fraction of the distance in perspective (as
# Blender's own overlays do), of the view distance in orthographic views.
DEPTH_BIAS = 0.00125


@dataclass
class ObjectDensity:
    """One object's density in one UV map: world-space corners and per-triangle texels per metre."""

    positions: np.ndarray  # (L, 3) float32, per loop, world space
    triangles: np.ndarray  # (T, 3) int32 loop indices
    values: np.ndarray  # (T,) texels per metre of the triangle's face, NaN where it has no world area
    areas: np.ndarray  # (T,) world area of each triangle


@dataclass
class View:
    """What the overlay draws: the surface arrays and the legend's numbers."""

    positions: np.ndarray  # (3K, 3) float32: K triangles
    colours: np.ndarray  # (3K, 4) float32
    resolution: int
    reference: float  # texels per metre shown green (the source maps' median)
    minimum: float
    median: float
    maximum: float
    shown: str  # 'REFINED' or 'SOURCE': the maps drawn
    drawn: list = field(default_factory=list)  # (object name, UV map) drawn
    fallback: list = field(default_factory=list)  # objects without a refined map, drawn with their source map
    skipped: list = field(default_factory=list)  # (object name, why) not drawn


class _State:
    handles = []  # SpaceView3D draw handler handles
    cache = {}  # (object name, UV map, resolution) -> ObjectDensity or a reason string
    view = None
    signature = None
    batch = None  # (shader, batch), made in the draw callback from `view`
    pending = False  # a refresh timer is registered
    failed = None  # the first error of a draw callback


# ------------------------------------------------------------ the numbers

def object_density(obj, uv_name, resolution, depsgraph):
    """ObjectDensity of `obj` in UV map `uv_name` as the bake sees it
    (evaluated, world space), or a reason string when it has none."""
    from lmrefine import metrics
    from lmrefine.layout_input import MAX_COORDINATE
    obj_eval = obj.evaluated_get(depsgraph)
    try:
        export = bridge.export_mesh(obj_eval, obj_eval.matrix_world, uv_name=uv_name, name=obj.name)
    except UserError:
        return f"loses '{uv_name}' in its modifiers"
    if export is None:
        return "no faces or no area after its modifiers and transform"
    if not (np.abs(export.positions) <= MAX_COORDINATE).all():  # the bake refuses it too
        return "vertices at NaN, Inf or beyond 1e9 units"
    with np.errstate(all="ignore"):
        areas = metrics.triangle_areas(export.positions, export.triangles)
    values = metrics.texels_per_metre(export.uvs, export.triangles, areas, resolution, faces=export.polygons)
    return ObjectDensity(export.positions, export.triangles, values, areas)


def maps_for(obj, settings):
    """(source map, map to draw) of a mesh object, or (None, None) when it has no source map.
    Refined draws `<source>_refined` where it exists, else the source map."""
    mesh = obj.data
    source = settings.source_layer.strip() or bridge.default_source_layer(mesh)
    if source is None or source not in mesh.uv_layers:
        return None, None
    refined = source + REFINED_SUFFIX
    if settings.density_map == 'REFINED' and refined in mesh.uv_layers:
        return source, refined
    return source, source


def weighted_median(values, weights):
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, cumulative[-1] / 2)])


def ramp_colours(values, reference, alpha=ALPHA):
    """(N, 4) colours of densities `values` against `reference`: the fixed
    log scale from 1/4x (blue) to 4x (red), magenta for 0 (no texels)."""
    values = np.asarray(values, np.float64)
    with np.errstate(all="ignore"):
        octave = np.clip(np.log2(values / reference), -OCTAVES, OCTAVES)
    octave = np.nan_to_num(octave, nan=0.0)
    stops = np.array([stop for stop, _ in RAMP])
    colours = np.stack([np.interp(octave, stops, [colour[c] for _, colour in RAMP]) for c in range(3)], axis=1)
    colours[~(values > 0)] = NO_TEXELS
    return np.concatenate([colours, np.full((len(values), 1), alpha)], axis=1).astype(np.float32)


def surface_arrays(density, reference):
    """(positions (3K, 3), colours (3K, 4)) float32 of the K triangles of
    `density` that can be drawn: a finite value and finite corners."""
    corners = density.positions[density.triangles]  # (T, 3, 3)
    keep = np.isfinite(density.values) & np.isfinite(corners).all(axis=(1, 2))
    colours = np.repeat(ramp_colours(density.values[keep], reference), 3, axis=0)
    return np.ascontiguousarray(corners[keep].reshape(-1, 3), np.float32), colours


def compute_view(scene, view_layer, depsgraph):
    """The View of `scene`: every visible mesh object with a source map,
    drawn with the map the panel picks; densities come from the cache."""
    settings = scene.lmrefine
    resolution = int(settings.resolution)
    entries, sources, skipped, fallback, used = [], [], [], [], set()
    for obj in scene.objects:
        if obj.type != 'MESH' or not obj.visible_get(view_layer=view_layer):
            continue
        source, shown = maps_for(obj, settings)
        if source is None:
            skipped.append((obj.name, "no lightmap UV map"))
            continue
        densities = {}
        for name in {source, shown}:
            key = (obj.name, name, resolution)
            if key not in _State.cache:
                _State.cache[key] = object_density(obj, name, resolution, depsgraph)
            densities[name] = _State.cache[key]
            used.add(key)
        if isinstance(densities[shown], str) or isinstance(densities[source], str):
            why = densities[shown] if isinstance(densities[shown], str) else densities[source]
            skipped.append((obj.name, why))
            continue
        if settings.density_map == 'REFINED' and shown == source:
            fallback.append(obj.name)
        entries.append((obj.name, shown, densities[shown]))
        sources.append(densities[source])

    for key in [key for key in _State.cache if key not in used]:  # renamed, deleted, another resolution
        del _State.cache[key]

    def pooled(items):
        values = np.concatenate([d.values for d in items]) if items else np.zeros(0)
        areas = np.concatenate([d.areas for d in items]) if items else np.zeros(0)
        usable = np.isfinite(values) & np.isfinite(areas)
        return values[usable], areas[usable]

    source_values, source_areas = pooled(sources)
    reference = weighted_median(source_values, source_areas) if source_values.size else 1.0
    if not reference > 0:  # every source face without texels: any scale shows them magenta
        reference = 1.0
    values, areas = pooled([entry[2] for entry in entries])
    arrays = [surface_arrays(entry[2], reference) for entry in entries]
    positions = np.concatenate([a[0] for a in arrays]) if arrays else np.zeros((0, 3), np.float32)
    colours = np.concatenate([a[1] for a in arrays]) if arrays else np.zeros((0, 4), np.float32)
    nan = float("nan")
    return View(positions, colours, resolution, reference,
                float(values.min()) if values.size else nan,
                weighted_median(values, areas) if values.size else nan,
                float(values.max()) if values.size else nan,
                settings.density_map, [(name, uv) for name, uv, _ in entries], fallback, skipped)


def format_density(value):
    """A density for the legend and the panel: whole texels from 100 to 99999, else 3 digits (1.23e+07)."""
    if not math.isfinite(value):
        return "-"
    return f"{value:.0f}" if 100 <= abs(value) < 1e5 else f"{value:.3g}"


def legend_lines(view):
    """The legend's text, top to bottom; the colour bar and its values are drawn under it."""
    which = "refined maps" if view.shown == 'REFINED' else "source maps"
    lines = [f"Texel density: {which} at {view.resolution} x {view.resolution}"]
    if view.fallback:
        lines.append(f"{len(view.fallback)} object(s) without a refined map show the source map")
    if view.skipped:
        lines.append(f"not drawn: {len(view.skipped)} object(s) without a lightmap UV map or anything to bake")
    lines.append(f"min {format_density(view.minimum)} / median {format_density(view.median)} / "
                 f"max {format_density(view.maximum)} texels per metre")
    lines.append(f"green: {format_density(view.reference)}/m, the source maps' median; blue 1/4x, red 4x; "
                 "magenta: no texels")
    return lines


# ------------------------------------------------------------ refreshing

def refresh(context=None):
    """Recompute what the overlay draws (the cache makes this cheap when
    little changed); called on a timer after a change and when it is turned on."""
    context = context or bpy.context
    scene, view_layer = context.scene, context.view_layer
    if scene is None or view_layer is None or not hasattr(scene, "lmrefine"):
        return None
    depsgraph = context.evaluated_depsgraph_get()
    settings = scene.lmrefine
    signature = (scene.name, settings.density_map, settings.source_layer, int(settings.resolution),
                 tuple((obj.name, obj.visible_get(view_layer=view_layer), tuple(obj.data.uv_layers.keys()))
                       for obj in scene.objects if obj.type == 'MESH'))
    if signature != _State.signature or _State.view is None:
        _State.view = compute_view(scene, view_layer, depsgraph)
        _State.signature = signature
        _State.batch = None
        _State.failed = None
        _redraw()
    return _State.view


def _redraw():
    window_manager = bpy.context.window_manager
    for window in (window_manager.windows if window_manager else ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def _refresh_soon():
    if not _State.pending:
        _State.pending = True
        bpy.app.timers.register(_refresh_timer, first_interval=0.05)


def _refresh_timer():
    _State.pending = False
    if _State.handles:
        try:
            refresh()
        except Exception:
            _report_once("refresh")
    return None


def _on_depsgraph_update(scene, depsgraph):
    """Drop the cached densities of objects whose geometry or transform changed; refresh soon."""
    changed = False
    for update in depsgraph.updates:
        data = update.id
        if isinstance(data, bpy.types.Object) and (update.is_updated_geometry or update.is_updated_transform):
            forget(data.original.name)
            changed = True
        elif isinstance(data, bpy.types.Mesh):
            for obj in bpy.data.objects:
                if obj.data is not None and obj.data.name == data.original.name:
                    forget(obj.name)
            changed = True
        elif isinstance(data, bpy.types.Scene):
            changed = True  # settings, visibility: the view's signature decides
    if changed:
        _refresh_soon()


def _on_undo(*_):
    _State.cache.clear()
    _State.signature = None
    _refresh_soon()


def forget(object_name):
    for key in [key for key in _State.cache if key[0] == object_name]:
        del _State.cache[key]
    _State.signature = None


# ------------------------------------------------------------ drawing

def _report_once(where):
    if _State.failed is None:
        _State.failed = f"{where}: {traceback.format_exc()}"
        print(f"lmrefine texel density overlay stopped drawing ({where}); it resumes after the next change:\n"
              f"{traceback.format_exc()}")


def depth_biased(projection, view_distance):
    """`projection` (a 4x4 mathutils.Matrix) pulled towards the camera by
    DEPTH_BIAS (what Blender's polygon offset does): the overlay wins the
    depth test against the surface it covers and loses against what is in front."""
    biased = projection.copy()
    if biased[3][3] > 0.5:  # orthographic
        biased[2][3] -= DEPTH_BIAS * 0.01 * view_distance
    else:
        biased[2][3] *= 1.0 + DEPTH_BIAS
    return biased


def _draw_surface():
    view = _State.view
    if view is None or _State.failed is not None or not len(view.positions):
        return
    try:
        import gpu
        from gpu_extras.batch import batch_for_shader
        if _State.batch is None:
            shader = gpu.shader.from_builtin('3D_FLAT_COLOR')
            _State.batch = (shader, batch_for_shader(shader, 'TRIS', {"pos": view.positions,
                                                                      "color": view.colours}))
        shader, batch = _State.batch
        region = bpy.context.region_data
        state = gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get()
        gpu.state.depth_test_set('LESS_EQUAL')
        gpu.state.depth_mask_set(False)
        gpu.state.blend_set('ALPHA')
        try:
            with gpu.matrix.push_pop_projection():
                gpu.matrix.load_projection_matrix(depth_biased(gpu.matrix.get_projection_matrix(),
                                                               region.view_distance if region else 10.0))
                batch.draw(shader)
        finally:  # what Blender's next drawing expects
            gpu.state.depth_test_set(state[0])
            gpu.state.depth_mask_set(state[1])
            gpu.state.blend_set(state[2])
    except Exception:
        _report_once("surface")


def _draw_legend():
    view = _State.view
    if view is None:
        return
    try:
        import blf
        import gpu
        from gpu_extras.batch import batch_for_shader
        context = bpy.context
        scale = context.preferences.system.ui_scale
        left = 16 * scale
        if context.preferences.system.use_region_overlap:  # the toolbar is drawn over the viewport
            left += sum(r.width for r in context.area.regions if r.type == 'TOOLS' and r.width > 1)
        line_height, size = 16 * scale, int(11 * scale)
        lines = legend_lines(view)
        font = 0
        blf.size(font, size, 72)
        blf.enable(font, blf.SHADOW)  # readable over any colour
        blf.shadow(font, 3, 0.0, 0.0, 0.0, 0.9)
        blf.shadow_offset(font, 1, -1)
        bar_width, bar_height = 240 * scale, 10 * scale
        y = 16 * scale
        # The colour bar with its end and middle values under it.
        blf.color(font, 1.0, 1.0, 1.0, 1.0)
        for fraction, octave in ((0.0, -OCTAVES), (0.5, 0.0), (1.0, OCTAVES)):
            text = format_density(view.reference * 2.0 ** octave)
            width = blf.dimensions(font, text)[0]
            blf.position(font, left + fraction * (bar_width - width), y, 0)
            blf.draw(font, text)
        y += line_height
        stops = [(left + (stop + OCTAVES) / (2 * OCTAVES) * bar_width, colour) for stop, colour in RAMP]
        positions, colours = [], []
        for (x0, c0), (x1, c1) in zip(stops, stops[1:]):
            quad = [(x0, y), (x1, y), (x1, y + bar_height), (x0, y), (x1, y + bar_height), (x0, y + bar_height)]
            positions += quad
            colours += [(*c, 1.0) for c in (c0, c1, c1, c0, c1, c0)]
        shader = gpu.shader.from_builtin('2D_SMOOTH_COLOR')
        batch_for_shader(shader, 'TRIS', {"pos": positions, "color": colours}).draw(shader)
        y += bar_height + 6 * scale
        for text in reversed(lines):
            blf.position(font, left, y, 0)
            blf.draw(font, text)
            y += line_height
        blf.disable(font, blf.SHADOW)
    except Exception:
        _report_once("legend")


# ------------------------------------------------------------ on and off

def enabled():
    return bool(_State.handles)


def current_view():
    """The View being drawn, None when the overlay is off."""
    return _State.view if _State.handles else None


def settings_changed(_settings, context):
    """A setting the overlay draws from changed: redraw now, not on the next depsgraph update."""
    if enabled():
        refresh(context)


def set_enabled(value):
    """Turn the overlay on or off (the panel's checkbox)."""
    if value:
        enable()
    else:
        disable()


def enable(context=None):
    """Add the draw and update handlers (once) and compute what to draw."""
    if not _State.handles:
        _State.handles = [
            bpy.types.SpaceView3D.draw_handler_add(_draw_surface, (), 'WINDOW', 'POST_VIEW'),
            bpy.types.SpaceView3D.draw_handler_add(_draw_legend, (), 'WINDOW', 'POST_PIXEL'),
        ]
        for handlers, function in _UPDATE_HANDLERS:
            if function not in handlers:
                handlers.append(function)
    _State.signature = None
    refresh(context)


def disable():
    """Remove every handler the overlay added and drop its data."""
    for handle in _State.handles:
        bpy.types.SpaceView3D.draw_handler_remove(handle, 'WINDOW')
    _State.handles = []
    for handlers, function in _UPDATE_HANDLERS:
        while function in handlers:
            handlers.remove(function)
    _State.cache.clear()
    _State.view = _State.batch = _State.signature = _State.failed = None
    if bpy.app.timers.is_registered(_refresh_timer):
        bpy.app.timers.unregister(_refresh_timer)
    _State.pending = False
    _redraw()


@persistent
def _on_load_pre(*_):
    """A new file: no overlay (its draw handlers would outlive the scene they draw)."""
    disable()


_UPDATE_HANDLERS = ((bpy.app.handlers.depsgraph_update_post, _on_depsgraph_update),
                    (bpy.app.handlers.undo_post, _on_undo), (bpy.app.handlers.redo_post, _on_undo))


def register():
    if _on_load_pre not in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.append(_on_load_pre)


def unregister():
    disable()
    while _on_load_pre in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_on_load_pre)
