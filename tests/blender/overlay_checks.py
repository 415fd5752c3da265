"""Checks of the texel-density overlay inside ONE headless Blender; writes facts as JSON for pytest.

    blender -b --factory-startup --python-exit-code 1 --python overlay_checks.py -- REPO OUT_JSON WORK_DIR

Headless Blender draws nothing, so the checks look at what the overlay would
draw (overlay.refresh's View: the arrays the batch is made of, the legend's
text) and at which handlers are installed. A check that raises is recorded
with its traceback.
"""

import json
import os
import sys
import traceback

REPO, OUT_JSON, WORK_DIR = sys.argv[sys.argv.index("--") + 1:][:3]
sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), os.path.dirname(__file__)]

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import lmrefine_blender  # noqa: E402
import scenes  # noqa: E402
from lmrefine_blender import overlay, panels  # noqa: E402
from scene_state import fingerprint  # noqa: E402

results = {}


def check(function):
    try:
        results[function.__name__] = function()
    except Exception:
        results[function.__name__] = {"exception": traceback.format_exc()}
    finally:
        overlay.disable()
    return function


def register():
    if not hasattr(bpy.types.Scene, "lmrefine"):
        lmrefine_blender.register()


def plane(name, size=2.0, location=(0.0, 0.0, 0.0)):
    """A size x size plane whose UV map 'UVMap' fills [0, 1]^2 (Blender's primitive)."""
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = name
    return obj


def set_uvs(obj, name, uvs):
    layer = obj.data.uv_layers.get(name) or obj.data.uv_layers.new(name=name)
    layer.data.foreach_set("uv", np.asarray(uvs, np.float32).ravel())
    obj.data.update()


def uvs_of(obj, name="UVMap"):
    values = np.empty(len(obj.data.loops) * 2, np.float32)
    obj.data.uv_layers[name].data.foreach_get("uv", values)
    return values.reshape(-1, 2)


def fresh(resolution=256, **values):
    scenes.reset()
    register()
    settings = bpy.context.scene.lmrefine
    settings.resolution = resolution
    settings.source_layer = "UVMap"
    for key, value in values.items():
        setattr(settings, key, value)
    return settings


def update():
    """What the viewport would do after a change: the depsgraph evaluates (handlers run), the timer refreshes."""
    bpy.context.view_layer.update()
    return overlay.refresh(bpy.context)


def view_facts(view):
    colours = np.unique(np.round(view.colours, 4), axis=0)
    return {"minimum": view.minimum, "median": view.median, "maximum": view.maximum, "reference": view.reference,
            "vertices": len(view.positions), "colours": colours.tolist(), "drawn": view.drawn,
            "fallback": view.fallback, "skipped": view.skipped, "legend": overlay.legend_lines(view),
            "finite": bool(np.isfinite(view.positions).all() and np.isfinite(view.colours).all()),
            "dtypes": [str(view.positions.dtype), str(view.colours.dtype)]}


@check
def known_plane():
    """2 m x 2 m, UVs fill [0, 1]^2, 256 x 256: 128 texels per metre; then transforms and modifiers."""
    settings = fresh()
    obj = plane("Plane")
    settings.density_overlay = True
    facts = {"plane": view_facts(overlay.current_view()),
             "green": overlay.ramp_colours([128.0], 128.0).tolist(),
             "ramp_ends": overlay.ramp_colours([32.0, 512.0, 1e9, 1.0, 0.0], 128.0).tolist()}
    obj.scale = (2.0, 2.0, 2.0)  # 4 m x 4 m: 64 per metre
    facts["scaled"] = view_facts(update())
    obj.scale = (1.0, 1.0, 1.0)
    obj.modifiers.new("Array", 'ARRAY').count = 3  # three times the area and three times the texels: 128
    facts["array"] = view_facts(update())
    obj.modifiers.clear()
    set_uvs(obj, "UVMap", uvs_of(obj) * 0.5)  # a quarter of the UV area: 64 per metre
    facts["uv_edit"] = view_facts(update())
    return facts


@check
def source_and_refined_maps():
    """Refined draws '<source>_refined' (half the texels per metre: cyan, 1/2x the source's median),
    Source draws the source map; an object without a refined map falls back to its source."""
    settings = fresh()
    obj = plane("Plane")
    set_uvs(obj, "UVMap_refined", uvs_of(obj) * 0.5)
    plane("Other", location=(3.0, 0.0, 0.0))
    settings.density_overlay = True
    refined = view_facts(overlay.current_view())
    settings.density_map = 'SOURCE'
    source = view_facts(overlay.current_view())
    return {"refined": refined, "source": source, "half": overlay.ramp_colours([64.0], 128.0).tolist()}


@check
def messy_meshes():
    """An n-gon, a zero-area face, a mesh without UV maps, a NaN UV, a huge and a zero scale, a modifier that
    drops the map: no exception, and every drawn value is finite."""
    settings = fresh()
    bpy.ops.mesh.primitive_circle_add(vertices=12, radius=1.0, fill_type='NGON', location=(0, 0, 0))
    ngon = bpy.context.active_object
    ngon.name = "Ngon"
    ngon.data.uv_layers.new(name="UVMap")
    xy = np.array([ngon.data.vertices[loop.vertex_index].co[:2] for loop in ngon.data.loops])
    set_uvs(ngon, "UVMap", 0.5 + xy * (0.5, 0.25))  # a squashed disc: 1/8 of the disc's area in UV
    sliver = scenes.degenerate_mesh()
    sliver.data.uv_layers.active_index = 1
    sliver.data.uv_layers.remove(sliver.data.uv_layers["UVMap"])
    sliver.data.uv_layers["Lightmap"].name = "UVMap"
    bare = scenes._mesh_object("Bare", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)])
    nan_uv = plane("NanUV", location=(5, 0, 0))
    values = uvs_of(nan_uv)
    values[0] = np.nan
    set_uvs(nan_uv, "UVMap", values)
    huge = plane("Huge", location=(8, 0, 0))
    huge.scale = (1e30, 1e30, 1e30)
    flat = plane("Flat", location=(11, 0, 0))
    flat.scale = (0.0, 0.0, 0.0)
    dropped = plane("Dropped", location=(14, 0, 0))
    dropped.data.uv_layers["UVMap"].name = "UVMap"
    weld = dropped.modifiers.new("Weld", 'WELD')
    weld.merge_threshold = 100.0  # collapses the plane: no faces left
    settings.density_overlay = True
    view = overlay.current_view()
    facts = view_facts(view)
    ngon_density = overlay._State.cache[("Ngon", "UVMap", 256)]
    facts["ngon_values"] = np.unique(np.round(ngon_density.values, 6)).tolist()
    facts["ngon_triangles"] = len(ngon_density.values)
    # sqrt(UV area x R^2 / area): the disc's UV area is (pi r^2) * 0.5 * 0.25 over its world area pi r^2.
    area = sum(p.area for p in ngon.data.polygons)
    uv_area = 0.0
    for polygon in ngon.data.polygons:
        corners = uvs_of(ngon)[polygon.loop_start:polygon.loop_start + polygon.loop_total]
        uv_area += 0.5 * abs(np.dot(corners[:, 0], np.roll(corners[:, 1], -1))
                             - np.dot(corners[:, 1], np.roll(corners[:, 0], -1)))
    facts["ngon_expected"] = float(np.sqrt(uv_area * 256 ** 2 / area))
    facts["sliver_values"] = overlay._State.cache[("Sliver", "UVMap", 256)].values.tolist()
    facts["bare_skipped"] = [entry for entry in view.skipped if entry[0] == "Bare"]
    # The draw callbacks in a Blender that cannot draw (background): they must not raise.
    import contextlib
    import io
    raised, printed = [], io.StringIO()
    with contextlib.redirect_stdout(printed):
        for callback in (overlay._draw_surface, overlay._draw_legend) * 3:  # three frames
            try:
                callback()
            except Exception as error:  # noqa: BLE001 - the fact is whether anything escapes
                raised.append(repr(error))
    facts["draw_raised"] = raised
    facts["draw_messages"] = printed.getvalue().count("overlay stopped drawing")
    facts["rows"] = panels.density_rows(settings)
    del bare
    return facts


@check
def depth_bias_and_cache():
    """The surface is pulled towards the camera by DEPTH_BIAS of its distance in perspective, by a constant in
    orthographic views, and the projection given is not modified; the cache keeps only what the view uses."""
    import math
    from mathutils import Matrix, Vector
    near, far, focal = 0.01, 1000.0, 1.0 / math.tan(0.4)
    perspective = Matrix(((focal, 0, 0, 0), (0, focal, 0, 0),
                          (0, 0, (far + near) / (near - far), 2 * far * near / (near - far)), (0, 0, -1, 0)))
    orthographic = Matrix(((0.1, 0, 0, 0), (0, 0.1, 0, 0), (0, 0, -2 / (far - near), -(far + near) / (far - near)),
                           (0, 0, 0, 1)))
    before = [tuple(row) for row in perspective]
    biased = overlay.depth_biased(perspective, 10.0)

    def ndc(matrix, distance):
        clip = matrix @ Vector((0.0, 0.0, -distance, 1.0))
        return clip.z / clip.w

    # The distance whose plain depth equals the biased depth at `distance` (ndc = -A + B / d).
    a, b = perspective[2][2], perspective[2][3]
    apparent = {d: b / (ndc(biased, d) + a) / d for d in (0.5, 2.0, 10.0)}  # mathutils computes in float32
    ortho_biased = overlay.depth_biased(orthographic, 10.0)
    ortho_shift = [ndc(orthographic, d) - ndc(ortho_biased, d) for d in (0.5, 10.0, 300.0)]
    # The cache: switch to Source, then to another resolution: only the entries in use stay.
    settings = fresh()
    obj = plane("Plane")
    set_uvs(obj, "UVMap_refined", uvs_of(obj) * 0.5)
    settings.density_overlay = True
    keys = {"refined": sorted(overlay._State.cache)}
    settings.density_map = 'SOURCE'
    keys["source"] = sorted(overlay._State.cache)
    settings.resolution = 512
    update()
    keys["resolution"] = sorted(overlay._State.cache)
    return {"apparent": list(apparent.values()), "expected": 1 / (1 + overlay.DEPTH_BIAS),
            "unchanged": [tuple(row) for row in perspective] == before, "ortho_shift": ortho_shift,
            "keys": keys}


@check
def random_broken_meshes():
    """40 meshes of random n-gons with NaN, Inf, huge and repeated vertices and NaN, Inf and collapsed UVs:
    the view is computed without an exception and draws only finite arrays."""
    settings = fresh()
    rng = np.random.default_rng(13)
    specials = np.array([np.nan, np.inf, -np.inf, 1e30, 1e-30, 0.0])
    for index in range(40):
        vertices = rng.normal(size=(int(rng.integers(3, 12)), 3)) * 10.0 ** rng.integers(-3, 4)
        vertices[rng.random(vertices.shape) < 0.05] = rng.choice(specials)
        vertices[rng.integers(len(vertices))] = vertices[0]  # a repeated vertex
        faces = []
        for _ in range(int(rng.integers(1, 6))):
            corners = rng.choice(len(vertices), size=int(rng.integers(3, min(len(vertices), 6) + 1)), replace=False)
            faces.append([int(c) for c in corners])
        mesh = bpy.data.meshes.new(f"Broken{index}")
        mesh.from_pydata([tuple(v) for v in vertices], [], faces)
        layer = mesh.uv_layers.new(name="UVMap")
        uvs = rng.random((len(mesh.loops), 2))
        uvs[rng.random(uvs.shape) < 0.1] = rng.choice(specials)
        if index % 5 == 0:
            uvs[:] = 0.5  # no texels at all
        layer.data.foreach_set("uv", uvs.astype(np.float32).ravel())
        obj = bpy.data.objects.new(f"Broken{index}", mesh)
        bpy.context.scene.collection.objects.link(obj)
    settings.density_overlay = True
    view = overlay.current_view()
    return {"finite": bool(np.isfinite(view.positions).all() and np.isfinite(view.colours).all()),
            "drawn": len(view.drawn), "skipped": len(view.skipped), "vertices": len(view.positions),
            "colours_in_range": bool(((view.colours >= 0) & (view.colours <= 1)).all()),
            "legend": overlay.legend_lines(view)}


@check
def toggle_adds_and_removes_handlers():
    settings = fresh()
    plane("Plane")

    def installed():
        return {"handles": len(overlay._State.handles), "enabled": settings.density_overlay,
                "depsgraph": overlay._on_depsgraph_update in bpy.app.handlers.depsgraph_update_post,
                "undo": overlay._on_undo in bpy.app.handlers.undo_post,
                "redo": overlay._on_undo in bpy.app.handlers.redo_post,
                "load_pre": overlay._on_load_pre in bpy.app.handlers.load_pre,
                "view": overlay.current_view() is not None}

    before = fingerprint()
    off = installed()
    settings.density_overlay = True
    on = installed()
    settings.density_overlay = True  # twice: still one set of handlers
    twice = installed()
    rows_on = panels.density_rows(settings)
    unchanged = fingerprint() == before
    settings.density_overlay = False
    after = installed()
    return {"off": off, "on": on, "twice": twice, "after": after, "rows_on": rows_on,
            "rows_off": panels.density_rows(settings), "scene_unchanged": unchanged,
            "depsgraph_handlers_after": len(bpy.app.handlers.depsgraph_update_post)}


@check
def loading_a_file_removes_the_handlers():
    settings = fresh()
    plane("Plane")
    path = os.path.join(WORK_DIR, "overlay.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    settings.density_overlay = True
    on = overlay.enabled()
    bpy.ops.wm.open_mainfile(filepath=path)
    after_open = {"enabled": overlay.enabled(), "handles": len(overlay._State.handles),
                  "depsgraph": overlay._on_depsgraph_update in bpy.app.handlers.depsgraph_update_post,
                  "load_pre_kept": overlay._on_load_pre in bpy.app.handlers.load_pre,
                  "property": bpy.context.scene.lmrefine.density_overlay}
    bpy.context.scene.lmrefine.density_overlay = True  # works again in the new file
    again = overlay.enabled() and overlay.current_view() is not None
    bpy.ops.wm.read_homefile(use_empty=True)
    after_new = overlay.enabled()
    return {"on": on, "after_open": after_open, "again": again, "after_new_file": after_new}


@check
def unregister_removes_the_handlers():
    settings = fresh()
    plane("Plane")
    settings.density_overlay = True
    on = overlay.enabled()
    lmrefine_blender.unregister()
    facts = {"on": on, "enabled": overlay.enabled(),
             "depsgraph": overlay._on_depsgraph_update in bpy.app.handlers.depsgraph_update_post,
             "load_pre": overlay._on_load_pre in bpy.app.handlers.load_pre}
    lmrefine_blender.register()
    facts["load_pre_after_register"] = overlay._on_load_pre in bpy.app.handlers.load_pre
    return facts


with open(OUT_JSON, "w", encoding="utf-8") as stream:
    json.dump(results, stream, indent=1, default=str)
