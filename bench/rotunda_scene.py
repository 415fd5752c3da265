"""A rotunda, as a .blend built the way a user builds one in a window: a
round hall (a 48-sided cylinder wall, open at a doorway, under a half dome
with an oculus) around a floor of 16 x 16 quads, with a ring of ten columns
(cylinders duplicated and joined into one object) and a low plinth (a box).
A sun at 55 degrees shines through the oculus and the doorway; a dim point
light hangs above the plinth. The four lit objects share one atlas, as a
user unwraps them together in multi-object edit mode: a "Lightmap" map
(UV > Smart UV Project) and a "LightmapPack" map (UV > Lightmap Pack), each
beside the UVMap Blender gives. Curved walls, smooth shading on the columns
and the dome, and thin column shadows inside a sharp disc of sun: a kind of
scene the tuning scenes do not have. Never tuned on (docs/evaluation.md, "A
rotunda, measured once").

    blender -b --factory-startup --python bench/rotunda_scene.py -- rotunda.blend
    PYTHONPATH=python /usr/bin/python3 -m lmrefine evaluate rotunda.blend --view-width 0 [--uv-map LightmapPack]
"""

import math
import sys

import bmesh
import bpy

RADIUS = 6.0
HEIGHT = 5.0


def edit(obj):
    bpy.ops.object.select_all(action='DESELECT')
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')


def delete_faces(obj, keep):
    """Deletes the faces whose centre (object space) fails `keep`, as Delete > Faces does."""
    mesh = bmesh.new()
    mesh.from_mesh(obj.data)
    doomed = [face for face in mesh.faces if not keep(face.calc_center_median())]
    bmesh.ops.delete(mesh, geom=doomed, context='FACES')
    mesh.to_mesh(obj.data)
    mesh.free()


def added(name):
    obj = bpy.context.active_object
    obj.name = name
    return obj


def joined(objects, name):
    """Object > Join of `objects` into the first of them, named `name`."""
    bpy.ops.object.select_all(action='DESELECT')
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    bpy.ops.object.join()
    return added(name)


def unwrap_together(objects):
    """Both lightmap maps on every object, unwrapped in one multi-object edit: one atlas."""
    for obj in objects:
        for name in ("Lightmap", "LightmapPack"):
            obj.data.uv_layers.new(name=name)
    bpy.ops.object.select_all(action='DESELECT')
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    for name, unwrap in (("Lightmap", lambda: bpy.ops.uv.smart_project(island_margin=0.01)),
                         ("LightmapPack", lambda: bpy.ops.uv.lightmap_pack(PREF_CONTEXT='ALL_FACES',
                                                                          PREF_PACK_IN_ONE=True,
                                                                          PREF_MARGIN_DIV=0.2))):
        for obj in objects:
            obj.data.uv_layers.active = obj.data.uv_layers[name]
        bpy.ops.object.mode_set(mode='EDIT')
        bpy.ops.mesh.select_all(action='SELECT')
        unwrap()
        bpy.ops.object.mode_set(mode='OBJECT')
    for obj in objects:
        obj.data.uv_layers.active = obj.data.uv_layers["Lightmap"]


def main(path):
    bpy.ops.object.select_all(action='SELECT')
    bpy.ops.object.delete()

    bpy.ops.mesh.primitive_plane_add(size=2 * RADIUS)
    floor = added("Floor")
    edit(floor)
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.mesh.subdivide(number_cuts=15)
    bpy.ops.object.mode_set(mode='OBJECT')

    # The wall: normals inwards, a doorway two segments wide facing the sun.
    bpy.ops.mesh.primitive_cylinder_add(vertices=48, radius=RADIUS, depth=HEIGHT, end_fill_type='NOTHING',
                                        location=(0, 0, HEIGHT / 2))
    wall = added("Wall")
    edit(wall)
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.mesh.subdivide(number_cuts=3)
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode='OBJECT')
    doorway = math.radians(-120)
    delete_faces(wall, lambda c: not (math.cos(math.atan2(c.y, c.x) - doorway) > math.cos(math.radians(9))
                                      and c.z < 3.2))

    # The dome: the upper half of a UV sphere, its top rings cut away (the oculus).
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=RADIUS, location=(0, 0, HEIGHT))
    dome = added("Dome")
    delete_faces(dome, lambda c: c.z > 0.02 and math.hypot(c.x, c.y) > 1.3)
    edit(dome)
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode='OBJECT')
    bpy.ops.object.shade_smooth()

    # Ten columns, duplicated (not linked) and joined, as a user makes a ring of them.
    columns = []
    for k in range(10):
        angle = 2 * math.pi * k / 10
        bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=0.25, depth=4.2,
                                            location=(4.2 * math.cos(angle), 4.2 * math.sin(angle), 2.1))
        columns.append(bpy.context.active_object)
    colonnade = joined(columns, "Colonnade")
    bpy.ops.object.shade_smooth()

    bpy.ops.mesh.primitive_cube_add(size=1, location=(0.0, 0.0, 0.3))
    plinth = added("Plinth")
    plinth.scale = (1.4, 1.4, 0.6)
    bpy.ops.object.transform_apply(scale=True)

    unwrap_together([floor, wall, colonnade, plinth])
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(35), 0, math.radians(-30)))
    sun = bpy.context.active_object
    sun.data.energy, sun.data.angle = 4.0, math.radians(0.5)
    bpy.ops.object.light_add(type='POINT', location=(0, 0, 3.8))
    bpy.context.active_object.data.energy = 150
    bpy.ops.wm.save_as_mainfile(filepath=path)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1])
