"""Bake scenes with Blender's Cycles, for cross-checks against lmrefine.bake.

Runs inside Blender (no lmrefine import):

    blender -b --factory-startup --python-exit-code 1 \
        --python tests/blender/cycles_bake.py -- jobs.json out.npz

jobs.json holds a list of jobs, each one scene in the same terms as
lmrefine.Scene (meshes with per-corner UVs, lights with Blender's property
names, world colour) plus the bake settings. Every job is baked in one Blender
process; out.npz holds "<job>/<mesh>/<pass>" -> float32 (R, R, 4), rows top
down like lmrefine's arrays, and "<job>/seconds/<pass>" -> bake time
("<job>/cpu_seconds/<pass>": CPU time of all of Blender's threads).
"""
import json
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix, Vector

# Cycles' own bake types for our passes (colour pass off, as lmrefine bakes).
# Blender 3.4 returns ~0 for DIFFUSE with pass_filter {'INDIRECT'} alone
# (measured), so "indirect" is baked as combined minus direct.
BAKE_TYPES = {
    "direct": dict(type="DIFFUSE", pass_filter={"DIRECT"}),
    "combined": dict(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}),
    "ao": dict(type="AO"),
}


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.use_preview_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.render.bake.use_pass_color = False
    scene.render.bake.margin = 0
    return scene


def diffuse_material(name, color):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    output = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(bsdf.outputs["BSDF"], output.inputs["Surface"])
    return material


def add_mesh(scene, index, spec, resolution):
    positions = np.asarray(spec["positions"], dtype=float)
    triangles = np.asarray(spec["triangles"], dtype=int)
    mesh = bpy.data.meshes.new(f"mesh{index}")
    mesh.from_pydata(positions.tolist(), [], triangles.tolist())
    # from_pydata keeps face and corner order: loop 3t+k is corner k of triangle t.
    if spec.get("uvs") is not None:
        layer = mesh.uv_layers.new(name="lightmap")
        layer.data.foreach_set("uv", np.asarray(spec["uvs"], dtype=np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new(f"object{index}", mesh)
    scene.collection.objects.link(obj)
    material = diffuse_material(f"material{index}", spec.get("base_color", (0.8, 0.8, 0.8)))
    mesh.materials.append(material)
    image = None
    if spec.get("receiver", True):
        image = bpy.data.images.new(f"bake{index}", resolution, resolution, alpha=True, float_buffer=True)
        node = material.node_tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        material.node_tree.nodes.active = node
    return obj, image


def add_light(scene, index, spec):
    """A light object placed by `matrix` (its matrix_world, rows), or by
    position, direction (its -Z) and axis_x (its +X; default: Blender's
    to_track_quat('-Z', 'Y') orientation), as lmrefine.Scene.add_light takes them."""
    spec = dict(spec)
    kind = spec.pop("kind")
    matrix = spec.pop("matrix", None)
    position = spec.pop("position", (0.0, 0.0, 0.0))
    direction = spec.pop("direction", (0.0, 0.0, -1.0))
    axis_x = spec.pop("axis_x", None)
    light = bpy.data.lights.new(f"light{index}", kind.upper())
    for key, value in spec.items():
        setattr(light, key, tuple(value) if isinstance(value, list) else value)
    obj = bpy.data.objects.new(f"light{index}", light)
    scene.collection.objects.link(obj)
    if matrix is not None:
        obj.matrix_world = Matrix(matrix)
        return
    obj.location = position
    # Blender lights shine down their local -Z axis.
    if axis_x is None:
        obj.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
        return
    z = -Vector(direction).normalized()
    x = Vector(axis_x)
    x = (x - x.dot(z) * z).normalized()
    obj.rotation_euler = Matrix((x, z.cross(x), z)).transposed().to_euler()


def set_world(scene, color, ao_distance):
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*color, 1.0)
    background.inputs["Strength"].default_value = 1.0
    world.light_settings.distance = ao_distance
    scene.world = world


def bake_pixels(image, name):
    """Bakes the selected object into its image; (R, R, 4) rows top-down."""
    bpy.ops.object.bake(margin=0, use_clear=True, **BAKE_TYPES[name])
    size = image.size[0]
    pixels = np.empty(size * size * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    # Blender's pixels are bottom-up; lmrefine's arrays are top-down.
    return pixels.reshape(size, size, 4)[::-1].copy()


def bake_job(job, out):
    scene = reset()
    resolution = job["resolution"]
    scene.cycles.samples = job["samples"]
    scene.cycles.seed = job.get("seed", 0)
    scene.cycles.diffuse_bounces = job.get("bounces", 4)
    scene.cycles.max_bounces = max(12, job.get("bounces", 4))
    set_world(scene, job.get("world", (0.0, 0.0, 0.0)), job.get("ao_distance", 10.0))
    receivers = []
    for index, spec in enumerate(job["meshes"]):
        obj, image = add_mesh(scene, index, spec, resolution)
        if image is not None:
            receivers.append((index, obj, image))
    for index, spec in enumerate(job.get("lights", [])):
        add_light(scene, index, spec)
    for name in job["passes"]:
        started, cpu_started = time.perf_counter(), time.process_time()
        for index, obj, image in receivers:
            bpy.ops.object.select_all(action="DESELECT")
            obj.select_set(True)
            bpy.context.view_layer.objects.active = obj
            if name == "indirect":
                pixels = bake_pixels(image, "combined")
                pixels[..., :3] -= bake_pixels(image, "direct")[..., :3]
            else:
                pixels = bake_pixels(image, name)
            out[f"{job['name']}/{index}/{name}"] = pixels
        out[f"{job['name']}/seconds/{name}"] = np.float64(time.perf_counter() - started)
        out[f"{job['name']}/cpu_seconds/{name}"] = np.float64(time.process_time() - cpu_started)


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    with open(argv[0]) as f:
        jobs = json.load(f)
    out = {}
    for job in jobs:
        bake_job(job, out)
    np.savez(argv[1], **out)


main()
