"""Tiny test levels for the batch tests, all made by one Blender process.

    blender -b --factory-startup --python make_levels.py -- OUT_DIR NAME[:VARIANT] ...

Each level: a subdivided floor plane and a cube on it (objects "Floor" and
"Cube"), a sun at an angle so the cube casts a hard shadow, and a second UV
map "Lightmap" (Smart UV Project). VARIANT (an integer) moves the sun, so two
levels of one name but another variant differ in content.
"""

import math
import os
import sys

import bpy


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def add_lightmap_uvs(obj):
    obj.data.uv_layers.new(name="Lightmap")  # the primitives come with "UVMap"
    obj.data.uv_layers.active = obj.data.uv_layers["Lightmap"]
    bpy.ops.object.select_all(action='DESELECT')
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.uv.smart_project(island_margin=0.1)
    bpy.ops.object.mode_set(mode='OBJECT')


def make_level(path, variant):
    clear()
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.subdivide(number_cuts=7)
    bpy.ops.object.mode_set(mode='OBJECT')
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 0.5))
    bpy.context.active_object.name = "Cube"
    for obj in (floor, bpy.data.objects["Cube"]):
        add_lightmap_uvs(obj)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    sun.data.energy = 3.0
    sun.data.angle = 0.01
    sun.rotation_euler = (math.radians(40 + 5 * variant), 0.0, math.radians(30))
    bpy.context.scene.collection.objects.link(sun)
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)


def main(argv):
    out = argv[0]
    os.makedirs(out, exist_ok=True)
    for spec in argv[1:]:
        name, _, variant = spec.partition(":")
        make_level(os.path.join(out, name + ".blend"), int(variant or 0))


main(sys.argv[sys.argv.index("--") + 1:])
