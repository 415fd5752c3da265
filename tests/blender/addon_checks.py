"""Checks of the lmrefine add-on inside ONE headless Blender; prints facts as JSON for pytest to assert.

    blender -b --factory-startup --python-exit-code 1 --python addon_checks.py -- REPO OUT_JSON WORK_DIR

Every check rebuilds its scene, so checks do not depend on each other. A
check that raises is recorded with its traceback (pytest shows it). The add-on
is loaded from the repository (addon/ and python/ on sys.path), never from an
installed copy.
"""

import json
import os
import sys
import traceback

REPO, OUT_JSON, WORK_DIR = sys.argv[sys.argv.index("--") + 1:][:3]
sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), os.path.dirname(__file__)]

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import lmrefine  # noqa: E402
from lmrefine import metrics  # noqa: E402
import lmrefine_blender  # noqa: E402
import lmrefine_blender.atlas  # noqa: E402
import scenes  # noqa: E402
from scene_state import _array, _digest, changed, fingerprint  # noqa: E402,F401
from lmrefine_blender import bridge, cycles_bake, operators, pipeline  # noqa: E402
from lmrefine_blender.journal import Journal  # noqa: E402

RESOLUTION = 64  # small: the whole group must stay fast
ATLAS = ("Blocker", "Floor", "Post")  # the objects scenes.atlas_scene lays out in one atlas
# LMREFINE_CHECKS=name,name runs only those checks (while working on them); pytest runs them all.
ONLY = set(filter(None, os.environ.get("LMREFINE_CHECKS", "").split(",")))

results = {}


def check(*needs):
    """Run the decorated check now and record its facts (or its traceback).
    `needs` names the parts of lmrefine it uses; a missing one fails the check."""
    exports = {"refine": ("refine_uvs", "check_layout"), "bake": ("bake", "Scene")}

    def run(function):
        if ONLY and function.__name__ not in ONLY:
            return function
        missing = [name for need in needs for name in exports[need] if not hasattr(lmrefine, name)]
        if missing:
            results[function.__name__] = {"exception": f"lmrefine lacks {', '.join(missing)}"}
            return function
        try:
            results[function.__name__] = function()
        except Exception:
            results[function.__name__] = {"exception": traceback.format_exc()}
        return function

    return run


def register():
    if not hasattr(bpy.types.Scene, "lmrefine"):
        lmrefine_blender.register()


# --------------------------------------------------------------- utilities

def geometry_digest(mesh):
    """Vertices, topology, normals and material indices: what a refinement must never touch."""
    return _digest(_array(mesh.vertices, "co", 3), _array(mesh.loops, "vertex_index", 1, np.int32),
                   _array(mesh.polygons, "loop_start", 1, np.int32), _array(mesh.polygons, "loop_total", 1, np.int32),
                   _array(mesh.polygons, "material_index", 1, np.int32), _array(mesh.polygons, "use_smooth", 1, bool))


def refine(undo=False, how='EXEC_DEFAULT'):
    """Run the operator like a script does; returns ('FINISHED'|'CANCELLED', error message or None)."""
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        try:
            result = bpy.ops.object.lmrefine_refine_uvs(how, undo)
        except RuntimeError as error:  # an ERROR report raises
            return "CANCELLED", str(error)
    return sorted(result)[0], None


def refine_with_reports(undo=False):
    """refine(undo), and the reports the operator made when it finished: [(kind, text)] ('INFO', 'WARNING'),
    as the Info log and the status bar show them."""
    reports, report_outcome = [], operators._report_outcome

    class Recording:
        """The operator, its reports recorded."""

        def __init__(self, operator):
            self.operator = operator

        def report(self, kinds, text):
            reports.append((sorted(kinds)[0], text))
            self.operator.report(kinds, text)

    operators._report_outcome = lambda operator, *args: report_outcome(Recording(operator), *args)
    try:
        outcome, message = refine(undo)
    finally:
        operators._report_outcome = report_outcome
    return outcome, message, reports


def settings(**values):
    target = bpy.context.scene.lmrefine
    for key, value in values.items():
        setattr(target, key, value)
    return target


def fresh_scene(build, **values):
    """build() a test scene, register the add-on and set the checks' settings (`values` add to or
    replace them)."""
    build()
    register()
    settings(**{"resolution": RESOLUTION, "padding": 2, "samples": 4, **values})


def fresh_shadow_scene(**values):
    fresh_scene(scenes.shadow_scene, **values)


# The checks' usual first map and second bake: the Embree baker, direct light.
EMBREE_DIRECT = {"first_lightmap": 'EMBREE', "backend": 'EMBREE', "bake_passes": {'DIRECT'}}


@check()
def registration():
    """register() adds the operators, the panels and Scene.lmrefine; unregister() removes all of them."""
    register()
    names = ("LMREFINE_PT_refine", "LMREFINE_PT_refine_options", "LMREFINE_PT_refine_stages",
             "LMREFINE_PT_refine_bake", "LMREFINE_PT_refine_result", "LMREFINE_PT_refine_warnings")
    registered = {
        "panels": [name for name in names if hasattr(bpy.types, name)],
        "category": bpy.types.LMREFINE_PT_refine.bl_category,
        "space": bpy.types.LMREFINE_PT_refine.bl_space_type,
        "operators": [hasattr(bpy.ops.object, "lmrefine_refine_uvs"),
                      hasattr(bpy.ops.object, "lmrefine_remove_preview")],
        "label": bpy.ops.object.lmrefine_refine_uvs.get_rna_type().name,
        "scene_property": hasattr(bpy.types.Scene, "lmrefine"),
    }
    # Panels are only drawn with a window; at least every icon they name must exist in this Blender.
    import inspect
    import re
    from lmrefine_blender import panels
    icons = bpy.types.UILayout.bl_rna.functions["prop"].parameters["icon"].enum_items.keys()
    used = set(re.findall(r"icon='(\w+)'", inspect.getsource(panels)))
    used |= set(re.findall(r"else '(\w+)'", inspect.getsource(panels)))
    registered["icons_used"] = sorted(used)
    registered["icons_missing"] = sorted(used - set(icons))
    lmrefine_blender.unregister()
    unregistered = {
        "panels": [name for name in names if hasattr(bpy.types, name)],
        "scene_property": hasattr(bpy.types.Scene, "lmrefine"),
        "operator": "lmrefine_refine_uvs" in dir(bpy.ops.object),
    }
    lmrefine_blender.register()
    return {"registered": registered, "unregistered": unregistered}


# ------------------------------------------------------------ error cases

def _error_case(prepare):
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE')
    prepare()
    before = fingerprint()
    outcome, message = refine()
    return {"outcome": outcome, "message": message, "changed": changed(before, fingerprint())}


@check()
def error_no_mesh():
    return _error_case(lambda: scenes.select_only())


@check()
def error_only_light_selected():
    return _error_case(lambda: scenes.select_only(bpy.data.objects["Sun"]))


@check()
def error_no_uv_layer():
    return _error_case(lambda: scenes.select_only(scenes.bare_mesh()))


@check()
def error_missing_source_layer():
    return _error_case(lambda: settings(source_layer="NoSuchMap"))


@check()
def error_edit_mode():
    def prepare():
        bpy.ops.object.mode_set(mode='EDIT')
    result = _error_case(prepare)
    bpy.ops.object.mode_set(mode='OBJECT')
    return result


@check()
def error_only_bad_objects():
    """Every selected object is skipped: the run stops, naming each with its fix."""
    return _error_case(lambda: scenes.select_only(scenes.bare_mesh(), scenes.flat_mesh()))


@check()
def error_hidden_object():
    """Hiding deselects in the UI, but the batch entry names objects: validation must catch it."""
    fresh_shadow_scene()
    floor = bpy.data.objects["Floor"]
    floor.hide_set(True)
    before = fingerprint()
    try:
        pipeline.validate(bpy.context, [floor], pipeline.settings_snapshot(bpy.context.scene.lmrefine))
        message = None
    except pipeline.UserError as error:
        message = str(error)
    return {"outcome": "CANCELLED", "message": message, "changed": changed(before, fingerprint())}


@check()
def error_linked_library():
    library_path = os.path.join(WORK_DIR, "library.blend")

    def prepare():
        floor = bpy.data.objects["Floor"]
        bpy.data.libraries.write(library_path, {floor}, fake_user=True)
        floor.name = "LocalFloor"
        with bpy.data.libraries.load(library_path, link=True) as (source, target):
            target.objects = ["Floor"]
        linked = target.objects[0]
        bpy.context.scene.collection.objects.link(linked)
        scenes.select_only(linked)

    return _error_case(prepare)


@check()
def error_image_not_found():
    return _error_case(lambda: settings(first_lightmap='IMAGE'))


@check()
def error_image_file_missing():
    def prepare():
        image = bpy.data.images.load(os.path.join(WORK_DIR, "lightmap.exr"), check_existing=False) \
            if os.path.exists(os.path.join(WORK_DIR, "lightmap.exr")) else bpy.data.images.new("Gone", 4, 4)
        image.source = 'FILE'
        image.filepath = os.path.join(WORK_DIR, "does_not_exist.exr")
        settings(first_lightmap='IMAGE', lightmap_image=image)

    return _error_case(prepare)


@check()
def error_image_wrong_size():
    def prepare():
        image = bpy.data.images.new("SmallLightmap", 16, 16, float_buffer=True)
        settings(first_lightmap='IMAGE', lightmap_image=image)

    return _error_case(prepare)


@check()
def error_uvs_outside_unit_square():
    def prepare():
        layer = bpy.data.objects["Floor"].data.uv_layers["Lightmap"]
        layer.data[0].uv = (1.5, 0.5)

    return _error_case(prepare)


@check()
def error_stacked_faces_in_the_source_map():
    def prepare():
        # UV > Reset: every face over the whole unit square, as a texture map may be.
        mesh = bpy.data.objects["Floor"].data
        corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
        layer = mesh.uv_layers["Lightmap"]
        for polygon in mesh.polygons:
            for k, loop in enumerate(polygon.loop_indices):
                layer.data[loop].uv = corners[k % 4]

    return _error_case(prepare)


@check()
def error_image_from_refined_bake():
    def prepare():
        image = bpy.data.images.new("Floor_lightmap_direct", RESOLUTION, RESOLUTION, float_buffer=True)
        image["lmrefine_object"] = "Floor"
        settings(first_lightmap='IMAGE', lightmap_image=image)

    return _error_case(prepare)


@check()
def error_no_bake_pass():
    return _error_case(lambda: settings(bake_passes=set()))


# --------------------------------------------------- skip and report, rollback

def _run_pipeline(objects):
    """validate + run_blocking on `objects`: (outcome or None, warnings, error message or None)."""
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    journal = Journal()
    try:
        targets = pipeline.validate(bpy.context, objects, options)
        outcome = pipeline.run_blocking(pipeline.run(bpy.context, targets, options, journal))
    except Exception as error:
        journal.rollback()
        return None, [], f"{type(error).__name__}: {error}"
    journal.commit()
    return outcome, outcome.warnings, None


@check("refine", "bake")
def noisy_first_map_is_named():
    """The shadow scene under a large area light. A first lightmap from Cycles at 1 sample is noisy: the
    warning says how noisy and the Samples that would bring it under lmrefine.metrics.NOISY_FIRST_MAP;
    Embree's at 16 samples a little (about 2.3%); Cycles' at 64 samples is not (about 1.6%)."""
    def under_an_area_light():
        scenes.shadow_scene()
        bpy.ops.object.light_add(type='AREA', location=(1.0, -1.0, 3.0))  # soft light: noise per sample
        bpy.context.active_object.data.size, bpy.context.active_object.data.energy = 4.0, 300.0

    facts = {}
    for key, first, samples in (("cycles_1", 'CYCLES', 1), ("cycles_64", 'CYCLES', 64), ("embree_16", 'EMBREE', 16)):
        fresh_scene(under_an_area_light, samples=samples, first_lightmap=first, backend='EMBREE',
                    bake_passes={'DIRECT'})
        outcome, warnings, error = _run_pipeline([bpy.data.objects["Floor"]])
        facts[key] = {"error": error, "warnings": warnings}
    return facts


@check("refine", "bake")
def skip_bad_objects_refines_the_others():
    """Floor with four broken objects: Floor is refined, each other one is skipped and named with its fix,
    and the skipped objects are untouched."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    floor = bpy.data.objects["Floor"]
    twin = bpy.data.objects.new("FloorTwin", floor.data)
    bpy.context.scene.collection.objects.link(twin)
    broken = [twin, scenes.bare_mesh(), scenes.flat_mesh(), scenes.nan_mesh()]
    scenes.select_only(floor, *broken)
    before = fingerprint()
    outcome, warnings, error = _run_pipeline([floor, *broken])
    after = fingerprint()
    skipped = [w for w in warnings if w.startswith("Skipped: ")]
    operator_outcome, message = refine()  # the same through the operator: it finishes
    return {"error": error, "objects": outcome and outcome.objects, "skipped": skipped, "warnings": warnings,
            "changed": changed(before, after), "operator": operator_outcome, "message": message}


@check("refine", "bake")
def faceless_objects_are_named_with_their_cause():
    """Floor with three objects that have nothing to lightmap (a guide of one edge, an emptied mesh, a quad
    a Weld collapses), each with a Lightmap map: each is skipped with its own cause."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    floor = bpy.data.objects["Floor"]
    guide = bpy.data.meshes.new("GuideMesh")
    guide.from_pydata([(0, 0, 0.2), (1, 0, 0.2)], [(0, 1)], [])
    emptied = bpy.data.meshes.new("EmptiedMesh")
    faceless = []
    for name, mesh in (("Guide", guide), ("Emptied", emptied)):
        mesh.uv_layers.new(name="Lightmap")
        faceless.append(bpy.data.objects.new(name, mesh))
        bpy.context.scene.collection.objects.link(faceless[-1])
    collapsed = scenes._mesh_object("Collapsed", [(3, 0, 0.5), (3.5, 0, 0.5), (3.5, 0.5, 0.5), (3, 0.5, 0.5)],
                                    [(0, 1, 2, 3)], [(0.1, 0.1), (0.4, 0.1), (0.4, 0.4), (0.1, 0.4)])
    collapsed.modifiers.new("Weld", 'WELD').merge_threshold = 100.0
    faceless.append(collapsed)
    scenes.select_only(floor, *faceless)
    outcome, warnings, error = _run_pipeline([floor, *faceless])
    return {"error": error, "objects": outcome and outcome.objects,
            "skipped": [w for w in warnings if w.startswith("Skipped: ")]}


@check("refine", "bake")
def copies_and_inside_out_meshes_are_named():
    """An Array modifier's copies share their UVs: the object is skipped, the message names the modifier and
    the fix. An inside-out box is refined with a warning saying why it bakes black. The floor, under a
    Subdivision Surface modifier (which moves UVs but copies none), is refined."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    import bmesh
    floor, blocker = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    floor.modifiers.new("Subdivision", 'SUBSURF')
    arrayed = bpy.data.objects.new("Arrayed", blocker.data.copy())
    arrayed.location = (-1.2, -1.2, 0.5)
    bpy.context.scene.collection.objects.link(arrayed)
    array = arrayed.modifiers.new("Row", 'ARRAY')
    array.count = 3
    mesh = bmesh.new()
    mesh.from_mesh(blocker.data)
    bmesh.ops.reverse_faces(mesh, faces=mesh.faces)
    mesh.to_mesh(blocker.data)
    mesh.free()
    scenes.select_only(floor, arrayed, blocker)
    outcome, warnings, error = _run_pipeline([floor, arrayed, blocker])
    return {"error": error, "objects": outcome and outcome.objects, "warnings": warnings,
            "arrayed_layers": [layer.name for layer in arrayed.data.uv_layers]}


@check("refine", "bake")
def modifier_folds_are_named():
    """Suzanne under a Subdivision Surface whose UV smoothing folds her Smart UV map where the bake reads
    it: the run warns, naming the modifier and its UV Smooth; with UV Smooth None, or the modifier off
    for render, there is nothing to say (bridge.modifier_folds_problem)."""
    fresh_shadow_scene(**EMBREE_DIRECT)
    monkey = scenes.smoothed_suzanne()
    scenes.select_only(monkey)
    outcome, warnings, error = _run_pipeline([monkey])
    modifier = monkey.modifiers["Subdivision"]
    depsgraph = bpy.context.evaluated_depsgraph_get()
    found = {"smoothed": bridge.modifier_folds_problem(depsgraph, monkey, "Lightmap", RESOLUTION)}
    modifier.uv_smooth = 'NONE'
    found["none"] = bridge.modifier_folds_problem(bpy.context.evaluated_depsgraph_get(), monkey, "Lightmap",
                                                  RESOLUTION)
    modifier.uv_smooth, modifier.show_render = 'PRESERVE_BOUNDARIES', False
    found["off"] = bridge.modifier_folds_problem(bpy.context.evaluated_depsgraph_get(), monkey, "Lightmap",
                                                 RESOLUTION)
    return {"error": error, "objects": outcome and outcome.objects, "warnings": warnings, **found}


@check("refine", "bake")
def tight_source_gutters_fixed_by_the_refined_map():
    """A coarse floor of one chart per face, its gutters under the padding: the route re-charts it at the
    padding, and the warning says the refined map is valid (only the source map's bake bleeds)."""
    scenes.coarse_shadow_scene()
    register()
    settings(resolution=RESOLUTION, padding=8, samples=4, first_lightmap='EMBREE', backend='EMBREE',
             bake_passes={'DIRECT'})  # its gutters: 6.4 texels
    floor = bpy.data.objects["Floor"]
    source = bridge.read_layout(floor.data, "Lightmap")
    outcome, warnings, error = _run_pipeline([floor])
    refined = bridge.read_uv_layer(floor.data, "Lightmap_refined")
    return {"error": error, "warnings": warnings,
            "source_gutter": lmrefine.check_layout(source.uvs, source.triangles, RESOLUTION)["min_gutter_texels"],
            "refined_check": lmrefine.check_layout(refined, source.triangles, RESOLUTION, padding=8)}


@check("refine", "bake")
def inside_out_member_of_a_shared_atlas_is_named():
    """Floor, Blocker and Post share one atlas; Post is inside out. The atlas is lit, so no black-map
    warning, but Post's own texels are black and the warning names it."""
    import bmesh
    fresh_scene(scenes.atlas_scene, **EMBREE_DIRECT)
    post = bpy.data.objects["Post"]
    mesh = bmesh.new()
    mesh.from_mesh(post.data)
    bmesh.ops.reverse_faces(mesh, faces=mesh.faces)
    mesh.to_mesh(post.data)
    mesh.free()
    objects = [bpy.data.objects[name] for name in ATLAS]
    outcome, warnings, error = _run_pipeline(objects)
    return {"error": error, "warnings": warnings, "atlases": outcome and outcome.atlases}


@check("refine", "bake")
def zero_area_faces_are_skipped_and_counted():
    """A mesh with one face of zero area in 3-D is refined; the face is counted in a warning."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    sliver = scenes.degenerate_mesh()
    scenes.select_only(sliver)
    outcome, warnings, error = _run_pipeline([sliver])
    return {"error": error, "objects": outcome and outcome.objects, "warnings": warnings,
            "refined": "Lightmap_refined" in sliver.data.uv_layers}


@check("refine", "bake")
def core_refusal_skips_the_object():
    """refine_uvs refusing one object's input (ValueError) skips that object; the other is refined."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    floor, box = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    original = lmrefine.refine_uvs

    def refuse_the_box(lightmap, uvs, triangles, *args, **kwargs):
        if len(triangles) == 12:
            raise ValueError("uvs: refused for the test [refine.cpp:42]")  # as the native core words it
        return original(lightmap, uvs, triangles, *args, **kwargs)

    box_before = fingerprint()["mesh:Cube"]
    lmrefine.refine_uvs = refuse_the_box
    try:
        outcome, warnings, error = _run_pipeline([floor, box])
    finally:
        lmrefine.refine_uvs = original
    return {"error": error, "objects": outcome and outcome.objects,
            "skipped": [w for w in warnings if w.startswith("Skipped: ")],
            "box_unchanged": fingerprint()["mesh:Cube"] == box_before,
            "floor_refined": "Lightmap_refined" in floor.data.uv_layers,
            # The operator's error report of a native failure, as the user reads it.
            "operator_messages": [operators._failure_message(error) for error in (
                ValueError("triangles[0] refers to UV 5 [coverage.cpp:127]"),
                RuntimeError("Embree failed [baker.cpp:231]"))]}


@check("refine", "bake")
def core_failure_late_leaves_the_scene_unchanged():
    """The second bake failing (after the refined maps were written) rolls the whole scene back,
    through the operator, and leaves no undo step behind."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    scenes.select_only(bpy.data.objects["Floor"], bpy.data.objects["Blocker"])
    original, calls = lmrefine.bake, []

    def fail_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("baker failed for the test")
        return original(*args, **kwargs)

    before = fingerprint()
    lmrefine.bake = fail_second
    try:
        outcome, message = refine()
    finally:
        lmrefine.bake = original
    return {"outcome": outcome, "message": message, "calls": len(calls), "changed": changed(before, fingerprint())}


# ----------------------------------------------------------------- bridge

@check()
def bridge_export():
    fresh_shadow_scene()
    floor = bpy.data.objects["Floor"]
    floor.location = (1.0, 2.0, 3.0)
    floor.scale = (2.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    receivers, occluders = bridge.export_scene(bpy.context, [floor], {"Floor": "Lightmap"})
    export = receivers[0]
    layout = bridge.read_layout(floor.data, "Lightmap")
    kind, sun = bridge.scene_lights(bpy.context)[0]
    hidden = bpy.data.objects["Blocker"]
    hidden.hide_render = True
    _, occluders_hidden = bridge.export_scene(bpy.context, [floor], {"Floor": "Lightmap"})
    return {
        "default_source": bridge.default_source_layer(floor.data),
        "occluders": sorted(e.name for e in occluders),
        "occluders_when_hidden": sorted(e.name for e in occluders_hidden),
        "x_range": [float(export.positions[:, 0].min()), float(export.positions[:, 0].max())],
        "y_range": [float(export.positions[:, 1].min()), float(export.positions[:, 1].max())],
        "z_range": [float(export.positions[:, 2].min()), float(export.positions[:, 2].max())],
        "normal_mean": export.normals.mean(axis=0).tolist(),
        "uvs_match_layout": bool(np.array_equal(export.uvs, bridge.read_uv_layer(floor.data, "Lightmap"))),
        "triangles_match_layout": bool(np.array_equal(export.triangles, layout.triangles)),
        "triangle_count": int(len(export.triangles)),
        "base_color": export.base_color[0].tolist(),
        "blocker_z_range": [float(occluders[0].positions[:, 2].min()), float(occluders[0].positions[:, 2].max())],
        "light_kind": kind,
        "sun": sun,
        "world": list(bridge.world_color(bpy.context.scene)),
    }


@check()
def bridge_welds_blender_layouts():
    """Blender's grid primitive stores corner UVs of one vertex that differ in the last bits."""
    fresh_shadow_scene()
    mesh = bpy.data.objects["Floor"].data
    raw = bridge.read_uv_layer(mesh, "UVMap")
    layout = bridge.read_layout(mesh, "UVMap")
    return {
        "raw_charts": int(lmrefine.find_charts(raw, layout.triangles).max() + 1),
        "raw_out_of_bounds": int(((raw < 0) | (raw > 1)).any(axis=1).sum()),
        "welded_charts": int(lmrefine.find_charts(layout.uvs, layout.triangles).max() + 1),
        "welded_max_shift": float(np.abs(layout.uvs - raw).max()),
        "welded_in_bounds": bool(((layout.uvs >= 0) & (layout.uvs <= 1)).all()),
        "raw_unchanged": bool(np.array_equal(raw, bridge.read_uv_layer(mesh, "UVMap"))),
    }


@check()
def bridge_lights():
    """Each Blender light type in the baker's terms: Blender's names and units, world-space pose."""
    scenes.reset()
    made = {}
    for kind in ('POINT', 'SPOT', 'SUN', 'AREA'):
        bpy.ops.object.light_add(type=kind, location=(1.0, 2.0, 3.0), rotation=(np.pi / 2, 0.0, 0.0))
        light = bpy.context.active_object
        light.name = kind
        made[kind] = light
    made['POINT'].data.shadow_soft_size = 0.3
    made['SPOT'].data.spot_size = 0.8
    made['SPOT'].data.spot_blend = 0.25
    made['SUN'].data.angle = 0.1
    made['AREA'].data.shape = 'RECTANGLE'
    made['AREA'].data.size, made['AREA'].data.size_y = 2.0, 0.5
    made['AREA'].scale = (3.0, 2.0, 1.0)
    made['AREA'].data.color = (1.0, 0.5, 0.25)
    dark = made['POINT'].copy()
    dark.data = made['POINT'].data.copy()
    dark.data.energy = 0.0
    dark.name = "Dark"
    bpy.context.scene.collection.objects.link(dark)
    # A square scaled unevenly and spun about its own axis: a 1.5 x 0.3 m strip.
    bpy.ops.object.light_add(type='AREA', location=(0.5, -0.5, 2.0), rotation=(0.2, 0.0, 0.9))
    strip = bpy.context.active_object
    strip.scale = (1.5, 0.3, 1.0)  # light_add's own scale= argument is not applied to lights
    strip.name = "Strip"
    strip.data.shape = 'SQUARE'
    strip.data.size = 1.0
    bpy.context.view_layer.update()
    facts = dict(bridge.light_params(made[kind]) for kind in made)
    facts["count"] = len(bridge.scene_lights(bpy.context))
    # The baker reads the strip as the rectangle Cycles makes of it: 1.5 x 0.3
    # along the object's own X and Y.
    strip_params = bridge.light_params(strip)[1]
    axes = np.array(strip.matrix_world.to_3x3().normalized())
    points = np.array([(x, y, 0.0) for x in (-0.5, 0.3, 1.2) for y in (-1.2, -0.4, 0.4)])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    values = []
    for params in (strip_params, dict(energy=10.0, shape="RECTANGLE", size=1.5, size_y=0.3, position=(0.5, -0.5, 2.0),
                                      direction=-axes[:, 2], axis_x=axes[:, 0])):
        scene = lmrefine.Scene()
        scene.add_light("area", **params)
        values.append(lmrefine.evaluate(scene, points, normals, samples=256, seed=1)[:, 0])
    facts["strip_values"] = [v.tolist() for v in values]
    return facts


@check()
def bridge_default_layers():
    mesh = bpy.data.meshes.new("Layers")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0)], [], [(0, 1, 2)])
    answers = {}
    for names in (["UVMap"], ["UVMap", "UVMap.001"], ["UVMap", "Detail", "LightmapUV"], ["A", "B", "C"],
                  ["UVMap", "UVMap.001", "UVMap.001_refined"],
                  ["UVMap", "UVMap_refined_direct", "UVMap_refined_indirect"]):
        while mesh.uv_layers:
            mesh.uv_layers.remove(mesh.uv_layers[0])
        for name in names:
            mesh.uv_layers.new(name=name)
        answers["+".join(names)] = bridge.default_source_layer(mesh)
    return answers


@check()
def bridge_image_roundtrip():
    image = bpy.data.images.new("Roundtrip", 8, 4, alpha=True, float_buffer=True)
    array = np.random.default_rng(5).random((4, 8, 4), dtype=np.float32)
    bridge.array_to_image(image, array)
    back = bridge.image_to_array(image)
    raw = np.empty(8 * 4 * 4, np.float32)
    image.pixels.foreach_get(raw)
    return {
        "roundtrip_equal": bool(np.array_equal(back, array)),
        # Blender's first pixel row is the bottom of the image: our last row.
        "bottom_row_first": bool(np.array_equal(raw.reshape(4, 8, 4)[0], array[-1])),
    }


# ------------------------------------------------------------ Cycles bake

@check()
def cycles_first_bake():
    fresh_shadow_scene()
    floor = bpy.data.objects["Floor"]
    before = fingerprint()
    engine_before = bpy.context.scene.render.engine
    with cycles_bake.render_settings(bpy.context, 4):
        image = cycles_bake.bake_object(bpy.context, floor, "Lightmap", "direct", RESOLUTION, 2)
    layout = bridge.read_layout(floor.data, "Lightmap")
    covered = lmrefine.coverage_mask(layout.uvs, layout.triangles, RESOLUTION)
    light = image[..., :3].mean(axis=2)[covered]
    # Save the bake for the 'existing image' checks and the batch tests.
    saved = bridge.new_float_image("FloorLightmap", RESOLUTION)
    bridge.array_to_image(saved, image)
    saved.filepath_raw = os.path.join(WORK_DIR, "lightmap.exr")
    saved.file_format = 'OPEN_EXR'
    saved.save()
    bpy.data.images.remove(saved)
    return {
        "shape": list(image.shape),
        "covered_texels": int(covered.sum()),
        "light_min": float(light.min()),
        "light_max": float(light.max()),
        "lit_fraction": float(np.mean(light > 0.5 * light.max())),
        "changed": changed(before, fingerprint()),
        "engine_restored": bpy.context.scene.render.engine == engine_before,
    }


# ----------------------------------------------------- end to end (needs API)

@check("refine")
def refine_defaults_match_the_library():
    """The panel's defaults are refine_uvs' own, so the add-on and the Python API agree out of the box."""
    import inspect

    fresh_shadow_scene()
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)["refine_options"]
    signature = inspect.signature(lmrefine.refine_uvs).parameters
    ours = {key: value for key, value in options.items()}
    theirs = {key: signature[key].default for key in options if key in signature}
    return {"ours": ours, "theirs": theirs,
            "missing": sorted(key for key in options if key not in signature)}


def _image_stats(name, layout_uvs, triangles):
    image = bpy.data.images.get(name)
    if image is None:
        return None
    pixels = bridge.image_to_array(image)
    covered = lmrefine.coverage_mask(layout_uvs, triangles, RESOLUTION)
    light = pixels[..., :3].mean(axis=2)[covered]
    # The gutter as lmrefine's baker fills it (each texel from the chart nearest it), whichever baker
    # baked the map: filling it again changes it by no more than the stored precision. A Cycles
    # margin averages neighbouring charts.
    refilled = lmrefine.dilate(pixels, layout_uvs, triangles, 16)
    return {"size": list(image.size), "is_float": image.is_float, "packed": image.packed_file is not None,
            "min": float(light.min()), "max": float(light.max()), "std": float(light.std()),
            "gutter_change": float(np.abs(refilled[..., :3] - pixels[..., :3]).max())}


def _end_to_end(first, backend, passes):
    fresh_shadow_scene(first_lightmap=first, backend=backend, bake_passes=passes)
    floor = bpy.data.objects["Floor"]
    mesh = floor.data
    if first == 'IMAGE':
        _hook_existing_lightmap(floor)
    layout = bridge.read_layout(mesh, "Lightmap")
    texture_uvs = bridge.read_uv_layer(mesh, "UVMap")
    source_uvs = bridge.read_uv_layer(mesh, "Lightmap")
    geometry = geometry_digest(mesh)
    before, outcome, message = _refine_as_one_undo_step()
    if outcome != "FINISHED":
        return {"outcome": outcome, "message": message}
    after = fingerprint()
    refined = bridge.read_uv_layer(mesh, "Lightmap_refined")
    check = lmrefine.check_layout(refined, layout.triangles, RESOLUTION, padding=2)
    nodes = bpy.data.materials["FloorMaterial"].node_tree.nodes
    preview = [(n.bl_idname, getattr(n, "uv_map", None)) for n in nodes if n.get("lmrefine_role")]
    result = bpy.context.scene.lmrefine.result
    facts = {
        "outcome": outcome,
        "changed": changed(before, after),
        "layers": [layer.name for layer in mesh.uv_layers],
        "active_layer": mesh.uv_layers.active.name,
        "render_layer": next(layer.name for layer in mesh.uv_layers if layer.active_render),
        "check_layout": {k: (bool(v) if isinstance(v, (bool, np.bool_)) else float(v)) for k, v in check.items()},
        "uv_max_move": float(np.abs(refined - layout.uvs).max()),
        "source_identical": bool(np.array_equal(bridge.read_uv_layer(mesh, "Lightmap"), source_uvs)),
        "texture_uvs_identical": bool(np.array_equal(bridge.read_uv_layer(mesh, "UVMap"), texture_uvs)),
        "geometry_identical": geometry_digest(mesh) == geometry,
        "images": {p.lower(): _image_stats(f"Floor_lightmap_{p.lower()}", refined, layout.triangles)
                   for p in passes},
        "preview_nodes": sorted(preview, key=str),
        "result_valid": result.valid,
        "transition_widening": result.transition_widening,
        "density_range": [result.density_min, result.density_max],
        "message": result.message,
        "timings": result.timings,
    }
    facts.update(_undo_once(before))
    return facts


def _refine_as_one_undo_step():
    """An undo step, then the operator run as a script with undo: (fingerprint before, outcome, message)."""
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        bpy.ops.ed.undo_push(message="before refine")
    before = fingerprint()
    outcome, message = refine(undo=True)
    return before, outcome, message


def _undo_once(before):
    """One Ctrl+Z after _refine_as_one_undo_step: what still differs from `before`, and whether a
    further step is left (it must not be: the run was exactly one undo step)."""
    with bpy.context.temp_override(window=bpy.context.window_manager.windows[0]):
        facts = {"can_undo": bpy.ops.ed.undo.poll()}
        bpy.ops.ed.undo()
        facts["changed_after_undo"] = changed(before, fingerprint())
        facts["can_undo_further"] = bpy.ops.ed.undo.poll()
    return facts


def _hook_existing_lightmap(floor):
    """Give the floor's material the Cycles-baked lightmap through a UV Map node set to 'Lightmap'."""
    image = bpy.data.images.load(os.path.join(WORK_DIR, "lightmap.exr"))
    tree = bpy.data.materials["FloorMaterial"].node_tree
    uv_node = tree.nodes.new("ShaderNodeUVMap")
    uv_node.uv_map = "Lightmap"
    image_node = tree.nodes.new("ShaderNodeTexImage")
    image_node.image = image
    tree.links.new(uv_node.outputs["UV"], image_node.inputs["Vector"])


@check("refine", "bake")
def end_to_end_embree():
    return _end_to_end('EMBREE', 'EMBREE', {'DIRECT', 'AO'})


@check("refine")
def end_to_end_cycles():
    return _end_to_end('CYCLES', 'CYCLES', {'DIRECT', 'AO'})


def _two_objects(backend):
    fresh_shadow_scene(first_lightmap=backend, backend=backend, bake_passes={'DIRECT'})
    floor, box = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    scenes.select_only(floor, box)
    source = {obj.name: bridge.read_layout(obj.data, "Lightmap") for obj in (floor, box)}
    outcome, message = refine()
    facts = {"outcome": outcome, "message": message}
    for obj in (floor, box):
        layout = source[obj.name]
        refined = bridge.read_uv_layer(obj.data, "Lightmap_refined")
        check = lmrefine.check_layout(refined, layout.triangles, RESOLUTION, padding=2)
        facts[obj.name] = {
            "charts": int(lmrefine.find_charts(refined, layout.triangles).max() + 1),
            "valid": bool(check["valid"]), "min_gutter_texels": float(check["min_gutter_texels"]),
            "image": _image_stats(f"{obj.name}_lightmap_direct", refined, layout.triangles),
        }
    return facts


@check("refine", "bake")
def end_to_end_two_objects():
    """Floor and box at once: each its own refined map and images; the box's six charts keep their gutters."""
    return _two_objects('EMBREE')


@check("refine")
def end_to_end_two_objects_cycles():
    """The same with Cycles: its margin averages the box's neighbouring charts; the stored images have
    the gutter lmrefine's baker fills."""
    return _two_objects('CYCLES')


@check("refine", "bake")
def second_click_bakes_the_materials_not_the_preview():
    """Refined twice with the same settings: the first run's preview (an Emission in the floor's
    material) is off while the second run bakes, so both runs bake the same light, and it is back
    (refreshed) after the run."""
    facts = {}
    for backend, passes in (('EMBREE', {'DIRECT', 'INDIRECT'}), ('CYCLES', {'DIRECT'})):
        fresh_shadow_scene(first_lightmap=backend, backend=backend, bake_passes=passes)
        runs = []
        for _ in range(2):
            outcome, message = refine()
            images = {p: np.array(bpy.data.images[f"Floor_lightmap_{p.lower()}"].pixels[:]) for p in sorted(passes)}
            nodes = bpy.data.materials["FloorMaterial"].node_tree.nodes
            runs.append({"outcome": outcome, "message": message, "images": images,
                         "preview_output_active": any(n.get("lmrefine_role") == "preview_output" and n.is_active_output
                                                      for n in nodes)})
        facts[backend] = {
            "outcomes": [run["outcome"] for run in runs], "messages": [run["message"] for run in runs],
            "means": [{p: float(image.mean()) for p, image in run["images"].items()} for run in runs],
            "max_difference": {p: float(np.abs(runs[1]["images"][p] - runs[0]["images"][p]).max())
                               for p in runs[0]["images"]},
            "preview_output_active": [run["preview_output_active"] for run in runs],
        }
    return facts


@check("refine", "bake")
def undo_after_a_second_run_brings_back_the_first_runs_lightmap():
    """A saved scene refined, then refined again with another Strength, then Ctrl+Z: the UV maps and
    the lightmap image (its pixels, and its file, read again) are the first run's."""
    fresh_shadow_scene(**EMBREE_DIRECT)
    os.makedirs(os.path.join(WORK_DIR, "undo_rerun"), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(WORK_DIR, "undo_rerun", "scene.blend"))
    floor = bpy.data.objects["Floor"]
    name = "Floor_lightmap_direct"
    first_outcome, _ = refine()
    first = np.array(bpy.data.images[name].pixels[:])
    first_uvs = bridge.read_uv_layer(floor.data, "Lightmap_refined")
    settings(strength=2.0)
    _, second_outcome, _ = _refine_as_one_undo_step()
    second = np.array(bpy.data.images[name].pixels[:])
    files = sorted(f for f in os.listdir(os.path.join(WORK_DIR, "undo_rerun")) if f.endswith(".exr"))
    with bpy.context.temp_override(window=bpy.context.window_manager.windows[0]):
        bpy.ops.ed.undo()
    image = bpy.data.images[name]
    undone = np.array(image.pixels[:])
    image.reload()  # what its file holds
    reloaded = np.array(image.pixels[:])
    preview = [n.image.name for n in bpy.data.materials["FloorMaterial"].node_tree.nodes
               if n.get("lmrefine_role") == "preview_image"]
    return {"outcomes": [first_outcome, second_outcome], "runs_differ": float(np.abs(second - first).max()),
            "undone_difference": float(np.abs(undone - first).max()),
            "reloaded_difference": float(np.abs(reloaded - first).max()),
            "uvs_difference": float(np.abs(bridge.read_uv_layer(bpy.data.objects["Floor"].data, "Lightmap_refined")
                                           - first_uvs).max()),
            "files": files, "preview_images": preview,
            "images": sorted(i.name for i in bpy.data.images if i.name.startswith("Floor_lightmap"))}


@check("refine")
def black_first_lightmap_warns():
    """No light at all: the run succeeds, says why nothing moved, and the layout is the source's."""
    fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})
    bpy.data.objects["Sun"].hide_render = True
    floor = bpy.data.objects["Floor"]
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    targets = pipeline.validate(bpy.context, [floor], options)
    outcome = pipeline.run_blocking(pipeline.run(bpy.context, targets, options, Journal()))
    refined = bridge.read_uv_layer(floor.data, "Lightmap_refined")
    return {"warnings": outcome.warnings,
            "max_move": float(np.abs(refined - targets[0].layout.uvs).max())}


@check("refine")
def modal_events():
    """The modal operator's own code (invoke's set-up, modal, Esc, the end) fed with timer and key events.

    Background Blender has no event loop, so the events are handed to modal()
    directly, and the operator's methods run on a stand-in `self` (reports are
    collected); everything else (driver, worker thread, journal, window
    manager, timer) is the real thing.
    """
    import time as clock
    from types import SimpleNamespace

    from lmrefine_blender.operators import LMREFINE_OT_refine_uvs as Operator

    facts = {}
    for mode in ("run", "escape"):
        fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})
        window = bpy.context.window_manager.windows[0]  # a fresh scene comes with a new window
        before = fingerprint()
        reports = []
        operator = SimpleNamespace(report=lambda kind, text: reports.append([sorted(kind), text]),
                                   _started=clock.perf_counter())
        for name in ("_prepare", "_begin_modal", "modal", "_status", "_end"):
            setattr(operator, name, getattr(Operator, name).__get__(operator))
        with bpy.context.temp_override(window=window):
            options, targets = operator._prepare(bpy.context)
            operator._begin_modal(bpy.context, options, targets)
            returned = {'RUNNING_MODAL'}
            events = 0
            while returned == {'RUNNING_MODAL'} and events < 10000:
                if mode == "escape" and operator._driver.label.startswith("Refining"):
                    operator.modal(bpy.context, SimpleNamespace(type='ESC', value='PRESS'))
                returned = operator.modal(bpy.context, SimpleNamespace(type='TIMER', value='NOTHING'))
                ignored = operator.modal(bpy.context, SimpleNamespace(type='LEFTMOUSE', value='PRESS'))
                assert ignored == {'RUNNING_MODAL'}
                events += 1
                clock.sleep(0.005)
        facts[mode] = {"returned": sorted(returned), "reports": reports, "changed": changed(before, fingerprint()),
                       "result_valid": bpy.context.scene.lmrefine.result.valid}
    return facts


@check("refine")
def invoke_in_background_runs_blocking():
    """INVOKE_DEFAULT (a button press) in background Blender has no event loop for the modal run."""
    fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})
    outcome, message = refine(how='INVOKE_DEFAULT')
    return {"outcome": outcome, "message": message,
            "has_layer": "Lightmap_refined" in bpy.data.objects["Floor"].data.uv_layers}


@check("refine")
def end_to_end_existing_image():
    return _end_to_end('IMAGE', 'CYCLES', {'DIRECT'})


@check("refine")
def remove_preview_restores_materials():
    """Remove Lightmap Preview takes out exactly the nodes the run added."""
    fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})
    material_before = fingerprint()["material:FloorMaterial"]
    outcome, message = refine()
    material_after_run = fingerprint()["material:FloorMaterial"]
    with bpy.context.temp_override(window=bpy.context.window_manager.windows[0]):
        removed = sorted(bpy.ops.object.lmrefine_remove_preview())
        again = sorted(bpy.ops.object.lmrefine_remove_preview())
    return {"outcome": outcome, "message": message, "removed": removed, "again": again,
            "changed_by_run": material_after_run != material_before,
            "restored": fingerprint()["material:FloorMaterial"] == material_before}


@check("refine")
def rerun_failure_restores_previous_run():
    """A second run that fails at its very last step (writing the EXRs) restores the first run's result:
    the refined map's UVs, the images' pixels and the preview nodes."""
    fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})
    first_outcome, message = refine()
    floor = bpy.data.objects["Floor"]
    settings(strength=2.0)  # a different layout and different pixels the second time
    before = fingerprint()
    refined_before = bridge.read_uv_layer(floor.data, "Lightmap_refined")
    pixels_before = bridge.image_to_array(bpy.data.images["Floor_lightmap_direct"])
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    targets = pipeline.validate(bpy.context, [floor], options)
    journal = Journal()
    unwritable = os.path.join(WORK_DIR, "lightmap.exr", "inside_a_file")  # a folder Blender cannot create
    try:
        pipeline.run_blocking(pipeline.run(bpy.context, targets, options, journal, image_dir=unwritable))
        raised = None
    except Exception as error:
        raised = type(error).__name__
        journal.rollback()
    return {
        "first_outcome": first_outcome, "message": message, "raised": raised,
        "changed": changed(before, fingerprint()),
        "refined_restored": bool(np.array_equal(bridge.read_uv_layer(floor.data, "Lightmap_refined"),
                                                refined_before)),
        "pixels_restored": bool(np.array_equal(bridge.image_to_array(bpy.data.images["Floor_lightmap_direct"]),
                                               pixels_before)),
    }


def _run_until(targets, options, journal, stop):
    """Run the job until `stop()` says so (as Esc does); the exception's name (None if it ran to the
    end), the journal rolled back after a failure."""
    try:
        pipeline.run_blocking(pipeline.run(bpy.context, targets, options, journal), should_stop=stop)
    except Exception as error:
        journal.rollback()
        return type(error).__name__
    return None


@check("refine")
def rollback_on_failure():
    """A Cycles second bake that fails after the refined layer was written leaves nothing behind."""
    fresh_shadow_scene(first_lightmap='IMAGE', backend='CYCLES', bake_passes={'DIRECT'})
    settings(lightmap_image=bpy.data.images.load(os.path.join(WORK_DIR, "lightmap.exr")))
    bpy.data.materials["FloorMaterial"].use_nodes = False  # the second bake refuses this material
    before = fingerprint()
    outcome, message = refine()
    return {"outcome": outcome, "message": message, "changed": changed(before, fingerprint())}


@check("refine")
def rollback_on_cancel():
    """Cancelled during the second bake (after the layer was written): the scene is as before."""
    fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT', 'AO'})
    mesh = bpy.data.objects["Floor"].data
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    before = fingerprint()
    targets = pipeline.validate(bpy.context, [bpy.data.objects["Floor"]], options)
    journal = Journal()
    stop = lambda: "Lightmap_refined" in mesh.uv_layers  # noqa: E731
    raised = _run_until(targets, options, journal, stop)
    return {"raised": raised, "changed": changed(before, fingerprint())}


@check("refine")
def threaded_driver_runs_and_cancels():
    """The modal operator's driver (worker thread + poll), which Esc cancels; no event loop needed."""
    import time as clock

    facts = {}
    # per_effect_cancel: Esc while the indirect map is refined, the direct map already written.
    cancel_at = {"cancel": "Refining", "per_effect_cancel": "Refining Floor (indirect)"}
    for mode in ("run", "cancel", "per_effect_cancel"):
        if mode == "per_effect_cancel":
            fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'},
                               layouts='PER_EFFECT')
        else:
            fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})
        floor = bpy.data.objects["Floor"]
        options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
        before = fingerprint()
        targets = pipeline.validate(bpy.context, [floor], options)
        journal = Journal()
        driver = pipeline.ThreadedDriver(pipeline.run(bpy.context, targets, options, journal))
        labels = []
        while True:
            state = driver.poll()
            if state is not None:
                break
            labels.append(driver.label)
            if mode in cancel_at and driver.label.startswith(cancel_at[mode]):
                facts.setdefault(f"{mode}_layers_at_cancel", [layer.name for layer in floor.data.uv_layers])
                driver.cancel()  # what Esc does, while the native refinement runs on the worker thread
            clock.sleep(0.01)
        kind, value = state
        if kind == "error":
            journal.rollback()
        facts[mode] = {"kind": kind, "value": type(value).__name__, "labels": sorted(set(labels)),
                       "has_layer": "Lightmap_refined" in floor.data.uv_layers,
                       "layers": [layer.name for layer in floor.data.uv_layers],
                       "changed": changed(before, fingerprint())}
    return facts


# --------------------------------------------------------------- progress

@check()
def progress_moves_per_map_and_stage():
    """The fractions run_blocking reports: a fake job with a baker-like call (stages restart at 0 per map,
    as lmrefine.bake's do) and a refine-like call (three stages); then a real run on two objects."""
    def staged(stages, steps=4):
        def call(progress):
            for stage in stages:
                for step in range(steps + 1):
                    progress(step / steps, stage)
            return "value"
        return call

    bake_stages = [f"baking {t} (map {m}/5)" for m in range(1, 6) for t in ("direct", "ao")]

    def job():
        yield pipeline.NativeWork("First bake", staged(bake_stages), 0.0, 0.4, parts=10)
        yield pipeline.NativeWork("Refining A", staged(["gradient map", "automaton", "pack"]), 0.4, 0.2,
                                  parts=pipeline.REFINE_STAGES)
        yield pipeline.NativeWork("Second bake", staged(bake_stages), 0.6, 0.4, parts=10)
        return "done"

    seen = []
    value = pipeline.run_blocking(job(), progress=lambda fraction, label: seen.append((fraction, label)))
    # The fraction when each map's last stage ends, per bake.
    ends = {f"{bake} {m}": max(f for f, label in seen if label.startswith(bake) and f"object {m}/5" in label)
            for bake in ("First bake", "Second bake") for m in range(1, 6)}

    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT', 'AO'})
    objects = [bpy.data.objects["Floor"], bpy.data.objects["Blocker"]]
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    targets = pipeline.validate(bpy.context, objects, options)
    real = []
    pipeline.run_blocking(pipeline.run(bpy.context, targets, options, Journal()),
                          progress=lambda fraction, label: real.append((fraction, label)))
    # A shared atlas: four objects, two maps (the atlas of three, Lonely's own).
    scenes.atlas_scene()
    settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', backend='EMBREE',
             bake_passes={'DIRECT'})
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    objects = [bpy.data.objects[name] for name in ATLAS + ("Lonely",)]
    atlas_run = []
    pipeline.run_blocking(pipeline.run(bpy.context, pipeline.validate(bpy.context, objects, options), options,
                                       Journal()), progress=lambda fraction, label: atlas_run.append((fraction, label)))
    return {"value": value, "fractions": [f for f, _ in seen], "ends": ends,
            "atlas_fractions": [f for f, _ in atlas_run], "atlas_labels": sorted({label for _, label in atlas_run}),
            "atlas_refining": {label.split(" (")[0]: [min(f for f, l in atlas_run if l.split(" (")[0] == label.split(" (")[0]),
                                                      max(f for f, l in atlas_run if l.split(" (")[0] == label.split(" (")[0])]
                               for _, label in atlas_run if label.startswith("Refining")},
            "real_fractions": [f for f, _ in real],
            "real_labels": sorted({label for _, label in real}),
            "real_at": {label: [min(f for f, l in real if l == label), max(f for f, l in real if l == label)]
                        for label in {label for _, label in real}}}


@check("refine", "bake")
def texture_map_as_source_warns():
    """A source map whose box faces overlap each other by half (a texture map's layout, though less
    than the unit square in all, which would be refused outright): the run succeeds and says the map
    looks like a texture map, with the fix; the panel counts the warning."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'}, source_layer="Tex")
    box = bpy.data.objects["Blocker"]
    layer = box.data.uv_layers.new(name="Tex")
    square = np.array([(0.0, 0.0), (0.3, 0.0), (0.3, 0.3), (0.0, 0.3)], np.float32)
    faces = [square + np.float32([0.05 + 0.1 * k, 0.3]) for k in range(len(box.data.polygons))]
    layer.data.foreach_set("uv", np.concatenate(faces).ravel())
    scenes.select_only(box)
    outcome, message = refine()
    result = bpy.context.scene.lmrefine.result
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    targets = pipeline.validate(bpy.context, [box], options)
    run = pipeline.run_blocking(pipeline.run(bpy.context, targets, options, Journal()))
    options["per_effect"] = "sqrt"  # Layouts: Per Effect says it per effect
    per_effect = pipeline.run_blocking(pipeline.run(bpy.context, targets, options, Journal()))
    # The box's own lightmap map (gutters of 6 texels at 64^2, fewer at the effects' sides) at a padding of 8.
    options.update(source_layer="Lightmap", padding=8)
    targets = pipeline.validate(bpy.context, [box], options)
    tight = pipeline.run_blocking(pipeline.run(bpy.context, targets, options, Journal()))
    from lmrefine_blender.panels import warning_rows
    return {"outcome": outcome, "message": message, "warnings": run.warnings, "panel_warnings": result.warnings,
            "panel_warning_text": result.warning_text, "panel_warning_rows": warning_rows(result),
            "per_effect_warnings": per_effect.warnings, "per_effect_tight_warnings": tight.warnings}


# ---------------------------------------------------------------- preview

def _output_state(tree):
    outputs = [node for node in tree.nodes if node.type == 'OUTPUT_MATERIAL']
    return {"active_output": next((node.name for node in outputs if node.is_active_output), None),
            "targets": {node.name: node.target for node in outputs},
            "active_node": tree.nodes.active.name if tree.nodes.active is not None else None,
            "eevee": tree.get_output_node('EEVEE').name, "cycles": tree.get_output_node('CYCLES').name}


def _wiring(tree, owner):
    """What the preview of `owner` shows in this tree: the image and UV map that reach each engine's output."""
    ours = {node["lmrefine_role"]: node for node in tree.nodes
            if node.get("lmrefine_role", "").startswith("preview") and node.get("lmrefine_object") == owner}
    if not ours:
        return None

    def source(node, socket):
        links = node.inputs[socket].links
        return links[0].from_node if links else None

    emission = source(tree.get_output_node('EEVEE'), "Surface")
    image_node = source(emission, "Color") if emission is not None and emission.type == 'EMISSION' else None
    uv_node = source(image_node, "Vector") if image_node is not None else None
    return {
        "roles": sorted(ours),
        "eevee_is_ours": tree.get_output_node('EEVEE') == ours["preview_output"],
        "cycles_is_ours": tree.get_output_node('CYCLES') == ours["preview_output"],
        "chain": [emission == ours["preview_emission"], image_node == ours["preview_image"],
                  uv_node == ours["preview_uv"]] if emission is not None else None,
        "image": ours["preview_image"].image.name if ours["preview_image"].image else None,
        "uv_map": ours["preview_uv"].uv_map,
        "active_node_is_image": tree.nodes.active == ours["preview_image"],
    }


@check("refine", "bake")
def preview_wiring_toggle_and_removal():
    """The preview after a run: one material with a user output set to EEVEE (which would win over any
    'All' output), one object without a material. Then before/after, then removal."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'AO', 'DIRECT'})
    floor, box = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    tree = bpy.data.materials["FloorMaterial"].node_tree
    eevee = tree.nodes.new("ShaderNodeOutputMaterial")
    eevee.name, eevee.target = "UserEevee", 'EEVEE'
    tree.nodes["Material Output"].is_active_output = True
    tree.nodes.active = tree.nodes["Principled BSDF"]
    box.data.materials.clear()
    floor.data.uv_layers.active = floor.data.uv_layers["UVMap"]
    box.data.uv_layers.active = box.data.uv_layers["UVMap"]
    scenes.select_only(floor, box)
    before = fingerprint()
    before_outputs = _output_state(tree)
    materials_before = len(bpy.data.materials)
    box_slots = [slot.material for slot in box.material_slots]
    outcome, message = refine()
    facts = {"outcome": outcome, "message": message, "before": before_outputs, "box_slots": len(box_slots),
             "box_materials": [m is not None for m in box_slots]}
    box_material = box.material_slots[0].material if box.material_slots else None
    facts["after"] = {
        "floor": _wiring(tree, "Floor"), "floor_outputs": _output_state(tree),
        "floor_active_uv": floor.data.uv_layers.active.name,
        "floor_render_uv": next(layer.name for layer in floor.data.uv_layers if layer.active_render),
        "box_material": box_material.name if box_material else None,
        "box": _wiring(box_material.node_tree, "Blocker") if box_material else None,
        "box_active_uv": box.data.uv_layers.active.name,
        "images": sorted(image.name for image in bpy.data.images if image.get("lmrefine_object")),
    }
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        facts["show_before"] = sorted(bpy.ops.object.lmrefine_show_preview(shown='BEFORE'))
        facts["before_shown"] = {"floor": _wiring(tree, "Floor"), "floor_active_uv": floor.data.uv_layers.active.name,
                                 "box": _wiring(box_material.node_tree, "Blocker"),
                                 "box_active_uv": box.data.uv_layers.active.name}
        facts["show_after"] = sorted(bpy.ops.object.lmrefine_show_preview(shown='AFTER'))
        facts["after_again"] = {"floor": _wiring(tree, "Floor"), "floor_active_uv": floor.data.uv_layers.active.name}
        facts["removed"] = sorted(bpy.ops.object.lmrefine_remove_preview())
        facts["show_without_preview"] = sorted(bpy.ops.object.lmrefine_show_preview(shown='BEFORE'))
    facts["restored"] = {
        "outputs": _output_state(tree), "floor_active_uv": floor.data.uv_layers.active.name,
        "box_active_uv": box.data.uv_layers.active.name, "box_slots": len(box.material_slots),
        "box_materials": [slot.material is not None for slot in box.material_slots],
        "materials": len(bpy.data.materials) - materials_before,
        # Only the refined maps and the lightmap images stay: every material is as it was.
        "changed": changed(before, fingerprint()),
    }
    return facts


# -------------------------------------------------------- shared atlas

def _smallest_chart_texels(uvs, triangles):
    """The fewest texels any chart of the layout covers at RESOLUTION."""
    charts = lmrefine.find_charts(uvs, triangles)
    return min(int(lmrefine.coverage_mask(uvs, triangles[charts == c], RESOLUTION).sum())
               for c in np.unique(charts))


def _atlas_run(**values):
    """atlas_scene refined in one undoable run; facts on images, previews, layouts, then one undo."""
    scenes.atlas_scene()
    register()
    settings(**{"resolution": RESOLUTION, "padding": 2, "samples": 4, "first_lightmap": 'EMBREE',
                "backend": 'EMBREE', "bake_passes": {'DIRECT', 'AO'}, **values})
    objects = [bpy.data.objects[name] for name in ATLAS + ("Lonely",)]
    source = {obj.name: bridge.read_layout(obj.data, "Lightmap") for obj in objects}
    before, outcome, message = _refine_as_one_undo_step()
    if outcome != "FINISHED":
        return {"outcome": outcome, "message": message}
    ours = [image for image in bpy.data.images if image.get("lmrefine_object")]
    facts = {"outcome": outcome, "message": bpy.context.scene.lmrefine.result.message,
             "result_images": bpy.context.scene.lmrefine.result.images,
             "stages_stopped": bpy.context.scene.lmrefine.result.stages_stopped,
             "images": {image.name: image["lmrefine_objects"] for image in ours}, "objects": {}}
    refined = {obj.name: bridge.read_uv_layer(obj.data, "Lightmap_refined") for obj in objects}
    source = {obj.name: bridge.read_layout(obj.data, "Lightmap") for obj in objects}  # tessellated, maybe
    masks = {name: lmrefine.coverage_mask(refined[name], source[name].triangles, RESOLUTION) for name in refined}
    for obj in objects:
        name = obj.name
        wiring = _wiring(obj.material_slots[0].material.node_tree, name)
        shown = bpy.data.images.get(wiring["image"]) if wiring else None
        light = bridge.image_to_array(shown)[masks[name]][:, :3].mean(axis=1) if shown is not None else None
        facts["objects"][name] = {
            "preview_image": wiring and wiring["image"], "preview_uv": wiring and wiring["uv_map"],
            "before_image": obj.get("lmrefine_preview", {}).get("before_image"),
            "moved": float(np.abs(refined[name] - source[name].uvs).max()),
            "texels": int(masks[name].sum()),
            "smallest_chart_texels": _smallest_chart_texels(refined[name], source[name].triangles),
            "light_max": float(light.max()) if light is not None else None,
        }
    # The atlas members' refined charts: no two objects share a texel, and the joined layout is valid.
    facts["shared_texels"] = {f"{a}/{b}": int(np.count_nonzero(masks[a] & masks[b]))
                              for i, a in enumerate(ATLAS) for b in ATLAS[i + 1:]}
    uvs, triangles, _, _ = lmrefine_blender.atlas.join_layouts([(refined[n], source[n].triangles) for n in ATLAS])
    check = lmrefine.check_layout(uvs, triangles, RESOLUTION, padding=2)
    facts["joined_check"] = {"valid": bool(check["valid"]), "min_gutter_texels": float(check["min_gutter_texels"])}
    source_uvs, _, _, _ = lmrefine_blender.atlas.join_layouts([(source[n].uvs, source[n].triangles) for n in ATLAS])
    facts["joined_repacked"] = bool(not np.allclose(uvs, source_uvs))
    facts.update(_undo_once(before))
    return facts


@check("refine", "bake")
def shared_atlas_one_image_per_pass():
    """Floor, Blocker and Post share an atlas: one refinement, one image per pass they all show;
    Lonely, laid out on its own lightmap, gets its own images."""
    return _atlas_run()


@check("refine", "bake")
def shared_atlas_off_one_image_per_object():
    return _atlas_run(shared_atlas=False)


@check("refine")
def shared_atlas_cycles():
    """The same with Cycles for both bakes: each member baked on its own, merged by its charts' coverage."""
    return _atlas_run(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'})


@check("refine", "bake")
def shared_atlas_stages_and_tessellation():
    """Three stages and tessellation: each stage refines the joined layout again; tessellated members
    rejoin the atlas; one undo puts every mesh back."""
    return _atlas_run(stages=3, tessellate=True, tessellate_budget=0.5, bake_passes={'DIRECT'})


@check("refine", "bake")
def shared_atlas_from_an_existing_image():
    """First Map Image: the three members' materials sample one atlas image through 'Lightmap' (the
    'before' image of an Embree run); it drives the one refinement and stays the preview's 'before'."""
    fresh_scene(scenes.atlas_scene, **EMBREE_DIRECT)
    members = [bpy.data.objects[name] for name in ATLAS]
    scenes.select_only(*members)
    first = refine()
    atlas_image = bpy.data.images["Floor_atlas_lightmap_before"]
    for obj in members:
        tree = obj.material_slots[0].material.node_tree
        uv_node = tree.nodes.new("ShaderNodeUVMap")
        uv_node.uv_map = "Lightmap"
        image_node = tree.nodes.new("ShaderNodeTexImage")
        image_node.image = atlas_image
        tree.links.new(uv_node.outputs["UV"], image_node.inputs["Vector"])
    settings(first_lightmap='IMAGE')
    outcome, message = refine()
    return {"first": first, "outcome": outcome, "message": message,
            "images": sorted(image.name for image in bpy.data.images if image.get("lmrefine_object")),
            "before_images": {obj.name: obj["lmrefine_preview"]["before_image"] for obj in members},
            "after_images": {obj.name: obj["lmrefine_preview"]["after_image"] for obj in members},
            "moved": {obj.name: float(np.abs(bridge.read_uv_layer(obj.data, "Lightmap_refined")
                                             - bridge.read_layout(obj.data, "Lightmap").uvs).max()) for obj in members},
            "result_images": bpy.context.scene.lmrefine.result.images,
            "earlier_fake_user": bpy.data.images["Floor_atlas_lightmap_direct (earlier run)"].use_fake_user}


@check("refine", "bake")
def shared_atlas_preview_removal():
    """Remove Preview on the atlas members puts back every material and active UV map; only the refined
    maps and the images stay."""
    fresh_scene(scenes.atlas_scene, **EMBREE_DIRECT)
    before = fingerprint()
    outcome, message = refine()
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        removed = sorted(bpy.ops.object.lmrefine_remove_preview())
    return {"outcome": outcome, "message": message, "removed": removed,
            "previews_left": [obj.name for obj in bpy.data.objects if obj.get("lmrefine_preview") is not None],
            "changed": changed(before, fingerprint())}


@check("refine", "bake")
def shared_atlas_grouping_ignores_selection_order():
    """The same groups and names whichever order the objects come in (validate's order is Blender's)."""
    from lmrefine_blender import atlas
    scenes.atlas_scene()
    register()
    settings(resolution=RESOLUTION)
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    orders = (ATLAS + ("Lonely",), ("Lonely", "Post", "Floor", "Blocker"))
    found = []
    for order in orders:
        targets = pipeline.validate(bpy.context, [bpy.data.objects[name] for name in order], options)
        found.append([(group.name, group.objects) for group in atlas.group_targets(targets, RESOLUTION)])
    return {"groups": found}


# ------------------------------------------------- tessellation and stages

def _corner_arrays(mesh):
    """Per loop: position (L, 3) and every UV map and the 'Tint' colour, plus each loop's polygon."""
    positions = _array(mesh.vertices, "co", 3).reshape(-1, 3)[_array(mesh.loops, "vertex_index", 1, np.int32)]
    polygon_of = np.repeat(np.arange(len(mesh.polygons)), _array(mesh.polygons, "loop_total", 1, np.int32))
    maps = {layer.name: bridge.read_uv_layer(mesh, layer.name).astype(np.float64) for layer in mesh.uv_layers}
    maps["Tint"] = _array(mesh.color_attributes["Tint"].data, "color", 4).reshape(-1, 4).astype(np.float64)
    return positions.astype(np.float64), polygon_of, maps


def _affine_residual(positions, values, groups):
    """Largest distance of `values` from the affine map of (x, y) fitted per group (least squares)."""
    worst = 0.0
    for group in np.unique(groups):
        rows = groups == group
        basis = np.column_stack([positions[rows, :2], np.ones(rows.sum())])
        fit, *_ = np.linalg.lstsq(basis, values[rows], rcond=None)
        worst = max(worst, float(np.abs(basis @ fit - values[rows]).max()))
    return worst


@check("refine", "bake")
def tessellation_writes_the_split_into_the_mesh():
    """Tessellate on, on a coarse floor (each quad its own Lightmap chart): more vertices, within the
    budget, all on the floor; every UV map and the colour attribute interpolated (UVMap and Tint stay
    one affine function of the position over the whole floor, Lightmap one per original quad, seams
    included); then Ctrl+Z restores the original mesh exactly."""
    fresh_scene(scenes.coarse_shadow_scene, **EMBREE_DIRECT, tessellate=True)
    mesh = bpy.data.objects["Floor"].data
    before_positions, before_polygon, _ = _corner_arrays(mesh)
    vertices_before = _array(mesh.vertices, "co", 3).reshape(-1, 3)
    quad_corners = [before_positions[before_polygon == p, :2] for p in range(len(mesh.polygons))]
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        bpy.ops.ed.undo_push(message="before refine")
    # What the pipeline asked of the re-chart route, and what its model chose.
    calls, refine_uvs = [], lmrefine.refine_uvs

    def recorded(*args, **kwargs):
        result = refine_uvs(*args, **kwargs)
        info = result.report.get("rechart") or {}
        calls.append({"rechart": kwargs.get("rechart", True), "used": bool(info.get("used")),
                      "always": bool(info.get("always")), "reason": info.get("reason")})
        return result

    lmrefine.refine_uvs = recorded
    try:
        outcome, message, reports = refine_with_reports(undo=True)
    finally:
        lmrefine.refine_uvs = refine_uvs
    mesh = bpy.data.objects["Floor"].data
    positions, polygon_of, maps = _corner_arrays(mesh)
    # The original quad each loop lies in: its polygon's centroid inside that quad's square.
    centroids = np.array([positions[polygon_of == p].mean(axis=0) for p in range(len(mesh.polygons))])
    quad_of_polygon = np.array([next(q for q, corners in enumerate(quad_corners)
                                     if (corners.min(axis=0) <= c[:2]).all() and (c[:2] <= corners.max(axis=0)).all())
                                for c in centroids])
    result = bpy.context.scene.lmrefine.result
    facts = {
        "outcome": outcome, "message": message, "result_message": result.message,
        "vertices_before": len(vertices_before), "vertices_after": len(mesh.vertices),
        "panel_vertices_added": result.vertices_added, "panel_tessellated": result.tessellated,
        "panel_recharted": result.recharted, "rechart_calls": calls, "reports": reports,
        "triangles_after": sum(1 for polygon in mesh.polygons if polygon.loop_total == 3),
        "largest_height": float(np.abs(positions[:, 2]).max()),
        "uvmap_residual": _affine_residual(positions, maps["UVMap"], np.zeros(len(positions))),
        "tint_residual": _affine_residual(positions, maps["Tint"], np.zeros(len(positions))),
        "lightmap_residual": _affine_residual(positions, maps["Lightmap"], quad_of_polygon[polygon_of]),
        "refined_triangles": int(len(bridge.read_layout(mesh, "Lightmap_refined").triangles)),
        "leftover_meshes": sorted(m.name for m in bpy.data.meshes),
    }
    with bpy.context.temp_override(window=window):
        bpy.ops.ed.undo()
        facts["can_undo_further"] = bpy.ops.ed.undo.poll()
    mesh = bpy.data.objects["Floor"].data
    facts["undo_vertices"] = len(mesh.vertices)
    facts["undo_coordinates_equal"] = bool(np.array_equal(_array(mesh.vertices, "co", 3).reshape(-1, 3),
                                                          vertices_before))
    facts["undo_layers"] = [layer.name for layer in mesh.uv_layers]
    return facts


@check("refine", "bake")
def preview_in_a_shared_material():
    """Two objects with one material: each gets its preview nodes; removing one shows the other,
    removing both restores the material exactly."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    floor, box = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    material = bpy.data.materials["FloorMaterial"]
    box.data.materials[0] = material
    scenes.select_only(floor, box)
    before = fingerprint()
    outcome, message = refine()
    tree = material.node_tree
    facts = {"outcome": outcome, "message": message,
             "shown_after_run": _wiring(tree, "Blocker")["eevee_is_ours"] or _wiring(tree, "Floor")["eevee_is_ours"]}
    with bpy.context.temp_override(window=bpy.context.window_manager.windows[0]):
        scenes.select_only(box)
        bpy.ops.object.lmrefine_remove_preview()
        facts["after_one_removed"] = _wiring(tree, "Floor")
        scenes.select_only(floor)
        bpy.ops.object.lmrefine_remove_preview()
    facts["changed"] = changed(before, fingerprint())
    return facts


@check("refine", "bake")
def tessellation_rolls_back_exactly():
    """A run cancelled at the second bake, after the mesh was tessellated and the refined map written:
    the journal puts back the original mesh (same datablock name, vertices, coordinates, every digest)."""
    fresh_scene(scenes.coarse_shadow_scene, **EMBREE_DIRECT, tessellate=True, tessellate_budget=1.0)
    floor = bpy.data.objects["Floor"]
    vertices_before = _array(floor.data.vertices, "co", 3).reshape(-1, 3)
    before = fingerprint()
    meshes_before = sorted(m.name for m in bpy.data.meshes)
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    targets = pipeline.validate(bpy.context, [floor], options)
    journal = Journal()
    seen = {}

    def stop():
        if "Lightmap_refined" not in floor.data.uv_layers:
            return False
        seen.setdefault("vertices_when_stopped", len(floor.data.vertices))
        return True

    raised = _run_until(targets, options, journal, stop)
    mesh = bpy.data.objects["Floor"].data
    return {"raised": raised, "vertices_when_stopped": seen.get("vertices_when_stopped"),
            "vertices": len(mesh.vertices), "vertices_before": len(vertices_before),
            "coordinates_equal": bool(np.array_equal(_array(mesh.vertices, "co", 3).reshape(-1, 3),
                                                     vertices_before)),
            "mesh_name": mesh.name, "meshes": sorted(m.name for m in bpy.data.meshes),
            "meshes_before": meshes_before, "changed": changed(before, fingerprint())}


@check()
def tessellation_leaves_meshes_it_would_change_more():
    """A mesh shared with another object, or under modifiers: with Tessellate on the object is refined
    without splitting (its mesh untouched), and a warning says why and what would let it be split."""
    facts = {}
    for case in ("shared", "modifier"):
        scenes.coarse_shadow_scene()
        register()
        settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', tessellate=True)
        floor = bpy.data.objects["Floor"]
        if case == "shared":
            twin = bpy.data.objects.new("FloorTwin", floor.data)
            bpy.context.scene.collection.objects.link(twin)
        else:
            floor.modifiers.new("Bevel", 'BEVEL')
        before = _array(floor.data.vertices, "co", 3)
        outcome, message, reports = refine_with_reports()
        after = _array(floor.data.vertices, "co", 3)
        facts[case] = {"outcome": outcome, "message": message,
                       "mesh_unchanged": before.shape == after.shape and bool(np.array_equal(before, after)),
                       "refined": "Lightmap_refined" in floor.data.uv_layers,
                       "warnings": [text for kind, text in reports if kind == 'WARNING'],
                       "tessellated": bpy.context.scene.lmrefine.result.tessellated}
    # Two objects under the same modifier: one warning names both.
    scenes.coarse_shadow_scene()
    register()
    settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', tessellate=True)
    floor, blocker = scenes.floor_and_blocker_atlas()
    for obj in (floor, blocker):
        obj.modifiers.new("Bevel", 'BEVEL')
    outcome, warnings, error = _run_pipeline([floor, blocker])
    facts["both"] = {"error": error, "warnings": warnings,
                     "not_split": outcome and {name: report.get("not_split")
                                               for name, report in outcome.tessellation.items()}}
    return facts


@check("refine", "bake")
def stretch_across_stripes():
    """The beams' shadows are stripes across x on two tiles: the panel and the message say how many charts
    were stretched, and the refined map shows it: on the striped tiles a texel step along x covers less
    of the floor than one along y, where the source map treated both alike. The same with the chart
    stretch off and Triangle Stretch on (key "triangle")."""
    scenes.striped_scene()
    register()
    facts = {}
    for key, max_stretch, triangle_stretch in (("2.0", 2.0, 1.0), ("1.0", 1.0, 1.0), ("triangle", 1.0, 2.0)):
        settings(resolution=128, padding=2, samples=4, first_lightmap='EMBREE', backend='EMBREE',
                 bake_passes={'DIRECT'}, max_stretch=max_stretch, triangle_stretch=triangle_stretch)
        outcome, message = refine()
        result = bpy.context.scene.lmrefine.result
        obj = bpy.data.objects["Tiles"]
        layout = bridge.read_layout(obj.data, "Lightmap", obj.matrix_world)
        refined = bridge.read_uv_layer(obj.data, "Lightmap_refined")
        corners = layout.positions[layout.triangles]
        striped = (corners[:, :, 1].mean(axis=1) > 4.4) & (corners[:, :, 0].mean(axis=1) < 4.2)  # back-left tiles
        gains = {}
        for axis, direction in (("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0))):
            d = np.tile(direction, (int(striped.sum()), 1))
            triangle = np.arange(int(striped.sum()))
            before = metrics.texels_across(corners[striped], layout.uvs[layout.triangles[striped]], triangle, d,
                                           128)
            after = metrics.texels_across(corners[striped], refined[layout.triangles[striped]], triangle, d, 128)
            gains[axis] = float(np.median(after / before))
        facts[key] = {
            "outcome": outcome, "message": message, "panel_stretched": result.stretched,
            "panel_stretched_triangles": result.stretched_triangles,
            "result_message": result.message, "gains": gains,
            "valid": bool(lmrefine.check_layout(refined, layout.triangles, 128, padding=2)["valid"])}
    return facts


@check("refine", "bake")
def stages_refine_the_layout_again():
    """Stages 2 refines the stage-1 layout again from a bake with it (the layout changes by more than
    the stop rule's 5%); the panel and the report say how many stages were kept."""
    from lmrefine import metrics

    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    mesh = bpy.data.objects["Floor"].data
    triangles = bridge.read_layout(mesh, "Lightmap").triangles
    layers = {}
    facts = {}
    for stages in (1, 2):
        settings(stages=stages)
        outcome, message = refine()
        result = bpy.context.scene.lmrefine.result
        layers[stages] = bridge.read_uv_layer(mesh, "Lightmap_refined")
        facts[stages] = {"outcome": outcome, "message": message, "result_message": result.message,
                         "stages": result.stages, "stages_kept": result.stages_kept,
                         "stopped": result.stages_stopped,
                         "valid": bool(lmrefine.check_layout(layers[stages], triangles, RESOLUTION,
                                                             padding=2)["valid"])}
    facts["layout_change"] = metrics.layout_change(layers[1], layers[2], triangles)
    facts["stage_min_change"] = metrics.STAGE_MIN_CHANGE
    settings(stages=3, strength=0.0)  # nothing moves: stage 2 stops the stages, stage 1 is kept
    facts["still"] = dict(zip(("outcome", "message"), refine()))
    result = bpy.context.scene.lmrefine.result
    facts["still"].update(stages_kept=result.stages_kept, stopped=result.stages_stopped,
                          result_message=result.message)
    return facts


@check()
def limit_wording():
    """The panel's Limit row and what its names mean, from made-up results."""
    register()
    from lmrefine_blender import panels
    limits = {text: panels.limit_row(text) for text in (
        "", "max_magnification, step_cap", "flipped, overlapping, step_cap", "min_shrink, max_magnification",
        "original_gutter", "aligned_steps", "degenerate, grid, gutter, out_of_bounds", "something_new")}
    return {"limits": limits, "words": panels.limit_words("step_cap, flipped, max_magnification")}


@check()
def rechart_wording():
    """The Info line of a re-charted map for each reason, from made-up reports."""
    register()
    room = {"charts": 60, "triangles": 120, "room_fraction": 0.0, "no_room": True}
    base = {"used": True, "room": room, "angle": 20.0, "charts": 25, "edge_room": False, "predicted_error": 0.6412,
            "predicted_error_source_route": 0.8049, "source_route_bound": None, "folds": None}
    folds = {"count": 672, "length": 188.2, "smooth": 3, "energy_fraction": 0.2}
    reports = {
        "no_room": {"rechart": base},
        "always": {"rechart": dict(base, room=dict(room, no_room=False), always=True, edge_room=True)},
        "folds": {"rechart": dict(base, room=dict(room, no_room=False), folds=folds,
                                  predicted_error_source_route=None, source_route_bound=0.9)},
    }
    reports["per_effect"] = {"rechart": {"used": True}, "effects": {
        "direct": {"rechart": {"used": False}}, "indirect": reports["folds"]}}
    return {key: operators.rechart_sentence(report) for key, report in reports.items()}


@check()
def not_recharted_wording():
    """The Info line of a map Re-chart if Better tried and did not re-chart, from made-up reports."""
    register()
    room = {"charts": 60, "triangles": 120, "room_fraction": 0.0, "no_room": True}
    folds = {"count": 12, "length": 8.5, "smooth": 0, "energy_fraction": 0.31}
    refused = {"used": False, "room": room, "angle": 20.0, "folds": None, "predicted_error": 0.9712,
               "predicted_error_source_route": 0.9403,
               "reason": "the error model predicts 0.971 of the source layout's error re-charted and 0.940 refining "
                         "the source layout (re-charting needs below 0.95 and below the other)"}
    failed = dict(refused, room=dict(room, no_room=False), folds=folds, predicted_error=0.62,
                  predicted_error_source_route=0.8,
                  failed=["overlapping", "gutter"],
                  reason="the re-charted layout failed overlapping, gutter against the source layout")
    note = ["not re-charted: ..."]
    reports = {
        "refused": {"rechart": refused, "notes": note},
        "failed": {"rechart": failed, "notes": note},
        "strength_0": {"rechart": {"used": False, "room": dict(room, no_room=False), "reason": "strength is 0"},
                       "notes": ["not re-charted: strength is 0"]},
        "not_tried": {"rechart": dict(refused, reason="the source layout has room"), "notes": []},
        "recharted": {"rechart": dict(refused, used=True), "notes": note},
    }
    reports["per_effect"] = {"effects": {"direct": reports["not_tried"], "indirect": reports["failed"]}}
    return {key: operators.not_recharted_sentence(report) for key, report in reports.items()}


@check()
def few_overlaps_wording():
    """A source map with a few overlapping triangles is a lightmap layout with a flaw, one whose triangles
    overlap widely a texture map's layout (pipeline.texture_like): the warnings, from made-up checks."""
    register()
    from types import SimpleNamespace
    group = SimpleNamespace(targets=[SimpleNamespace(source="Lightmap")], triangles=np.zeros((994, 3), np.int32))
    clean = {"flipped": 0, "degenerate": 0, "overlapping": 0, "out_of_bounds": 0, "min_gutter_texels": 3.0,
             "valid": True}
    checks = {"few": dict(clean, overlapping=2, min_gutter_texels=1.62, valid=False),
              "many": dict(clean, overlapping=300, min_gutter_texels=0.0, valid=False),
              "touching": dict(clean, min_gutter_texels=0.0, valid=False)}
    # The refined map as refine_uvs leaves it: the few overlaps kept in place, the rest valid.
    refined = {"few": dict(checks["few"], min_gutter_texels=3.0), "many": clean, "touching": clean}
    found = {key: {"texture_like": pipeline.texture_like(check, len(group.triangles)),
                   "warning": pipeline.source_warning("'Floor_atlas'", group, check, 2, 256, refined[key])}
             for key, check in checks.items()}
    found["recharted"] = pipeline.source_warning("'Floor_atlas'", group, checks["few"], 2, 256, clean)
    return found


@check()
def setting_wording():
    """A message names a setting as its reader sets it: by its panel label, or (the batch) by its flag."""
    register()
    from lmrefine_blender import errors
    mesh = bpy.data.meshes.new("OnlyRefinedMesh")
    mesh.uv_layers.new(name="Lightmap_refined")
    obj = bpy.data.objects.new("OnlyRefined", mesh)
    bpy.context.scene.collection.objects.link(obj)
    by_reader = {}
    for batch in (False, True):
        errors.BATCH = batch
        try:
            pipeline._validate_object(obj, {"source_layer": None}, {}, 64, None)
        except pipeline.UserError as error:
            by_reader["batch" if batch else "panel"] = str(error)
        finally:
            errors.BATCH = False
    return by_reader


@check()
def refusal_wording():
    """Several refusals in one message: one a line, each a sentence."""
    return {"one_per_line": [pipeline.one_per_line(["'A' is hidden: show it", "'B' has no UV map."]),
                             pipeline.one_per_line(["'A' is hidden: show it"])]}


@check()
def repack_wording():
    """The repack advice for a source map that was already invalid: the Margin only where charts are too close."""
    register()
    from types import SimpleNamespace
    group = SimpleNamespace(targets=[SimpleNamespace(source="Lightmap")], triangles=np.zeros((12, 3), np.int32))
    tight = {"valid": False, "flipped": 0, "degenerate": 0, "overlapping": 0, "out_of_bounds": 0,
             "min_gutter_texels": 1.5}
    flipped = dict(tight, flipped=2, min_gutter_texels=4.0)
    return {"tight": pipeline.source_warning("'Box'", group, tight, 2, 64),
            "flipped": pipeline.source_warning("'Box'", group, flipped, 2, 64)}


@check()
def images_wording():
    """How many images a run wrote, with Layouts: One and Per Effect."""
    register()
    summary = {"images_per_pass": 2, "objects": 3, "shared_images": {}}
    return {"one": operators.images_sentence(dict(summary, effects={})),
            "per_effect": operators.images_sentence(dict(summary, effects={"direct": {}, "indirect": {}}))}


@check()
def menus_and_panel_rows():
    """The operator's menu entries (what F3 search finds) and panels that draw the same rows in every state."""
    register()
    from types import SimpleNamespace

    from lmrefine_blender import operators, panels

    class Layout:
        """A stand-in UILayout that records what a panel draws (panels draw only with a window)."""

        def __init__(self, log):
            self.log = log

        def __getattr__(self, name):  # use_property_split, enabled, ...: accepted and ignored
            return None

        def __setattr__(self, name, value):
            object.__setattr__(self, name, value)

        def _sub(self, *args, **kwargs):
            return Layout(self.log)

        column = row = box = split = _sub

        def label(self, text="", icon='NONE'):
            self.log.append(("label", text, icon))

        def prop(self, data, name, text=None, icon='NONE', **kwargs):
            self.log.append(("prop", name, icon))

        def prop_search(self, data, name, *args, **kwargs):
            self.log.append(("prop", name, 'NONE'))

        def template_ID(self, data, name, **kwargs):
            self.log.append(("prop", name, 'NONE'))

        def operator(self, idname, text=None, icon='NONE', depress=False, **kwargs):
            self.log.append(("operator", idname, icon))
            return SimpleNamespace()

        def separator(self):
            self.log.append(("separator",))

    def draw(panel):
        log = []
        panel.draw(SimpleNamespace(layout=Layout(log), split_layout=lambda: Layout(log)), bpy.context)
        return log

    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'})
    icons = set(bpy.types.UILayout.bl_rna.functions["prop"].parameters["icon"].enum_items.keys())
    states = {}
    scenes.select_only()
    shown = ("LMREFINE_PT_refine", "LMREFINE_PT_refine_bake", "LMREFINE_PT_refine_result",
             "LMREFINE_PT_refine_warnings", "LMREFINE_PT_density")
    states["nothing"] = {name: draw(getattr(panels, name)) for name in shown}
    scenes.select_only(bpy.data.objects["Floor"])
    outcome, message = refine()
    result = bpy.context.scene.lmrefine.result
    result_message = result.message
    bpy.context.scene.lmrefine.density_overlay = True  # its panel draws the same rows on and off
    states["after_run"] = {name: draw(getattr(panels, name)) for name in shown}
    bpy.context.scene.lmrefine.density_overlay = False
    result.moved = 0
    result.objects = "ArcadeNorth, ArcadeWest, Floor, LowWall, Well"  # five names
    states["nothing_moved"] = {name: draw(getattr(panels, name)) for name in
                               ("LMREFINE_PT_refine_result", "LMREFINE_PT_refine_warnings")}
    result.stages, result.stages_kept = 3, 2  # a map that stopped early: its name, then why, on rows of their own
    result.stages_stopped = "Floor_atlas: stage 3 backed off; Lonely: stage 2 moved 0.4%"
    states["staged"] = {"LMREFINE_PT_refine_result": draw(panels.LMREFINE_PT_refine_result)}
    result.stages, result.stages_kept, result.stages_stopped = 1, 1, ""
    # Back-off limits, and warnings the panel keeps after the run (seven: five shown, two counted).
    limited_by, result.limited_by = result.limited_by, "flipped, overlapping, step_cap"
    result.warnings = 7
    result.warning_text = "\n".join(["'Floor': nothing moved: strength is 0; the layout returned is the input"]
                                     + [f"Skipped: 'Box{k}' has no UV map" for k in range(6)])
    states["warned"] = {name: draw(getattr(panels, name)) for name in
                        ("LMREFINE_PT_refine_result", "LMREFINE_PT_refine_warnings")}
    result.limited_by, result.warnings, result.warning_text = limited_by, 0, ""
    settings(layouts='PER_EFFECT')
    per_effect_outcome = refine()
    per_effect_message = result.message
    states["per_effect"] = {name: draw(getattr(panels, name)) for name in
                            ("LMREFINE_PT_refine_stages", "LMREFINE_PT_refine_result")}
    settings(layouts='ONE')
    used = {entry[2] for state in states.values() for log in state.values() for entry in log if len(entry) > 2}
    menus = {}
    for menu in operators.MENUS:
        functions = getattr(getattr(bpy.types, menu).draw, "_draw_funcs", [])
        log = []
        if operators.draw_menu_entry in functions:
            operators.draw_menu_entry(SimpleNamespace(layout=Layout(log)), bpy.context)
        menus[menu] = [entry[1] for entry in log if entry[0] == "operator"]
    lmrefine_blender.unregister()
    menus_after_unregister = {menu: any(getattr(f, "__module__", "").startswith("lmrefine_blender")
                                        for f in getattr(getattr(bpy.types, menu).draw, "_draw_funcs", []))
                              for menu in operators.MENUS}
    lmrefine_blender.register()
    return {
        "outcome": outcome, "message": message,
        "rows": {state: {panel: len(log) for panel, log in logs.items()} for state, logs in states.items()},
        "labels": {state: [entry[1] for entry in logs["LMREFINE_PT_refine_result"] if entry[0] == "label"]
                   for state, logs in states.items()},
        "warning_rows": {state: [entry[1:] for entry in logs["LMREFINE_PT_refine_warnings"] if entry[0] == "label"]
                         for state, logs in states.items() if "LMREFINE_PT_refine_warnings" in logs},
        "result_message": result_message, "per_effect_message": per_effect_message,
        "operators_after_run": [entry[1] for entry in states["after_run"]["LMREFINE_PT_refine_bake"]
                                if entry[0] == "operator"],
        "icons_used": sorted(used - {'NONE'}), "icons_missing": sorted(used - icons - {'NONE'}),
        "menus": menus, "menus_after_unregister": menus_after_unregister,
        "show_operator": hasattr(bpy.ops.object, "lmrefine_show_preview"),
        "per_effect_outcome": per_effect_outcome,
        "per_effect_props": [entry[1] for entry in states["per_effect"]["LMREFINE_PT_refine_stages"]
                             if entry[0] == "prop"],
    }


# ------------------------------------------------------- per-effect layouts

EFFECTS = ("direct", "indirect")


def _terms_wiring(tree, owner):
    """What reaches the preview's Emission of `owner`: [(image, UV map of the UV node feeding it)], found by
    walking the links from the active output back (Add nodes added up, each image through its UV node)."""
    output = tree.get_output_node('EEVEE')
    emission = output.inputs["Surface"].links[0].from_node
    terms, adds = [], []

    def walk(node):
        if node.type == 'VECT_MATH':
            adds.append(node.operation)
            for socket in node.inputs[:2]:
                walk(socket.links[0].from_node)
        elif node.type == 'TEX_IMAGE':
            uv_node = node.inputs["Vector"].links[0].from_node
            terms.append([node.image.name if node.image else None, uv_node.uv_map, node.get("lmrefine_object"),
                          uv_node.get("lmrefine_object")])

    walk(emission.inputs["Color"].links[0].from_node)
    return {"output_is_ours": output.get("lmrefine_object") == owner, "emission": emission.type,
            "adds": adds, "terms": terms,
            "active_node": tree.nodes.active.name if tree.nodes.active else None}


def _per_effect_facts(objects, groups):
    facts = {"result_effects": bpy.context.scene.lmrefine.result.effects,
             "result_message": bpy.context.scene.lmrefine.result.message, "layers": {}, "images": {},
             "wiring": {}, "preview_terms": {}}
    for obj in objects:
        facts["layers"][obj.name] = [layer.name for layer in obj.data.uv_layers]
        facts["wiring"][obj.name] = _terms_wiring(obj.material_slots[0].material.node_tree, obj.name)
        facts["active_uv"] = facts.get("active_uv", {})
        facts["active_uv"][obj.name] = obj.data.uv_layers.active.name
    for image in bpy.data.images:
        if image.get("lmrefine_object"):
            facts["images"][image.name] = {"size": list(image.size), "objects": image["lmrefine_objects"],
                                           "pass": image["lmrefine_pass"]}
    # Each effect's layout, as written, against its own resolution.
    facts["checks"] = {}
    for group, members in groups.items():
        for effect in EFFECTS:
            image = bpy.data.images[f"{group}_lightmap_{effect}_effect"]
            side = image.size[0]
            layouts = [(bridge.read_uv_layer(bpy.data.objects[n].data, f"Lightmap_refined_{effect}"),
                        bridge.read_layout(bpy.data.objects[n].data, "Lightmap").triangles) for n in members]
            uvs, triangles, _, _ = lmrefine_blender.atlas.join_layouts(layouts)
            source = lmrefine_blender.atlas.join_layouts(
                [(bridge.read_layout(bpy.data.objects[n].data, "Lightmap").uvs, t) for n, (_, t) in
                 zip(members, layouts)])[0]
            check = lmrefine.check_layout(uvs, triangles, side, padding=0)
            facts["checks"][f"{group}/{effect}"] = {"side": side, "overlapping": int(check["overlapping"]),
                                                    "moved": float(np.abs(uvs - source).max())}
    return facts


@check("refine", "bake")
def per_effect_layouts_images_and_preview():
    """Layouts: Per Effect on the shadow scene (Floor and Blocker apart): one UV map and one image per
    effect at the split resolutions, the preview adding them, before/after, then Remove Preview."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT', 'AO'},
                       layouts='PER_EFFECT', shared_atlas=False)
    floor, box = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    floor.data.uv_layers.active = floor.data.uv_layers["UVMap"]
    scenes.select_only(floor, box)
    before = fingerprint()
    outcome, message = refine()
    if outcome != "FINISHED":
        return {"outcome": outcome, "message": message}
    facts = {"outcome": outcome, "message": message, **_per_effect_facts([floor, box], {"Floor": ["Floor"],
                                                                                         "Blocker": ["Blocker"]})}
    facts["preview_terms"] = {obj.name: pipeline.materials.preview_terms(obj) for obj in (floor, box)}
    tree = floor.material_slots[0].material.node_tree
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        facts["show_before"] = sorted(bpy.ops.object.lmrefine_show_preview(shown='BEFORE'))
        facts["before_wiring"] = _terms_wiring(tree, "Floor")
        facts["before_active_uv"] = floor.data.uv_layers.active.name
        facts["show_after"] = sorted(bpy.ops.object.lmrefine_show_preview(shown='AFTER'))
        facts["after_again"] = _terms_wiring(tree, "Floor")
        facts["removed"] = sorted(bpy.ops.object.lmrefine_remove_preview())
    facts["restored_active_uv"] = floor.data.uv_layers.active.name
    # Only the UV maps (mesh) and the images stay: every material is as it was.
    facts["changed"] = changed(before, fingerprint())
    return facts


@check("refine", "bake")
def per_effect_split_matches_the_rule():
    """The run's effect resolutions are lmrefine.per_effect's split of R^2 for the energies it measured."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'}, layouts='PER_EFFECT',
                       per_effect_rule='ENERGY')
    floor = bpy.data.objects["Floor"]
    scenes.select_only(floor)
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    journal = Journal()
    progress = []
    outcome = pipeline.run_blocking(pipeline.run(bpy.context, pipeline.validate(bpy.context, [floor], options),
                                                 options, journal),
                                    progress=lambda fraction, label: progress.append((fraction, label)))
    journal.commit()
    from lmrefine.per_effect import split_fractions, split_resolutions
    effects = outcome.effects["Floor"]
    energies = {name: effects[name]["report"]["energy"] for name in EFFECTS}
    return {"rule": options["per_effect"], "sides": {name: effects[name]["resolution"] for name in EFFECTS},
            "expected": split_resolutions(RESOLUTION, split_fractions("energy", energies)),
            "energies": energies, "summary_effects": outcome.summary()["effects"],
            "report_effects": sorted(outcome.reports["Floor"]["effects"]),
            "fractions": [fraction for fraction, _ in progress],
            "at": {label: [min(f for f, l in progress if l.startswith(label)),
                           max(f for f, l in progress if l.startswith(label))]
                   for label in ("First bake (effects", "First bake (direct", "First bake (indirect",
                                 "Refining Floor (direct)", "Refining Floor (indirect)", "Second bake (direct",
                                 "Second bake (indirect")},
            "image_sizes": {name: list(bpy.data.images[effects[name]["image"]].size) for name in EFFECTS}}


@check("refine", "bake")
def per_effect_is_one_undo_step():
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'}, layouts='PER_EFFECT')
    scenes.select_only(bpy.data.objects["Floor"])
    before, outcome, message = _refine_as_one_undo_step()
    facts = {"outcome": outcome, "message": message,
             "layers": [layer.name for layer in bpy.data.objects["Floor"].data.uv_layers]}
    facts.update(_undo_once(before))
    return facts


@check("refine", "bake")
def per_effect_cancel_rolls_back():
    """Cancelled in the second bake of the last effect (every per-effect map written), with Cycles: the
    scene is as before."""
    fresh_shadow_scene(first_lightmap='CYCLES', backend='CYCLES', bake_passes={'DIRECT'}, layouts='PER_EFFECT')
    mesh = bpy.data.objects["Floor"].data
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    before = fingerprint()
    targets = pipeline.validate(bpy.context, [bpy.data.objects["Floor"]], options)
    journal = Journal()
    seen = {"layers": None}

    def stop():
        if "Lightmap_refined_indirect" in mesh.uv_layers:
            seen["layers"] = [layer.name for layer in mesh.uv_layers]
            return True
        return False

    raised = _run_until(targets, options, journal, stop)
    return {"raised": raised, "layers_when_cancelled": seen["layers"], "changed": changed(before, fingerprint())}


@check("refine", "bake")
def per_effect_adds_up_to_the_combined_light():
    """At the floor's triangle centroids: the effects' images, each looked up through its own refined UV
    map, added, against a combined bake at R with the source map (and the before images likewise)."""
    from lmrefine.metrics import bilinear_lookup
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'}, layouts='PER_EFFECT')
    settings(samples=32)
    floor = bpy.data.objects["Floor"]
    scenes.select_only(floor)
    outcome, message = refine()
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    targets = pipeline.validate(bpy.context, [floor], options)
    combined = pipeline.run_blocking(pipeline._bake_embree(bpy.context, lmrefine, targets, {"Floor": "Lightmap"},
                                                           ("combined",), options, "check", 0.0, 1.0, []))
    triangles = bridge.read_layout(floor.data, "Lightmap").triangles

    def light(image_name, uv_map):
        centroids = bridge.read_uv_layer(floor.data, uv_map)[triangles].mean(axis=1)
        return bilinear_lookup(bridge.image_to_array(bpy.data.images[image_name]), centroids)[:, :3]

    truth = bilinear_lookup(combined["combined"]["Floor"], bridge.read_uv_layer(floor.data, "Lightmap")[
        triangles].mean(axis=1))[:, :3]
    after = sum(light(f"Floor_lightmap_{e}_effect", f"Lightmap_refined_{e}") for e in EFFECTS)
    before = sum(light(f"Floor_lightmap_before_{e}", "Lightmap") for e in EFFECTS)
    scale = float(truth.mean())

    def relative(values):
        return {"mean": float(values.mean() / scale - 1.0),
                "rmse": float(np.sqrt(np.mean((values - truth) ** 2)) / scale)}

    return {"outcome": outcome, "message": message, "points": len(truth), "after": relative(after),
            "before": relative(before),
            # The control: the direct image through the source map (a preview wired to the wrong map).
            "wrong_map": relative(light("Floor_lightmap_direct_effect", "Lightmap")
                                  + light("Floor_lightmap_indirect_effect", "Lightmap_refined_indirect")),
            "indirect_share": float(light("Floor_lightmap_indirect_effect", "Lightmap_refined_indirect").mean()
                                    / scale)}


@check("refine", "bake")
def per_effect_nothing_moved_warns():
    """Strength 0: neither effect's map moves, and each says so."""
    fresh_shadow_scene(first_lightmap='EMBREE', backend='EMBREE', bake_passes={'DIRECT'}, layouts='PER_EFFECT',
                       strength=0.0)
    floor = bpy.data.objects["Floor"]
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    journal = Journal()
    outcome = pipeline.run_blocking(pipeline.run(bpy.context, pipeline.validate(bpy.context, [floor], options),
                                                 options, journal))
    journal.commit()
    return {"warnings": outcome.warnings, "moved": outcome.summary()["moved"]}


@check("refine", "bake")
def per_effect_shared_atlas():
    """Per Effect on the atlas scene: one image per effect per atlas group, every member's preview adding
    its group's effect images through its own per-effect UV maps."""
    fresh_scene(scenes.atlas_scene, **EMBREE_DIRECT, layouts='PER_EFFECT')
    objects = [bpy.data.objects[name] for name in ATLAS + ("Lonely",)]
    before = fingerprint()
    outcome, message = refine()
    if outcome != "FINISHED":
        return {"outcome": outcome, "message": message}
    facts = {"outcome": outcome, **_per_effect_facts(objects, {"Floor_atlas": list(ATLAS), "Lonely": ["Lonely"]})}
    with bpy.context.temp_override(window=bpy.context.window_manager.windows[0]):
        facts["removed"] = sorted(bpy.ops.object.lmrefine_remove_preview())
    facts["changed"] = changed(before, fingerprint())
    return facts


@check("refine", "bake")
def per_effect_refuses_an_existing_image():
    """An existing lightmap holds one light, not its effects: a user error naming the fix, nothing changed."""
    fresh_shadow_scene(first_lightmap='IMAGE', layouts='PER_EFFECT')
    settings(lightmap_image=bpy.data.images.new("Given", RESOLUTION, RESOLUTION, float_buffer=True))
    before = fingerprint()
    outcome, message = refine()
    return {"outcome": outcome, "message": message, "changed": changed(before, fingerprint())}


def _save_for_batch(make_scene, filename):
    make_scene()
    register()
    path = os.path.join(WORK_DIR, filename)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    return {"path": path}


@check()
def save_coarse_scene_for_batch():
    return _save_for_batch(scenes.coarse_shadow_scene, "coarse.blend")


@check()
def save_atlas_scene_for_batch():
    return _save_for_batch(scenes.atlas_scene, "atlas.blend")


@check()
def save_scene_for_batch():
    return _save_for_batch(fresh_shadow_scene, "shadow.blend")


def _area_ratio_range(source, refined, triangles):
    ratio = metrics.uv_areas(refined, triangles) / metrics.uv_areas(source, triangles)
    return [float(ratio.min()), float(ratio.max())]


@check("refine", "bake")
def rechart_lightmap_pack_source():
    """A source map with one chart per face (Lightmap Pack's kind) gives the refiner no room: the run
    re-charts the floor from the mesh and writes a valid refined map (the source map, the geometry
    untouched; the panel and the Info line say so). With the setting off it refines the source layout."""
    facts = {}
    for rechart in (True, False):
        fresh_scene(lambda: scenes.coarse_shadow_scene(quads=8), **EMBREE_DIRECT, rechart=rechart)
        floor = bpy.data.objects["Floor"]
        mesh = floor.data
        layout = bridge.read_layout(mesh, "Lightmap")
        source_uvs = bridge.read_uv_layer(mesh, "Lightmap")
        geometry = geometry_digest(mesh)
        outcome, message, reports = refine_with_reports()
        result = bpy.context.scene.lmrefine.result
        refined = bridge.read_uv_layer(mesh, "Lightmap_refined")
        check = lmrefine.check_layout(refined, layout.triangles, RESOLUTION, padding=2)
        facts[f"rechart_{rechart}"] = {
            "outcome": outcome, "message": message, "panel_recharted": result.recharted,
            "result_message": result.message, "reports": reports,
            "valid": bool(check["valid"]), "min_gutter_texels": float(check["min_gutter_texels"]),
            "refined_charts": int(len(np.unique(lmrefine.find_charts(refined, layout.triangles,
                                                                      lmrefine.CHART_TOLERANCE)))),
            "source_charts": int(len(np.unique(lmrefine.find_charts(layout.uvs, layout.triangles,
                                                                     lmrefine.CHART_TOLERANCE)))),
            "source_identical": bool(np.array_equal(bridge.read_uv_layer(mesh, "Lightmap"), source_uvs)),
            "geometry_identical": geometry_digest(mesh) == geometry,
            "image": _image_stats("Floor_lightmap_direct", refined, layout.triangles),
            # The panel's texel figures and the same measured here: unsigned UV area, refined over source.
            "panel_density": [float(result.density_min), float(result.density_max)],
            "area_ratio": _area_ratio_range(layout.uvs, refined, layout.triangles),
        }
        if rechart:  # the progress of the refinement, re-chart route included: (fraction, stage) in order
            options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
            seen = []
            pipeline.run_blocking(pipeline.run(bpy.context, pipeline.validate(bpy.context, [floor], options),
                                               options, Journal()),
                                  progress=lambda fraction, label: seen.append((fraction, label)))
            facts["rechart_progress"] = [(f, label.split(" (", 1)[1][:-1]) for f, label in seen
                                         if label.startswith("Refining") and " (" in label]
    return facts



@check("refine", "bake")
def rechart_folded_source():
    """A source map whose one chart folds over a lit ridge (Smart UV Project's kind, with room): the run
    re-charts the roof into its two slopes (the panel and the message say so, the Info line says why) and
    the progress runs through the route's stages, never back."""
    fresh_scene(lambda: scenes.roof_scene(quads=8), **EMBREE_DIRECT)
    roof = bpy.data.objects["Roof"]
    mesh = roof.data
    layout = bridge.read_layout(mesh, "Lightmap")
    source_uvs = bridge.read_uv_layer(mesh, "Lightmap")
    outcome, message, reports = refine_with_reports()
    result = bpy.context.scene.lmrefine.result
    refined = bridge.read_uv_layer(mesh, "Lightmap_refined")
    check_ = lmrefine.check_layout(refined, layout.triangles, RESOLUTION, padding=2)
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    seen = []
    run = pipeline.run_blocking(pipeline.run(bpy.context, pipeline.validate(bpy.context, [roof], options), options,
                                             Journal()),
                                progress=lambda fraction, label: seen.append((fraction, label)))
    repack = run.reports["Roof"]["repack"] or {}
    return {"outcome": outcome, "message": message, "panel_recharted": result.recharted,
            "result_message": result.message, "reports": reports, "valid": bool(check_["valid"]),
            "fill": dict(repack.get("fill") or {}, repack_used=bool(repack.get("used"))),
            "stretch_fill": (run.reports["Roof"].get("triangle_stretch") or {}).get("fill") or {},
            "stretch_used": bool((run.reports["Roof"].get("triangle_stretch") or {}).get("used")),
            "refined_chart_ids": lmrefine.find_charts(refined, layout.triangles, lmrefine.CHART_TOLERANCE).tolist(),
            "source_charts": int(len(np.unique(lmrefine.find_charts(layout.uvs, layout.triangles,
                                                                     lmrefine.CHART_TOLERANCE)))),
            "refined_charts": int(len(np.unique(lmrefine.find_charts(refined, layout.triangles,
                                                                      lmrefine.CHART_TOLERANCE)))),
            "source_identical": bool(np.array_equal(bridge.read_uv_layer(mesh, "Lightmap"), source_uvs)),
            "progress": [(f, label.split(" (", 1)[1][:-1]) for f, label in seen
                         if label.startswith("Refining") and " (" in label]}


@check("refine", "bake")
def rechart_hilly_quads():
    """A hilly floor of quads, one chart each (Lightmap Pack's kind): the re-charted charts keep each
    quad whole (its two triangles share the diagonal's loops), so the route is not refused."""
    fresh_scene(lambda: scenes.hilly_floor_scene(quads=12), **EMBREE_DIRECT)
    floor = bpy.data.objects["Floor"]
    mesh = floor.data
    layout = bridge.read_layout(mesh, "Lightmap", floor.matrix_world)
    run, _, error = _run_pipeline([floor])
    if error:
        return {"error": error}
    refined = bridge.read_uv_layer(mesh, "Lightmap_refined")
    positions = layout.positions[layout.triangles]
    normals = np.cross(positions[:, 1] - positions[:, 0], positions[:, 2] - positions[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return {"rechart": {key: value for key, value in run.reports["Floor"]["rechart"].items()
                        if key in ("used", "reason", "charts")},
            "valid": bool(lmrefine.check_layout(refined, layout.triangles, RESOLUTION, padding=2)["valid"]),
            "largest_angle": float(np.degrees(np.arccos(np.clip(normals @ [0.0, 0.0, 1.0], -1, 1))).max()),
            "source_charts": int(len(np.unique(lmrefine.find_charts(layout.uvs, layout.triangles,
                                                                     lmrefine.CHART_TOLERANCE))))}


@check("refine", "bake")
def rechart_smooth_shaded_ridge():
    """The same folded roof shaded smooth (Shade Smooth: one normal per vertex, so the light does not
    step at the ridge): the ridge still folds, but the core is told it is smooth-shaded and credits a
    cut there with nothing; reading the split normals leaves the mesh as it was."""
    scenes.roof_scene(quads=8)
    roof = bpy.data.objects["Roof"]
    mesh = roof.data
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    mesh.update()
    register()
    settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', backend='EMBREE',
             bake_passes={'DIRECT'})
    layout = bridge.read_layout(mesh, "Lightmap", roof.matrix_world)
    ridge = np.isclose(layout.positions[:, 0], 0.0)
    outcome, message = refine()
    result = bpy.context.scene.lmrefine.result
    refined = bridge.read_uv_layer(mesh, "Lightmap_refined")
    options = pipeline.settings_snapshot(bpy.context.scene.lmrefine)
    seen = []
    run = pipeline.run_blocking(pipeline.run(bpy.context, pipeline.validate(bpy.context, [roof], options), options,
                                             Journal()),
                                progress=lambda fraction, label: seen.append(label))
    return {"outcome": outcome, "message": message, "panel_recharted": result.recharted,
            "rechart": {key: value for key, value in run.reports["Roof"]["rechart"].items() if key != "room"},
            "stages": sorted({label.split(" (", 1)[1][:-1] for label in seen
                              if label.startswith("Refining") and " (" in label}),
            "ridge_normals": np.unique(np.round(layout.normals[ridge], 5), axis=0).tolist(),
            "refined_charts": int(len(np.unique(lmrefine.find_charts(refined, layout.triangles,
                                                                      lmrefine.CHART_TOLERANCE)))),
            "valid": bool(lmrefine.check_layout(refined, layout.triangles, RESOLUTION, padding=2)["valid"]),
            "custom_normals": bool(mesh.has_custom_normals), "auto_smooth": bool(mesh.use_auto_smooth)}


@check("refine", "bake")
def rechart_shared_lightmap_pack_atlas():
    """A floor and a box whose Lightmap maps are one chart per face, packed side by side in one atlas:
    the joined layout gives no room, so the one refinement re-charts both meshes (their world positions
    joined like their UVs) into one image; the panel counts objects, not atlases."""
    scenes.coarse_shadow_scene(quads=8)
    floor, blocker = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    scenes._fit_layer(floor.data, (0.03, 0.03, 0.6, 0.97))
    scenes._fit_layer(blocker.data, (0.66, 0.4, 0.97, 0.97))
    scenes.select_only(floor, blocker)
    register()
    settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', backend='EMBREE',
             bake_passes={'DIRECT'}, rechart=True)
    source = {obj.name: (bridge.read_layout(obj.data, "Lightmap"), bridge.read_uv_layer(obj.data, "Lightmap"))
              for obj in (floor, blocker)}
    outcome, message = refine()
    result = bpy.context.scene.lmrefine.result
    refined = {name: bridge.read_uv_layer(bpy.data.objects[name].data, "Lightmap_refined") for name in source}
    masks = {name: lmrefine.coverage_mask(refined[name], source[name][0].triangles, RESOLUTION) for name in source}
    uvs, triangles, _, _ = lmrefine_blender.atlas.join_layouts(
        [(refined[name], source[name][0].triangles) for name in source])
    check = lmrefine.check_layout(uvs, triangles, RESOLUTION, padding=2)
    return {
        "outcome": outcome, "message": message, "result_message": result.message,
        "panel_recharted": result.recharted, "images": result.images,
        "valid": bool(check["valid"]), "shared_texels": int(np.count_nonzero(masks["Floor"] & masks["Blocker"])),
        "refined_charts": int(len(np.unique(lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)))),
        "source_identical": all(np.array_equal(bridge.read_uv_layer(bpy.data.objects[name].data, "Lightmap"),
                                               source[name][1]) for name in source),
    }


@check("refine", "bake")
def coarse_floor_suggests_tessellation():
    """A floor of 2 x 2 quads (about 29 x 29 texels each), its Lightmap map one chart filling the
    square, under a box's shadow: the warp can move only the middle vertex and cannot put texels
    inside those triangles, so the run says Tessellate is the fix; with Tessellate on it does not."""
    def coarse_floor(light=None, **options):
        """The 2 x 2-quad floor with one chart, the add-on registered with `options`; `light` edits
        the scene first."""
        scenes.coarse_shadow_scene(quads=2)
        floor = bpy.data.objects["Floor"]
        floor.data.uv_layers.remove(floor.data.uv_layers["Lightmap"])
        scenes._set_lightmap_layer(floor.data)
        if light:
            light()
        register()
        settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', backend='EMBREE',
                 bake_passes={'DIRECT'}, **options)
        return floor

    facts = {}
    # strength 0: nothing to tessellate for; budget 64: enough for the split to end by itself; budget 16:
    # spent, with only triangles a warp serves left to split.
    for tessellate, strength, budget in ((False, 24.0, 0.25), (True, 24.0, 0.25), (False, 0.0, 0.25),
                                         (True, 24.0, 64.0), (True, 24.0, 16.0)):
        floor = coarse_floor(tessellate=tessellate, strength=strength, tessellate_budget=budget)
        vertices = len(floor.data.vertices)
        outcome, warnings, error = _run_pipeline([floor])
        facts[f"tessellate_{tessellate}" + ("_strength_0" if strength == 0 else "")
              + (f"_budget_{budget:g}" if budget != 0.25 else "")] = {
            "error": error, "warnings": warnings, "vertices_before": vertices,
            "tessellation": outcome and outcome.tessellation.get("Floor"),
            "widening": outcome and outcome.reports["Floor"]["transition_widening"]}

    def falloff():
        """No blocker, the sun off and a point light high over a corner: a gentle falloff, no edge."""
        bpy.data.objects.remove(bpy.data.objects["Blocker"])
        bpy.data.objects["Sun"].data.energy = 0.0
        bpy.ops.object.light_add(type='POINT', location=(1.5, 1.5, 6.0))
        bpy.context.active_object.data.energy = 3000.0

    outcome, warnings, error = _run_pipeline([coarse_floor(falloff, tessellate=False)])
    facts["falloff"] = {"error": error, "warnings": warnings,
                        "report": outcome and {key: outcome.reports["Floor"][key]
                                               for key in ("transition_widening", "transition_triangle_texels")}}
    # A map too large to try the split on (the limit lowered to this floor's size): the rough figure.
    limit = pipeline.SPLIT_TRIAL_TRIANGLES
    pipeline.SPLIT_TRIAL_TRIANGLES = 1
    try:
        outcome, warnings, error = _run_pipeline([coarse_floor(tessellate=False)])
    finally:
        pipeline.SPLIT_TRIAL_TRIANGLES = limit
    facts["too_large_to_try"] = {"error": error, "warnings": warnings}
    # The floor and the box in one atlas (the floor's map in the left half, the box's on the right): the
    # advice says how many of the triangles it counts lie on the object holding the most.
    coarse_floor(tessellate=False)
    floor, blocker = scenes.floor_and_blocker_atlas()
    split_needs, needs = pipeline._split_needs, []
    pipeline._split_needs = lambda *args: needs.append(split_needs(*args)) or needs[-1]
    try:
        outcome, warnings, error = _run_pipeline([floor, blocker])
    finally:
        pipeline._split_needs = split_needs
    facts["with_the_box"] = {"error": error, "warnings": warnings, "atlases": outcome and outcome.atlases,
                             "counted": [{name: held for name, _, _, held in need} for need in needs]}
    return facts


@check("refine")
def flat_sphere_on_its_own_map_is_left_as_it_is():
    """A flat-shaded UV sphere on the UV map Blender gives it (its facets' edges on texel boundaries at
    64^2), lit by a sun: the refinement would put the facets' light steps inside texels, so the map is
    returned as it is, the warning says why, and no Tessellate advice follows."""
    scenes.reset()
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.light_add(type='SUN', rotation=(0.6, 0.3, 0.8))
    bpy.context.active_object.data.energy = 3.0
    register()
    settings(resolution=RESOLUTION, padding=2, samples=4, first_lightmap='EMBREE', backend='EMBREE',
             bake_passes={'DIRECT'})
    outcome, warnings, error = _run_pipeline([sphere])
    report = outcome.reports[sphere.name] if outcome else {}
    facts = {"error": error, "warnings": warnings, "moved": report.get("moved"),
             "aligned_steps": report.get("aligned_steps"), "limited_by": report.get("limited_by"),
             "source_map": sphere.data.uv_layers[0].name}
    # With Tessellate on, the mesh is not split for a layout that will stay as it is.
    vertices = len(sphere.data.vertices)
    settings(tessellate=True, tessellate_budget=4.0)
    outcome, warnings, error = _run_pipeline([sphere])
    facts["tessellate"] = {"error": error, "warnings": warnings, "vertices_before": vertices,
                           "vertices_after": len(sphere.data.vertices),
                           "report": outcome and outcome.tessellation.get(sphere.name)}
    return facts


with open(OUT_JSON, "w", encoding="utf-8") as stream:
    json.dump(results, stream, indent=1, default=str)
