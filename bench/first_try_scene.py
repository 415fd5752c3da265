"""A user's first try, as a .blend: Blender's startup scene (its cube, point
light and camera) plus a one-quad 10 m floor, a UV sphere and a cylinder,
each with the UV map Blender gives a new primitive, under a sun. The floor
is the coarse case of docs/refiner.md, "Budgets past 16x, and the local
back-off" (Tessellate with a large Vertex Budget):

    blender -b --factory-startup --python bench/first_try_scene.py -- first_try.blend
    PYTHONPATH=python /usr/bin/python3 -m lmrefine evaluate first_try.blend --objects Plane --tessellate 300 --view-width 0

The objects' UV maps overlap one another (each fills the UV square), so
`evaluate` takes one receiver at a time (--objects); the others occlude.
"""

import sys

import bmesh
import bpy


def add(name, build, location):
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")  # calc_uvs writes into the mesh's UV layer: it must exist
    build(bm)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def main(path):
    add("Plane", lambda bm: bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=5, calc_uvs=True),
        (0, 0, -1))
    add("Sphere", lambda bm: bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=0.6, calc_uvs=True),
        (2, -2, 0))
    add("Cylinder", lambda bm: bmesh.ops.create_cone(bm, cap_ends=True, segments=32, radius1=0.2, radius2=0.2,
                                                      depth=3, calc_uvs=True), (-2, 1, 0.5))
    sun = bpy.data.lights.new("Sun", 'SUN')
    sun.angle, sun.energy = 0.01, 3.0
    sun_object = bpy.data.objects.new("Sun", sun)
    sun_object.rotation_euler = (0.6, 0.3, 0.8)
    bpy.context.scene.collection.objects.link(sun_object)
    for obj in bpy.data.objects:
        obj.select_set(obj.type == 'MESH')
    bpy.context.view_layer.objects.active = bpy.data.objects["Plane"]
    bpy.ops.wm.save_as_mainfile(filepath=path)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1])
