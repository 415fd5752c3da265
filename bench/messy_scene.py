"""A messy scene, as a .blend: the traps of real levels in one place, each
made the way a user makes it in Blender (docs/robustness.md, "A messy
scene, in a window"):

* Floor: a 12 x 12 grid whose first UV map is a texture map tiled 4x
  (outside [0, 1]) and whose second, "Lightmap", is a Lightmap Pack;
* Wall: a cube with Smart UV Project under an Array (3 copies) and a
  Bevel modifier: the copies share their UVs;
* Platform: a filled 24-gon extruded down, so it is closed and inside out
  (its normals point inward);
* Columns: three cylinders in an excluded collection, instanced by an empty
  (occluders only, hidden as objects);
* Box and Box.linked: a linked duplicate (two objects, one mesh);
* a sun.

    blender -b --factory-startup --python bench/messy_scene.py -- messy.blend
    blender -b messy.blend --python addon/lmrefine_blender/batch.py -- --objects all --resolution 256 --out out

The batch refines Floor, Box and Platform, skips Wall (its Array's copies)
and Box.linked (its shared mesh) with their fixes, says that Platform is
inside out, and lists the hidden columns as left out.
"""

import sys

import bpy


def select_all_in_edit_mode():
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')


def build(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ops = bpy.ops
    ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=10)
    floor = bpy.context.object
    floor.name = "Floor"
    mesh = floor.data
    for corner in mesh.uv_layers[0].data:  # a tiling texture map first
        corner.uv = (corner.uv[0] * 4, corner.uv[1] * 4)
    mesh.uv_layers.new(name="Lightmap")
    mesh.uv_layers.active = mesh.uv_layers["Lightmap"]
    select_all_in_edit_mode()
    ops.uv.lightmap_pack(PREF_CONTEXT='ALL_FACES')
    ops.object.mode_set(mode='OBJECT')

    ops.mesh.primitive_cube_add(size=1, location=(-2, 1, 0.75))
    wall = bpy.context.object
    wall.name = "Wall"
    wall.scale = (0.3, 1.0, 1.5)
    ops.object.transform_apply(scale=True)
    select_all_in_edit_mode()
    ops.uv.smart_project(island_margin=0.02)
    ops.object.mode_set(mode='OBJECT')
    array = wall.modifiers.new("Array", 'ARRAY')
    array.count, array.relative_offset_displace = 3, (0, 1.5, 0)
    bevel = wall.modifiers.new("Bevel", 'BEVEL')
    bevel.width, bevel.segments = 0.05, 2

    ops.mesh.primitive_circle_add(vertices=24, radius=1.2, fill_type='NGON', location=(2, -1, 0.3))
    bpy.context.object.name = "Platform"
    select_all_in_edit_mode()
    ops.mesh.extrude_region_move(TRANSFORM_OT_translate={"value": (0, 0, -0.3)})  # keeps the cap: inside out
    ops.mesh.select_all(action='SELECT')
    ops.uv.smart_project(island_margin=0.02)
    ops.object.mode_set(mode='OBJECT')

    columns = bpy.data.collections.new("Columns")
    bpy.context.scene.collection.children.link(columns)
    for index in range(3):
        ops.mesh.primitive_cylinder_add(vertices=12, radius=0.2, depth=3, location=(index, 0, 1.5))
        column = bpy.context.object
        column.name = f"Column{index}"
        for collection in column.users_collection:
            collection.objects.unlink(column)
        columns.objects.link(column)
    bpy.context.view_layer.layer_collection.children["Columns"].exclude = True
    ops.object.collection_instance_add(collection="Columns", location=(1, 2, 0))

    ops.mesh.primitive_cube_add(size=0.8, location=(3, 3, 0.4))
    box = bpy.context.object
    box.name = "Box"
    select_all_in_edit_mode()
    ops.uv.lightmap_pack(PREF_CONTEXT='ALL_FACES')
    ops.object.mode_set(mode='OBJECT')
    twin = box.copy()  # Alt+D: the same mesh
    twin.name, twin.location = "Box.linked", (-3, -3, 0.4)
    bpy.context.scene.collection.objects.link(twin)

    sun = bpy.data.lights.new("Sun", 'SUN')
    sun.angle, sun.energy = 0.02, 4.0
    sun_object = bpy.data.objects.new("Sun", sun)
    sun_object.rotation_euler = (0.7, 0.2, 0.9)
    bpy.context.scene.collection.objects.link(sun_object)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.type == 'MESH')
    bpy.context.view_layer.objects.active = floor
    bpy.ops.wm.save_as_mainfile(filepath=path)


if __name__ == "__main__":
    build(sys.argv[sys.argv.index("--") + 1])
