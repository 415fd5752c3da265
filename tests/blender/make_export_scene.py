"""A small level for the export-scene tests (tests/test_scene_export.py).

    blender -b --factory-startup --python-exit-code 1 --python make_export_scene.py -- OUT.blend [TWIN.blend [EMPTY.blend [ARRAYED.blend [FACELESS.blend]]]]

A 4 x 4 m floor of 8 x 8 quads with two UV maps: "UVMap" (a texture map
tiled 0..2, outside [0, 1]) and "Lightmap" (the floor mapped onto
[0.05, 0.95]^2); a cube floating over it without a UV map (an occluder); a
hidden mesh with a UV map; a sun; a camera looking at the floor. TWIN adds
a plane on its own UV square, EMPTY has no mesh, ARRAYED adds a rail: one
quad with a lightmap map and an Array modifier that copies it (and its
UVs) three times. FACELESS adds a guide (a mesh of one edge, with a UV
map), an emptied mesh (no vertices left, its UV maps kept) and a quad with a
lightmap map whose Weld modifier collapses it.
"""

import math
import sys

import bpy
import numpy as np

CELLS = 8

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene

xs = np.linspace(-2.0, 2.0, CELLS + 1)
vertices = [(float(x), float(y), 0.0) for y in xs for x in xs]
faces = [(j * (CELLS + 1) + i, j * (CELLS + 1) + i + 1, (j + 1) * (CELLS + 1) + i + 1, (j + 1) * (CELLS + 1) + i)
         for j in range(CELLS) for i in range(CELLS)]
mesh = bpy.data.meshes.new("Floor")
mesh.from_pydata(vertices, [], faces)
loop_vertex = np.empty(len(mesh.loops), np.int32)
mesh.loops.foreach_get("vertex_index", loop_vertex)
xy = np.array(vertices, np.float32)[loop_vertex, :2]
for name, uv in (("UVMap", (xy + 2.0) / 2.0), ("Lightmap", 0.05 + 0.9 * (xy + 2.0) / 4.0)):
    layer = mesh.uv_layers.new(name=name)
    layer.data.foreach_set("uv", np.ascontiguousarray(uv, np.float32).ravel())
floor = bpy.data.objects.new("Floor", mesh)
scene.collection.objects.link(floor)
material = bpy.data.materials.new("Grey")
material.diffuse_color = (0.6, 0.6, 0.6, 1.0)
mesh.materials.append(material)

bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 1.0))
cube = bpy.context.active_object
cube.name = "Cube"
while cube.data.uv_layers:
    cube.data.uv_layers.remove(cube.data.uv_layers[0])

bpy.ops.mesh.primitive_plane_add(size=1.0, location=(5.0, 5.0, 0.0))
hidden = bpy.context.active_object
hidden.name = "Hidden"
hidden.hide_render = True
hidden.hide_set(True)

sun_data = bpy.data.lights.new("Sun", "SUN")
sun_data.energy = 3.0
sun_data.angle = math.radians(1.0)
sun = bpy.data.objects.new("Sun", sun_data)
sun.rotation_euler = (math.radians(30), 0.0, math.radians(20))
scene.collection.objects.link(sun)

camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
camera.location = (0.0, -6.0, 4.0)
camera.rotation_euler = (math.radians(57), 0.0, 0.0)
scene.collection.objects.link(camera)
scene.camera = camera
scene.render.resolution_x, scene.render.resolution_y = 640, 400

bpy.context.preferences.filepaths.save_version = 0
paths = sys.argv[sys.argv.index("--") + 1:]
bpy.ops.wm.save_as_mainfile(filepath=paths[0])
if len(paths) > 1:
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(3.0, 0.0, 0.0))
    bpy.context.active_object.name = "Twin"
    bpy.ops.wm.save_as_mainfile(filepath=paths[1])
if len(paths) > 3:
    bpy.ops.wm.open_mainfile(filepath=paths[0])
    rail = bpy.data.meshes.new("Rail")
    rail.from_pydata([(-1.5, 1.5, 0.5), (-1.0, 1.5, 0.5), (-1.0, 1.7, 0.5), (-1.5, 1.7, 0.5)], [], [(0, 1, 2, 3)])
    for name, uv in (("UVMap", [(0, 0), (1, 0), (1, 1), (0, 1)]), ("Lightmap", [(0.1, 0.1), (0.4, 0.1), (0.4, 0.4),
                                                                              (0.1, 0.4)])):
        rail.uv_layers.new(name=name).data.foreach_set("uv", np.ascontiguousarray(uv, np.float32).ravel())
    rail_object = bpy.data.objects.new("Rail", rail)
    bpy.context.scene.collection.objects.link(rail_object)
    array = rail_object.modifiers.new("Array", "ARRAY")
    array.count, array.relative_offset_displace = 3, (1.5, 0.0, 0.0)
    bpy.ops.wm.save_as_mainfile(filepath=paths[3])
if len(paths) > 2:
    bpy.ops.wm.open_mainfile(filepath=paths[0])
    for obj in [obj for obj in bpy.data.objects if obj.type == "MESH"]:
        bpy.data.objects.remove(obj)
    bpy.ops.wm.save_as_mainfile(filepath=paths[2])
if len(paths) > 4:
    bpy.ops.wm.open_mainfile(filepath=paths[0])
    guide = bpy.data.meshes.new("Guide")
    guide.from_pydata([(-1.0, -1.0, 0.2), (1.0, -1.0, 0.2)], [(0, 1)], [])
    emptied = bpy.data.meshes.new("Emptied")
    quad = bpy.data.meshes.new("Collapsed")
    quad.from_pydata([(2.5, 0.0, 0.5), (3.0, 0.0, 0.5), (3.0, 0.5, 0.5), (2.5, 0.5, 0.5)], [], [(0, 1, 2, 3)])
    for mesh in (guide, emptied, quad):
        for name in ("UVMap", "Lightmap"):
            mesh.uv_layers.new(name=name)
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(mesh.name, mesh))
    weld = bpy.data.objects["Collapsed"].modifiers.new("Weld", "WELD")
    weld.merge_threshold = 100.0  # every vertex joins one: no face left
    bpy.ops.wm.save_as_mainfile(filepath=paths[4])
