"""Fuzz cases for the add-on's operator on broken meshes, inside ONE headless Blender.

    blender -b --factory-startup --python blender_cases.py -- REPO LOG SEED START COUNT

Each case builds a scene: the floor and box of the add-on tests, a sun, and
one to three broken objects (degenerate and duplicate faces, n-gons, loose
vertices, NaN or huge positions, missing, empty or stacked UV maps,
non-manifold edges, modifiers, instances, zero or negative scale, shared
meshes, no faces), selects some of them and runs Refine Lightmap UVs as a
script does. Before a case starts it appends {"index", "started"} to LOG, and
{"index", "outcome", "detail"} when it ends, so run.py can tell which case a
dead or stuck Blender was running. Outcomes:

    ok                  FINISHED; every user mesh and UV map as before
    refused             CANCELLED with a message for the user; scene exactly as before
    other exception     the operator failed with an unexpected error, or raised
    scene modified      a CANCELLED run changed the scene, or a FINISHED one changed
                        the user's geometry or UV maps (only *_refined maps may change)
    invalid layout      a refined map worse than its source (lmrefine.backoff.worse_than_source)
    good object not refined
                        the floor or the box was selected but not refined (a broken
                        object beside them must be skipped, not stop the run)
"""

import faulthandler
import json
import os
import sys
import traceback

REPO, LOG, SEED, START, COUNT = sys.argv[sys.argv.index("--") + 1:][:5]
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), os.path.join(REPO, "tests", "blender")]

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import lmrefine  # noqa: E402
import lmrefine_blender  # noqa: E402
import scenes  # noqa: E402
from lmrefine.backoff import worse_than_source  # noqa: E402
from scene_state import _array, _digest, changed, fingerprint  # noqa: E402

REFINED = "_refined"


# ------------------------------------------------------------- broken meshes

def _object(name, vertices, faces, edges=()):
    mesh = bpy.data.meshes.new(name + "Mesh")
    mesh.from_pydata([tuple(float(c) for c in v) for v in vertices], list(edges), [tuple(f) for f in faces])
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = (0.0, 0.0, 0.5)
    return obj


def _grid(n, size=1.0):
    vertices = [(size * j / n - size / 2, size * i / n - size / 2, 0.0) for i in range(n + 1) for j in range(n + 1)]
    faces = [(i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j)
             for i in range(n) for j in range(n)]
    return vertices, faces


def _lightmap_layer(obj, rng, kind="pack"):
    """A "Lightmap" UV map: a packed layout (one chart per face), or a broken one."""
    mesh = obj.data
    layer = mesh.uv_layers.new(name="Lightmap")
    uvs = np.zeros((len(mesh.loops), 2), np.float32)
    faces = len(mesh.polygons)
    across = int(np.ceil(np.sqrt(max(faces, 1))))
    for index, polygon in enumerate(mesh.polygons):
        cell = np.array([index % across, index // across]) / across
        count = polygon.loop_total
        angles = np.linspace(0, 2 * np.pi, count, endpoint=False) + np.pi / 4
        ring = 0.5 + 0.35 * np.column_stack([np.cos(angles), np.sin(angles)])
        uvs[polygon.loop_start:polygon.loop_start + count] = cell + ring / across
    if kind == "empty":
        uvs[:] = 0.0
    elif kind == "stacked":
        for polygon in mesh.polygons:
            count = polygon.loop_total
            angles = np.linspace(0, 2 * np.pi, count, endpoint=False)
            uvs[polygon.loop_start:polygon.loop_start + count] = 0.5 + 0.3 * np.column_stack(
                [np.cos(angles), np.sin(angles)])
    elif kind == "outside":
        uvs[0] = (1.5, -0.25)
    elif kind == "nan":
        uvs[0] = (np.nan, 0.5)
    layer.data.foreach_set("uv", uvs.ravel())
    return layer


def broken_object(name, defect, rng):
    """One object with `defect`; returns it (with a "Lightmap" UV map unless the defect removes it)."""
    n = int(rng.integers(1, 4))
    vertices, faces = _grid(n)
    uv_kind = "pack"
    if defect == "degenerate faces":
        base = len(vertices)
        vertices += [(2, 0, 0), (3, 0, 0), (4, 0, 0)]
        faces += [(base, base + 1, base + 2)]
    elif defect == "only degenerate faces":
        vertices, faces = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)], [(0, 1, 2), (1, 2, 3)]
    elif defect == "duplicate faces":
        faces += faces[: int(rng.integers(1, len(faces) + 1))]
    elif defect == "n-gons":
        angles = np.linspace(0, 2 * np.pi, int(rng.integers(5, 12)), endpoint=False)
        radius = np.where(np.arange(len(angles)) % 2, 0.3, 1.0)  # a star: concave
        base = len(vertices)
        vertices += [(1.5 + r * np.cos(a), r * np.sin(a), 0.0) for r, a in zip(radius, angles)]
        faces += [tuple(range(base, base + len(angles)))]
    elif defect == "loose vertices":
        base = len(vertices)
        vertices += [(5, 5, 5), (6, 5, 5), (7, 7, 7)]
        edges = [(base, base + 1)]
        obj = _object(name, vertices, faces, edges)
        _lightmap_layer(obj, rng)
        return obj
    elif defect in ("NaN positions", "huge positions"):
        vertices[0] = (float("nan") if defect == "NaN positions" else 1e30, 0.0, 0.0)
    elif defect == "non-manifold":
        base = len(vertices)
        vertices += [(0, 0, 1), (0, 0, -1), (0, 1, 0)]
        faces += [(0, 1, base), (0, 1, base + 1), (0, 1, base + 2)]  # three faces on one edge
    elif defect == "no faces":
        faces = []
    elif defect in ("missing UV map", "empty UV map", "stacked UVs", "UVs outside", "NaN UVs"):
        uv_kind = {"missing UV map": None, "empty UV map": "empty", "stacked UVs": "stacked",
                   "UVs outside": "outside", "NaN UVs": "nan"}[defect]
    obj = _object(name, vertices, faces)
    if uv_kind is not None:
        _lightmap_layer(obj, rng, uv_kind)
    if defect == "zero scale":
        obj.scale = ((0.0, 0.0, 0.0), (1.0, 0.0, 1.0), (1e-30, 1e-30, 1e-30))[rng.integers(3)]
    elif defect == "negative scale":
        obj.scale = (-1.0, 1.0, 1.0)
    elif defect == "huge scale":
        obj.scale = (1e30, 1e30, 1e30)
    elif defect == "modifiers":
        kind = int(rng.integers(5))
        if kind == 0:
            obj.modifiers.new("Subdivision", 'SUBSURF').levels = 1
        elif kind == 1:
            obj.modifiers.new("Array", 'ARRAY').count = int(rng.integers(1, 4))
        elif kind == 2:
            obj.modifiers.new("Solidify", 'SOLIDIFY').thickness = 0.1
        elif kind == 3:
            obj.modifiers.new("Decimate", 'DECIMATE').ratio = 0.0  # may remove every face
        else:
            displace = obj.modifiers.new("Displace", 'DISPLACE')
            displace.strength = float(rng.choice([1e30, -1e30, 2.0]))
    elif defect == "instances":
        obj.instance_type = 'VERTS'  # its vertices instance a child
        child = _object(name + "Child", [(0, 0, 0), (0.2, 0, 0), (0, 0.2, 0)], [(0, 1, 2)])
        _lightmap_layer(child, rng)
        child.parent = obj
    elif defect == "shared mesh":
        twin = bpy.data.objects.new(name + "Twin", obj.data)
        bpy.context.scene.collection.objects.link(twin)
    elif defect == "hidden":
        obj.hide_set(True)
    elif defect == "eight UV maps":
        for k in range(7):
            obj.data.uv_layers.new(name=f"Extra{k}")
    return obj


DEFECTS = ("degenerate faces", "only degenerate faces", "duplicate faces", "n-gons", "loose vertices",
           "NaN positions", "huge positions", "non-manifold", "no faces", "missing UV map", "empty UV map",
           "stacked UVs", "UVs outside", "NaN UVs", "zero scale", "negative scale", "huge scale", "modifiers",
           "instances", "shared mesh", "hidden", "eight UV maps")


# ----------------------------------------------------------------- judging

def user_state():
    """Per mesh: geometry and every UV map but the refined ones (what a run must never change)."""
    state = {}
    for mesh in bpy.data.meshes:
        layers = [(layer.name, _digest(_array(layer.data, "uv", 2))) for layer in mesh.uv_layers
                  if not layer.name.endswith(REFINED)]
        state[mesh.name] = _digest(_array(mesh.vertices, "co", 3), _array(mesh.loops, "vertex_index", 1, np.int32),
                                   _array(mesh.polygons, "loop_start", 1, np.int32), layers)
    return state


def tessellation_problems(selected, budget, vertices_before, user_before):
    """A tessellated mesh keeps its vertices (first, unmoved) and adds at most budget x their count; it is
    taken out of `user_before` so the run's other changes are still checked."""
    problems = []
    for obj in selected:
        mesh = obj.data if obj.type == 'MESH' else None
        if mesh is None or mesh.name not in vertices_before:
            continue
        old = vertices_before[mesh.name]
        new = _array(mesh.vertices, "co", 3).reshape(-1, 3)
        if len(new) == len(old):
            continue
        if len(new) > len(old) + int(np.floor(budget * len(old))) or not np.array_equal(new[:len(old)], old):
            problems.append(f"{obj.name}: {len(old)} -> {len(new)} vertices, originals kept: "
                            f"{np.array_equal(new[:len(old)], old)}")
        user_before.pop(mesh.name, None)
    return problems


def refine():
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        try:
            result = bpy.ops.object.lmrefine_refine_uvs('EXEC_DEFAULT', False)
        except RuntimeError as error:  # an ERROR report raises
            return "CANCELLED", str(error)
    return sorted(result)[0], None


def refined_layouts_valid(selected, settings):
    """Objects whose refined map is worse than its source, by the library's own rule."""
    from lmrefine_blender import bridge

    bad = []
    for obj in selected:
        mesh = obj.data
        if mesh is None or obj.type != 'MESH' or "Lightmap" + REFINED not in mesh.uv_layers:
            continue
        layout = bridge.read_layout(mesh, "Lightmap")
        refined = bridge.read_uv_layer(mesh, "Lightmap" + REFINED)
        worse, _ = worse_than_source(refined, layout.uvs, layout.triangles, settings.resolution, settings.padding)
        if worse:
            bad.append(f"{obj.name}: {worse}")
    return bad


def run_case(seed, index):
    rng = np.random.default_rng([seed, index, 7])
    scenes.shadow_scene()
    if not hasattr(bpy.types.Scene, "lmrefine"):
        lmrefine_blender.register()
    settings = bpy.context.scene.lmrefine
    settings.resolution = int(rng.choice([16, 32]))
    settings.padding = int(rng.integers(0, 4))
    settings.samples = 1
    settings.first_lightmap = 'EMBREE'
    settings.backend = 'EMBREE'
    settings.bake_passes = {'DIRECT'} if rng.random() < 0.7 else {'DIRECT', 'AO'}
    settings.preview = bool(rng.random() < 0.5)
    defects = [str(d) for d in rng.choice(DEFECTS, size=int(rng.integers(1, 4)))]
    objects = [broken_object(f"Broken{k}", defect, rng) for k, defect in enumerate(defects)]
    candidates = [bpy.data.objects["Floor"], bpy.data.objects["Blocker"]] + objects
    candidates += [o for o in bpy.data.objects if o.name.endswith("Twin")]
    selected = [o for o in candidates if rng.random() < 0.7] or objects[:1]
    scenes.select_only(*selected)
    description = f"defects {defects}; selected {[o.name for o in selected]}"
    good = [o for o in selected if o.name in ("Floor", "Blocker")]
    # The opt-in settings draw from their own stream: the cases above stay what they were.
    extra = np.random.default_rng([seed, index, 8])
    settings.stages = int(extra.choice([1, 1, 2, 3]))
    settings.tessellate = bool(extra.random() < 0.3)
    description += f"; stages {settings.stages}" + ("; tessellate" if settings.tessellate else "")
    before, user_before = fingerprint(), user_state()
    vertices_before = {mesh.name: _array(mesh.vertices, "co", 3).reshape(-1, 3) for mesh in bpy.data.meshes}
    outcome, message = refine()
    missed = [o.name for o in good if "Lightmap" + REFINED not in o.data.uv_layers]
    if missed:  # bad geometry elsewhere must not stop these
        return "good object not refined", f"{description}: {outcome} {message}; not refined: {missed}"
    if outcome == "FINISHED":
        if settings.tessellate:
            split = tessellation_problems(selected, settings.tessellate_budget, vertices_before, user_before)
            if split:
                return "scene modified", f"{description}: tessellation {split}"
        # Meshes taken out of user_before were tessellated, and checked above; a new mesh still counts.
        after = {name: digest for name, digest in user_state().items()
                 if name in user_before or name not in vertices_before}
        if after != user_before:
            return "scene modified", f"{description}: FINISHED but changed {changed(user_before, after)}"
        bad = refined_layouts_valid(selected, settings)
        if bad:
            return "invalid layout", f"{description}: {bad}"
        return "ok", description
    after = fingerprint()
    if after != before:
        return "scene modified", f"{description}: CANCELLED ({message}) but changed {changed(before, after)}"
    if message is None or "Refinement failed" in message or "Could not fully revert" in message:
        return "other exception", f"{description}: {message}"
    return "refused", f"{description}: {message}"


def main():
    seed, start, count = int(SEED), int(START), int(COUNT)
    with open(LOG, "a") as log:
        for index in range(start, start + count):
            log.write(json.dumps({"index": index, "started": True}) + "\n")
            log.flush()
            # A stuck case prints where every thread is before run.py kills Blender.
            faulthandler.dump_traceback_later(float(os.environ.get("LMREFINE_FUZZ_DUMP_AFTER", 50)), exit=False)
            try:
                outcome, detail = run_case(seed, index)
            except Exception:  # noqa: BLE001  (raised out of the operator or the case)
                outcome, detail = "other exception", traceback.format_exc(limit=8)
            faulthandler.cancel_dump_traceback_later()
            log.write(json.dumps({"index": index, "outcome": outcome, "detail": detail[:3000]}) + "\n")
            log.flush()


main()
