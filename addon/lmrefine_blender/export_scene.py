"""Headless export of a .blend's scene into the scene .npz lmrefine's evaluation reads.

    blender -b LEVEL.blend --factory-startup --python-exit-code 1 \
        --python export_scene.py -- --out scene.npz [--objects all] [--uv-map NAME]

Run by ``python3 -m lmrefine export-scene`` (and by ``evaluate LEVEL.blend``).
The receivers are the --objects with their lightmap UV map (--uv-map, or the
add-on's automatic choice: a map named like "Lightmap", else the second map);
they are read as the add-on's bake reads them (bridge.export_scene: modifiers
applied, world space, split normals, material base colours), and every other
visible, render-enabled geometry casts shadows. Lights, the world colour and
the active camera go along. The file is lmrefine.sample_scenes' format, with
the receivers' UV map as the UV variant "own".

Exit status 0; 1 with "lmrefine: error: ..." on stderr when the scene cannot
be exported; 2 for bad flags.
"""

import argparse
import os
import sys

# Runs as a plain script (`--python`), as batch.py does: make the add-on and
# the lmrefine package importable from an installed add-on or a checkout.
_HERE = os.path.dirname(os.path.abspath(__file__))
for _path in (os.path.dirname(_HERE), os.path.join(_HERE, "..", "..", "python")):
    _path = os.path.normpath(_path)
    if os.path.isdir(_path) and _path not in sys.path:
        sys.path.insert(0, _path)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from lmrefine_blender import bridge  # noqa: E402
from lmrefine_blender.batch import object_names  # noqa: E402
from lmrefine_blender.errors import UserError  # noqa: E402
from lmrefine.scene_export import ATLAS_CHECK_RESOLUTION  # noqa: E402

UNWRAP_HINT = "Object Data > UV Maps > +, then UV > Smart UV Project or Lightmap Pack"


def build_parser():
    parser = argparse.ArgumentParser(
        prog="blender -b LEVEL.blend --python export_scene.py --",
        description="Write the scene of the open .blend as a scene .npz for `python3 -m lmrefine evaluate`.")
    parser.add_argument("--out", required=True, help="the scene .npz to write")
    parser.add_argument("--objects", default="all",
                        help="the receivers (objects that get a lightmap): 'all' (every visible mesh object with a "
                             "UV map, the default), 'selected', 'collection:NAME' or comma-separated names")
    parser.add_argument("--uv-map", help="the lightmap UV map of every receiver (default: a map named like "
                                         "'Lightmap', else the second UV map, else the only one)")
    return parser


def lightmap_uv_map(obj, uv_map):
    """The name of `obj`'s lightmap UV map, or a UserError saying what to do."""
    mesh = obj.data
    names = [layer.name for layer in mesh.uv_layers]
    if not names:
        raise UserError(f"'{obj.name}' has no UV map: give it a lightmap UV map in Blender ({UNWRAP_HINT}), "
                        "or leave it out of --objects")
    if uv_map is not None:
        if uv_map not in names:
            raise UserError(f"'{obj.name}' has no UV map '{uv_map}' (it has: {', '.join(names)}): pass --uv-map "
                            "with one of those, or leave the object out of --objects")
        return uv_map
    chosen = bridge.default_source_layer(mesh)
    if chosen is None:
        raise UserError(f"'{obj.name}' has only refined UV maps ({', '.join(names)}): pass --uv-map NAME")
    return chosen


def check_uvs(export, uv_name):
    """A lightmap layout lies inside [0, 1] and is finite (what the baker takes)."""
    uvs = export.uvs  # per face corner
    bad = int(np.count_nonzero(~np.isfinite(uvs).all(axis=1) | ((uvs < 0.0) | (uvs > 1.0)).any(axis=1)))
    if bad:
        raise UserError(f"UV map '{uv_name}' of '{export.name}' has {bad} UVs outside [0, 1] (or NaN): a lightmap "
                        "layout must lie inside the unit square; repack it in Blender (UV > Pack Islands), or "
                        "pass --uv-map with the object's lightmap UV map")


def camera_description(scene):
    """The active camera as surface_view.Camera.to_dict has it, or None
    (no camera, or one the pictures cannot use: orthographic, panoramic)."""
    camera = scene.camera
    if camera is None or camera.type != 'CAMERA':
        return None
    if camera.data.type != 'PERSP':
        print(f"lmrefine: note: camera '{camera.name}' is {camera.data.type.lower()}: the pictures use the "
              "default camera", flush=True)
        return None
    frame = camera.data.view_frame(scene=scene)  # the image plane in camera space, sensor fit and shift applied
    xs, ys = [v.x for v in frame], [v.y for v in frame]
    rotation = camera.matrix_world.to_3x3().normalized()
    return {"name": camera.name, "position": list(camera.matrix_world.translation),
            "rotation": [list(row) for row in rotation],
            "frame": [min(xs), max(xs), min(ys), max(ys), frame[0].z]}


def export(out, objects_spec, uv_map):
    from lmrefine.sample_scenes import SampleScene

    scene = bpy.context.scene
    spec = [item.strip() for item in objects_spec.split(",") if item.strip()]
    if spec == ["all"]:
        meshes = [obj for obj in scene.objects if obj.type == 'MESH']
        if not meshes:
            raise UserError(f"{bpy.data.filepath} has no mesh object, so nothing to lightmap: check that this is "
                            "the level's .blend, or make its geometry real meshes in Blender (Object > Convert > "
                            "Mesh)")
        if not any(len(obj.data.uv_layers) for obj in meshes):
            raise UserError(f"none of the {len(meshes)} mesh objects in {bpy.data.filepath} has a UV map: give the "
                            f"objects that get a lightmap a lightmap UV map in Blender ({UNWRAP_HINT})")
    names = object_names(spec, scene)  # all and collection:NAME leave out what the bake does not see
    objects = [bpy.data.objects[name] for name in names]
    not_meshes = [f"'{obj.name}' ({obj.type.lower()})" for obj in objects if obj.type != 'MESH']
    if not_meshes:
        raise UserError(f"--objects names objects that are not meshes: {', '.join(not_meshes)}")
    hidden = [obj.name for obj in objects if not bridge.renders(obj)]
    named = spec not in (["all"], ["selected"]) and not spec[0].startswith("collection:")
    if hidden and named:
        raise UserError(f"{', '.join(hidden)}: hidden or disabled for render; show them in Blender, or leave them "
                        "out of --objects")
    hidden = sorted(hidden + names.left_out)
    if hidden:
        print(f"lmrefine: note: left out (hidden or disabled for render): {', '.join(hidden)}", flush=True)
        objects = [obj for obj in objects if bridge.renders(obj)]
    if not objects:
        raise UserError(f"--objects {objects_spec}: every such object is hidden or disabled for render")
    # Nothing to lightmap (a mesh without faces, a zero scale, modifiers that remove every face): named, an
    # error; picked by all, selected or a collection, left out with a note (it casts no shadow either).
    depsgraph = bpy.context.evaluated_depsgraph_get()
    faceless = {obj.name: problem for obj in objects
                if (problem := bridge.faceless_problem(obj, obj.evaluated_get(depsgraph))) is not None}
    if faceless and named:
        raise UserError(f"{next(iter(faceless.values()))}; or leave the object out of --objects")
    for problem in faceless.values():
        print(f"lmrefine: note: left out (nothing to lightmap): {problem}", flush=True)
    objects = [obj for obj in objects if obj.name not in faceless]
    if not objects:
        raise UserError(f"--objects {objects_spec}: no such object has faces to lightmap (above)")
    lights = [{"name": obj.name, "kind": kind, **params}
              for obj, (kind, params) in bridge.scene_lights(bpy.context, named=True)]
    if not lights and not any(bridge.world_color(scene)):
        raise UserError(f"{bpy.data.filepath} has no light (no visible light with energy, black world): add a "
                        "light in Blender, there is nothing to bake")
    uv_name_of = {obj.name: lightmap_uv_map(obj, uv_map) for obj in objects}
    left_out = []
    receivers, occluders = bridge.export_scene(bpy.context, objects, uv_name_of, left_out)
    for name in left_out:
        print(f"lmrefine: note: '{name}' casts no shadow: it has vertices at NaN, Inf or beyond 1e9 units", flush=True)
    kept = []
    for export in receivers:
        uv_name = uv_name_of[export.name]
        check_uvs(export, uv_name)
        # Copies sharing their UVs, which the add-on's run skips (checked at the atlas check's resolution):
        # named, an error; picked by all, selected or a collection, an occluder only, as the run leaves it.
        obj = bpy.data.objects[export.name]
        copied = bridge.copied_faces_problem(obj, uv_name, bridge.read_layout(obj.data, uv_name), export,
                                             ATLAS_CHECK_RESOLUTION)
        if copied and named:
            raise UserError(f"{copied}; or leave the object out of --objects")
        if copied:
            print(f"lmrefine: note: left out as a receiver (it casts shadows): {copied}", flush=True)
            occluders.append(export)
            del uv_name_of[export.name]
        else:
            kept.append(export)
    receivers = kept
    if not receivers:
        raise UserError(f"--objects {objects_spec}: every such object was left out (above): fix them as the notes "
                        "say, or name other objects")

    def joined(parts, with_uvs):
        offsets = np.cumsum([0] + [len(p.positions) for p in parts])
        return {
            "positions": np.concatenate([p.positions for p in parts]) if parts else np.zeros((0, 3), np.float32),
            "triangles": (np.concatenate([p.triangles + offset for p, offset in zip(parts, offsets)])
                          if parts else np.zeros((0, 3), np.int32)).astype(np.int32),
            # Per corner (row 3t + k), as the scene file and the baker take them.
            "normals": np.concatenate([p.normals[p.triangles.ravel()] for p in parts]) if parts else None,
            "uvs": np.concatenate([p.uvs[p.triangles.ravel()] for p in parts]) if with_uvs else None,
        }

    # The face each triangle was cut from, numbered on across the receivers (refine_uvs' polygons=).
    faces = np.cumsum([0] + [int(e.polygons.max()) + 1 if len(e.polygons) else 0 for e in receivers])
    polygons = (np.concatenate([e.polygons + offset for e, offset in zip(receivers, faces)]).astype(np.int32)
                if receivers else np.zeros(0, np.int32))
    receiving = joined(receivers, with_uvs=True)
    blocking = joined(occluders, with_uvs=False)
    name = os.path.splitext(os.path.basename(bpy.data.filepath))[0] or "scene"
    sample = SampleScene(
        name=name,
        positions=receiving["positions"], triangles=receiving["triangles"], normals=receiving["normals"],
        uvs={"own": receiving["uvs"]},
        base_color=np.clip(np.concatenate([e.base_color for e in receivers]), 0.0, 1.0).astype(np.float32),
        object_id=np.concatenate([np.full(len(e.triangles), i, np.int32) for i, e in enumerate(receivers)]),
        objects=[e.name for e in receivers], lights=lights, world=bridge.world_color(scene), passes=("direct",),
        occluder_positions=blocking["positions"].astype(np.float32), occluder_triangles=blocking["triangles"],
        description=f"exported from {os.path.basename(bpy.data.filepath)}: {len(receivers)} receivers "
                    f"({', '.join(sorted(set(uv_name_of.values())))}), {len(occluders)} occluders",
        camera=camera_description(scene), uv_maps=uv_name_of, polygons=polygons)
    directory = os.path.dirname(os.path.abspath(out))
    os.makedirs(directory, exist_ok=True)
    sample.save(out)
    print(f"lmrefine: exported {len(receivers)} receivers ({len(sample.triangles)} triangles), {len(occluders)} "
          f"occluders ({len(blocking['triangles'])} triangles), {len(lights)} lights, camera: "
          f"{sample.camera['name'] if sample.camera else 'none (default view)'} -> {out}", flush=True)


def main(argv):
    args = build_parser().parse_args(argv)  # exits 2 with usage on bad flags, 0 on --help
    if not bpy.data.filepath:
        print("lmrefine: error: no .blend opened: run `blender -b LEVEL.blend --python export_scene.py -- ...`",
              file=sys.stderr, flush=True)
        return 1
    try:
        export(args.out, args.objects, args.uv_map)
    except UserError as error:
        print(f"lmrefine: error: {error}", file=sys.stderr, flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []))
