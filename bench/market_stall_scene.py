"""A market stall, as a .blend built the way a user builds one in a window:
a ground of 10 x 10 quads (8 m) under a counter (a box), an awning (a tilted
plane of 4 x 4 quads), three posts (one cylinder and an Array modifier) and a
tyre (a torus), under a low sun and a point light. Each object keeps the
UVMap Blender gives it and gets a second map, "Lightmap": UV > Lightmap Pack
on the ground, UV > Smart UV Project on the others. Made when the add-on was
tried in a window (docs/evaluation.md, "A market stall, measured once"); never
tuned on.

    blender -b --factory-startup --python bench/market_stall_scene.py -- stall.blend
    PYTHONPATH=python /usr/bin/python3 -m lmrefine evaluate stall.blend --objects NAME --view-width 0

The objects' lightmap maps each fill the UV square, so `evaluate` takes one
receiver at a time (--objects); the others occlude.
"""

import math
import sys

import bpy


def unwrap(obj, kind):
    """A "Lightmap" UV map beside the object's UVMap, unwrapped as a user would in the UV menu."""
    bpy.ops.object.select_all(action='DESELECT')
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    obj.data.uv_layers.active = obj.data.uv_layers.new(name="Lightmap")
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    if kind == "lightmap":
        bpy.ops.uv.lightmap_pack(PREF_CONTEXT='ALL_FACES', PREF_MARGIN_DIV=0.2)
    else:
        bpy.ops.uv.smart_project(island_margin=0.02)
    bpy.ops.object.mode_set(mode='OBJECT')


def added(name):
    obj = bpy.context.active_object
    obj.name = name
    return obj


def subdivided(obj, cuts):
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode='OBJECT')
    return obj


def main(path):
    bpy.ops.object.select_all(action='SELECT')
    bpy.ops.object.delete()
    bpy.ops.mesh.primitive_plane_add(size=8)
    ground = subdivided(added("Ground"), 9)
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 1.2))
    counter = added("Counter")
    counter.scale = (2.0, 0.6, 0.5)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0.3, 2.6))
    awning = subdivided(added("Awning"), 3)
    awning.scale, awning.rotation_euler = (2.6, 1.6, 1), (0.35, 0, 0)
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.06, depth=2.6, location=(-1.2, 1.0, 1.3))
    posts = added("Posts")
    array = posts.modifiers.new("Array", 'ARRAY')
    array.count, array.relative_offset_displace = 3, (20, 0, 0)
    bpy.ops.mesh.primitive_torus_add(location=(2.5, -2.0, 0.35), major_radius=0.6, minor_radius=0.25)
    tyre = added("Tyre")
    for obj, kind in ((ground, "lightmap"), (counter, "smart"), (awning, "smart"), (posts, "smart"),
                      (tyre, "smart")):
        unwrap(obj, kind)
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(55), 0, math.radians(30)))
    bpy.context.active_object.data.energy, bpy.context.active_object.data.angle = 3.0, math.radians(1)
    bpy.ops.object.light_add(type='POINT', location=(2, 2, 3))
    bpy.context.active_object.data.energy = 300
    bpy.ops.wm.save_as_mainfile(filepath=path)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1])
