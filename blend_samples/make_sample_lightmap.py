"""Bake the bundled sample lightmap with Cycles (run by `make sample-lightmap`).

    blender -b --factory-startup --python-exit-code 1 \
        --python blend_samples/make_sample_lightmap.py -- OUT_DIR [RESOLUTION]

Builds a small sunlit courtyard (a tessellated floor, columns, a gate with a
lintel), gives it one Lightmap Pack atlas, bakes direct + indirect diffuse
light with Cycles (colour pass off, as a lightmap) and writes:

    courtyard_lightmap.exr   float RGB(A) lightmap, row 0 at the top
    courtyard_layout.npz     uvs (T*3, 2) float32 per corner, triangles (T, 3) int32

The layout is what the gradient map needs for its coverage mask: coverage
comes from rasterizing the layout, never from the baked image's alpha.
"""

import math
import os
import sys

import bpy
import numpy as np


def argv_after_dashes():
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def add_box(name, location, scale):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = scale
    return obj


def build_courtyard():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=24, y_subdivisions=24, size=10.0)
    parts = [bpy.context.active_object]
    for i, (x, y) in enumerate([(-2.5, -2.5), (2.5, -2.5), (-2.5, 2.5), (2.5, 2.5)]):
        parts.append(add_box(f"Column{i}", (x, y, 1.25), (0.5, 0.5, 2.5)))
    parts.append(add_box("GatePostL", (-1.0, 0.0, 1.0), (0.3, 0.3, 2.0)))
    parts.append(add_box("GatePostR", (1.0, 0.0, 1.0), (0.3, 0.3, 2.0)))
    parts.append(add_box("Lintel", (0.0, 0.0, 2.15), (2.6, 0.4, 0.3)))
    for obj in parts:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = parts[0]
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    bpy.ops.object.join()
    courtyard = bpy.context.active_object
    courtyard.name = "Courtyard"

    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True,
                             PREF_NEW_UVLAYER=False, PREF_BOX_DIV=12, PREF_MARGIN_DIV=0.3)
    bpy.ops.object.mode_set(mode="OBJECT")

    sun_data = bpy.data.lights.new("Sun", type="SUN")
    sun_data.energy = 3.0
    sun_data.angle = math.radians(0.5)
    sun = bpy.data.objects.new("Sun", sun_data)
    sun.rotation_euler = (math.radians(50), 0.0, math.radians(35))
    bpy.context.collection.objects.link(sun)

    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.06, 0.08, 1.0)
    bpy.context.scene.world = world
    return courtyard


def bake(obj, resolution):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 64
    scene.cycles.use_denoising = False  # Debian's Blender has no OpenImageDenoise
    scene.render.bake.use_pass_color = False
    scene.render.bake.use_pass_direct = True
    scene.render.bake.use_pass_indirect = True
    scene.render.bake.margin = 2

    image = bpy.data.images.new("CourtyardLightmap", resolution, resolution, float_buffer=True, alpha=True)
    material = bpy.data.materials.new("Stone")
    material.use_nodes = True
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.nodes.active = node
    obj.data.materials.append(material)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}, use_clear=True)
    pixels = np.empty(resolution * resolution * 4, np.float32)
    image.pixels.foreach_get(pixels)
    # Blender's pixels are bottom-up; lmrefine arrays are top-down.
    return pixels.reshape(resolution, resolution, 4)[::-1].copy()


def layout(obj):
    mesh = obj.data
    mesh.calc_loop_triangles()
    loops = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    loop_uvs = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers.active.data.foreach_get("uv", loop_uvs)
    uvs = loop_uvs.reshape(-1, 2)[loops]
    return uvs, np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)


def main():
    args = argv_after_dashes()
    out_dir = args[0] if args else os.path.dirname(os.path.abspath(__file__))
    resolution = int(args[1]) if len(args) > 1 else 256
    import lmrefine

    courtyard = build_courtyard()
    lightmap = bake(courtyard, resolution)
    uvs, triangles = layout(courtyard)
    lmrefine.write_image(os.path.join(out_dir, "courtyard_lightmap.exr"), lightmap[..., :3].copy(), format="half")
    np.savez_compressed(os.path.join(out_dir, "courtyard_layout.npz"), uvs=uvs, triangles=triangles)
    print(f"wrote courtyard lightmap {resolution}^2, {len(triangles)} triangles, to {out_dir}")


main()
