"""Scenes drawn at random, built the way a user builds one in a window, to
measure lmrefine on scenes nobody has looked at (docs/evaluation.md,
"Scenes drawn at random"). Each seed gives one .blend: a floor (a plane,
subdivided finely or barely), three to seven props on it drawn from Blender's
primitives (cubes, some with a Simple subdivision modifier left unapplied,
cylinders, UV spheres and Suzanne under a Subdivision Surface modifier,
smooth-shaded or not, scaled without applying the scale, turned), sometimes
a wall or a pergola of beams that casts shadows but has no lightmap (no UV
map), a sun at a random height and heading, and zero to two point, spot or
area lights. The lit objects share one atlas in two maps, as a user unwraps
them together in multi-object edit mode: "Lightmap" (UV > Smart UV Project)
and "LightmapPack" (UV > Lightmap Pack).

    blender -b --factory-startup --python-exit-code 1 --python bench/random_scenes.py -- OUT_DIR SEED [SEED ...]
    PYTHONPATH=python /usr/bin/python3 -m lmrefine evaluate OUT_DIR/random_SEED.blend --view-width 0 \
        --uv-map Lightmap|LightmapPack [--resolution 512]

Each scene's draw is written beside it (random_SEED.json): what was built,
so a row can be read without opening the file. Blender does not always
order a UV sphere's triangles the same way from run to run (the same
vertices, another triangle order), so a seed built again may measure a
little differently: the figures in docs/evaluation.md are of the files
built then.
"""

import json
import math
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rotunda_scene import added, edit, joined, unwrap_together  # noqa: E402  (the same user steps)


def subdivide(obj, cuts):
    """Edit > Subdivide with `cuts` cuts on every face, as a user does it."""
    edit(obj)
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode='OBJECT')


def material(obj, rng):
    shade = rng.uniform(0.35, 0.85, 3)
    made = bpy.data.materials.new(obj.name + "Material")
    made.use_nodes = True
    made.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*shade, 1.0)
    obj.data.materials.append(made)


def prop(kind, index, rng, size, draw):
    """One prop of `kind` somewhere on a floor of side `size`; its draw goes into `draw`."""
    x, y = rng.uniform(-0.35, 0.35, 2) * size
    turn = float(rng.uniform(0, math.pi))
    smooth = bool(rng.random() < 0.5)
    if kind == "cube":
        scale = rng.uniform(0.3, 1.6, 3)
        bpy.ops.mesh.primitive_cube_add(size=1, location=(x, y, scale[2] / 2), rotation=(0, 0, turn))
        obj = added(f"Cube{index}")
        obj.scale = scale
        levels = int(rng.integers(0, 4))
        if levels:  # a Simple subdivision, left as a modifier, gives the faces vertices to move
            modifier = obj.modifiers.new("Subdivision", 'SUBSURF')
            modifier.subdivision_type, modifier.levels, modifier.render_levels = 'SIMPLE', levels, levels
        smooth = False
        entry = {"scale": [round(float(s), 2) for s in scale], "simple_levels": levels}
    elif kind == "cylinder":
        radius, depth = float(rng.uniform(0.15, 0.6)), float(rng.uniform(0.8, 3.0))
        vertices = int(rng.integers(8, 33))
        bpy.ops.mesh.primitive_cylinder_add(vertices=vertices, radius=radius, depth=depth, location=(x, y, depth / 2))
        obj = added(f"Cylinder{index}")
        entry = {"radius": round(radius, 2), "depth": round(depth, 2), "vertices": vertices}
    elif kind == "sphere":
        radius = float(rng.uniform(0.3, 1.0))
        segments = int(rng.integers(12, 33))
        bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=segments // 2, radius=radius,
                                             location=(x, y, radius))
        obj = added(f"Sphere{index}")
        entry = {"radius": round(radius, 2), "segments": segments}
    else:  # Suzanne on a plinth of her own height
        scale = float(rng.uniform(0.5, 1.2))
        bpy.ops.mesh.primitive_monkey_add(size=2 * scale, location=(x, y, 0.9 * scale), rotation=(0, 0, turn))
        obj = added(f"Suzanne{index}")
        obj.modifiers.new("Subdivision", 'SUBSURF').levels = 1
        entry = {"size": round(2 * scale, 2)}
    if smooth:
        bpy.ops.object.shade_smooth()
    material(obj, rng)
    draw.append({"kind": kind, "name": obj.name, "at": [round(float(x), 2), round(float(y), 2)],
                 "turn_degrees": round(math.degrees(turn)), "smooth": smooth, **entry})
    return obj


def caster(kind, rng, size, draw):
    """A wall or a pergola of beams with no UV map: it casts shadows and gets no lightmap."""
    if kind == "wall":
        length, height = float(rng.uniform(0.4, 0.8) * size), float(rng.uniform(1.5, 3.0))
        side = float(rng.choice([-1, 1])) * 0.45 * size
        bpy.ops.mesh.primitive_cube_add(size=1, location=(0, side, height / 2))
        obj = added("Wall")
        obj.scale = (length, 0.25, height)
        entry = {"length": round(length, 2), "height": round(height, 2)}
    else:
        beams, height = int(rng.integers(5, 12)), float(rng.uniform(2.2, 3.2))
        span, gap = float(rng.uniform(2.0, 4.0)), float(rng.uniform(0.25, 0.6))
        x, y = rng.uniform(-0.2, 0.2, 2) * size
        made = []
        for k in range(beams):
            bpy.ops.mesh.primitive_cube_add(size=1, location=(x + (k - beams / 2) * gap, y, height))
            made.append(bpy.context.active_object)
            made[-1].scale = (0.08, span, 0.15)
        obj = joined(made, "Pergola")
        entry = {"beams": beams, "height": round(height, 2), "gap": round(gap, 2)}
    while obj.data.uv_layers:
        obj.data.uv_layers.remove(obj.data.uv_layers[0])
    draw.append({"kind": kind, "casts_only": True, **entry})


def lights(rng, size, draw):
    elevation, heading = float(rng.uniform(20, 65)), float(rng.uniform(0, 360))
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(90 - elevation), 0, math.radians(heading)))
    sun = added("Sun")
    sun.data.energy, sun.data.angle = float(rng.uniform(3, 5)), math.radians(float(rng.uniform(0.3, 3.0)))
    draw.append({"kind": "sun", "elevation": round(elevation), "heading": round(heading),
                 "angle_degrees": round(math.degrees(sun.data.angle), 2)})
    for k in range(int(rng.integers(0, 3))):
        kind = str(rng.choice(["POINT", "SPOT", "AREA"]))
        x, y = rng.uniform(-0.3, 0.3, 2) * size
        z = float(rng.uniform(1.5, 3.5))
        bpy.ops.object.light_add(type=kind, location=(x, y, z),
                                 rotation=(float(rng.uniform(0, 0.6)), float(rng.uniform(0, 0.6)), 0))
        light = added(f"{kind.title()}{k}")
        light.data.energy = float(rng.uniform(100, 500))
        light.data.color = tuple(rng.uniform(0.6, 1.0, 3))
        if kind == "AREA":
            light.data.size = float(rng.uniform(0.3, 1.5))
        else:
            light.data.shadow_soft_size = float(rng.uniform(0.05, 0.4))
        if kind == "SPOT":
            light.data.spot_size = math.radians(float(rng.uniform(40, 100)))
            light.data.spot_blend = float(rng.uniform(0.05, 0.5))
        draw.append({"kind": kind.lower(), "at": [round(float(x), 2), round(float(y), 2), round(z, 2)],
                     "energy": round(light.data.energy)})


def build(seed, out_dir):
    rng = np.random.default_rng(seed)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups
    size = float(rng.uniform(8, 14))
    coarse = bool(rng.random() < 0.25)
    cuts = int(rng.integers(0, 4)) if coarse else int(rng.integers(15, 41))
    bpy.ops.mesh.primitive_plane_add(size=size)
    floor = added("Floor")
    if cuts:
        subdivide(floor, cuts)
    material(floor, rng)
    draw = [{"kind": "floor", "size": round(size, 2), "cuts": cuts, "coarse": coarse}]
    receivers = [floor]
    for index in range(int(rng.integers(3, 8))):
        kind = str(rng.choice(["cube", "cube", "cylinder", "sphere", "suzanne"]))
        receivers.append(prop(kind, index, rng, size, draw))
    if rng.random() < 0.5:
        caster(str(rng.choice(["wall", "pergola"])), rng, size, draw)
    lights(rng, size, draw)
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    sky = tuple(float(c) for c in rng.uniform(0.02, 0.12, 3))
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*sky, 1.0)
    bpy.context.scene.world = world
    unwrap_together(receivers)
    path = os.path.join(out_dir, f"random_{seed}.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
    with open(os.path.join(out_dir, f"random_{seed}.json"), "w") as f:
        json.dump({"seed": seed, "draw": draw}, f, indent=1)
    print(f"random_{seed}: {len(receivers)} lit objects, floor {cuts} cuts -> {path}")


if __name__ == "__main__":
    arguments = sys.argv[sys.argv.index("--") + 1:]
    os.makedirs(arguments[0], exist_ok=True)
    for seed in arguments[1:]:
        build(int(seed), os.path.abspath(arguments[0]))
