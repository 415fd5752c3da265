"""Build the bundled sample scenes (run by `make samples`).

    blender -b --factory-startup --python-exit-code 1 \
        --python blend_samples/make_samples.py -- [OUT_DIR] [SCENE ...]
    blender -b --factory-startup --python-exit-code 1 \
        --python blend_samples/make_samples.py -- --export-only [OUT_DIR] [SCENE ...]

(The second writes the .npz again from the saved .blend, its layouts as
they are, when the file gains a field.)

Writes, per scene, ``<name>.blend`` (small: no images, compressed) and
``<name>.npz``, the same scene for lmrefine without Blender (read it with
``lmrefine.sample_scenes.load_sample``):

    positions     (V, 3) float32   world space, every receiver of the scene
    triangles     (T, 3) int32     indices into positions
    normals       (3T, 3) float32  per corner (corner k of triangle t at 3t+k)
    uv_lightmap   (3T, 2) float32  per corner, Blender's Lightmap Pack atlas
    uv_smart      (3T, 2) float32  per corner, Smart UV Project atlas
    base_color    (T, 3) float32   albedo per triangle
    object_id     (T,) int32       index into meta["objects"]
    polygons      (T,) int32       the face each triangle was cut from (the
                  receivers' faces numbered one after another)
    occluder_positions (U, 3), occluder_triangles (S, 3): casters without a
                  lightmap (foliage, fence), same conventions
    meta          JSON string: objects, lights (Blender's light properties,
                  world position and direction, and matrix_world, which
                  places them for the baker), world colour, passes, the
                  resolution the atlases' margins were made for

Every scene has two UV layers on its receivers, "Lightmap" (Lightmap Pack,
one shared atlas for all receivers, one chart per face; gutter 2 texels at
512^2) and "LightmapSmart" (Smart UV Project, also one shared atlas, few large
charts; meant for 256^2 and up).
Receivers are built from grids of roughly square cells (see CELL) because the
refinement can only move vertices: a shadow edge inside a big triangle cannot
gain texels. Casters that are not lightmapped (leaves, fence slats) are
flagged with the custom property ``lmrefine_receiver = False``.
"""

import json
import math
import os
import sys

import bmesh
import bpy
import numpy as np
from mathutils import Vector

# The scene file's format (lmrefine.sample_scenes) and the add-on's reading of
# lights (lmrefine_blender.bridge) are shared with `export-scene`.
_REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
for _path in (os.path.join(_REPO, "python"), os.path.join(_REPO, "addon")):
    if _path not in sys.path:
        sys.path.insert(0, _path)

from lmrefine.sample_scenes import SampleScene  # noqa: E402
from lmrefine_blender.bridge import light_params, world_color  # noqa: E402

# Target edge length of receiver cells, metres.
CELL = 0.3
# Gutters between charts. Lightmap Pack makes one chart per face, thousands
# of them on tessellated receivers, so it is meant for 512^2 and up: its
# gutter is 2 / DIV of the atlas = 2 texels at 512^2 (the operator contracts
# each box by 1/DIV on every side, DIV = int(100 / Margin)). Smart UV Project
# makes few large charts, fine from 256^2 on.
LIGHTMAP_PACK_MARGIN = 0.2  # the operator's "Margin" (percent): DIV = 500
MIN_RESOLUTION = {"lightmap": 512, "smart": 256}


# --------------------------------------------------------------------------- geometry


def grid_faces(bm, origin, axis_u, axis_v, count_u, count_v, holes=()):
    """Quads of a grid from `origin` spanning `axis_u` x `axis_v` (world
    vectors), count_u x count_v cells; cells whose centre (in [0,1]^2 grid
    coordinates) lies inside one of `holes` (u0, v0, u1, v1) are left out."""
    origin, axis_u, axis_v = Vector(origin), Vector(axis_u), Vector(axis_v)
    verts = [[bm.verts.new(origin + axis_u * (i / count_u) + axis_v * (j / count_v))
              for j in range(count_v + 1)] for i in range(count_u + 1)]
    for i in range(count_u):
        for j in range(count_v):
            cu, cv = (i + 0.5) / count_u, (j + 0.5) / count_v
            if any(u0 < cu < u1 and v0 < cv < v1 for u0, v0, u1, v1 in holes):
                continue
            bm.faces.new((verts[i][j], verts[i + 1][j], verts[i + 1][j + 1], verts[i][j + 1]))


def cells(length, cell=CELL):
    return max(1, int(math.ceil(length / cell - 1e-6)))


def box_faces(bm, center, size, cell=CELL):
    """A closed box (outward normals) made of grids of about `cell` metres."""
    c, (sx, sy, sz) = Vector(center), size
    x, y, z = Vector((sx, 0, 0)), Vector((0, sy, 0)), Vector((0, 0, sz))
    lo = c - (x + y + z) / 2
    # Each face: origin, u axis, v axis chosen so u x v points outwards.
    for origin, u, v in ((lo, y, x), (lo + z, x, y), (lo, x, z), (lo + y, z, x), (lo, z, y), (lo + x, y, z)):
        grid_faces(bm, origin, u, v, cells(u.length, cell), cells(v.length, cell))


def cylinder_faces(bm, base, radius, height, segments=16, cell=CELL):
    """A capped vertical cylinder with rings about `cell` apart."""
    base = Vector(base)
    rings = cells(height, cell)
    ring = []
    for k in range(rings + 1):
        z = height * k / rings
        ring.append([bm.verts.new(base + Vector((radius * math.cos(2 * math.pi * s / segments),
                                                 radius * math.sin(2 * math.pi * s / segments), z)))
                     for s in range(segments)])
    for k in range(rings):
        for s in range(segments):
            t = (s + 1) % segments
            bm.faces.new((ring[k][s], ring[k][t], ring[k + 1][t], ring[k + 1][s]))
    bm.faces.new(list(reversed(ring[0])))
    bm.faces.new(ring[-1])


def arch_faces(bm, center, span, rise_top, depth, thickness, segments=12):
    """A semicircular arch in the XZ plane (spanning x in center +- span/2,
    springing at center.z), `depth` along y: intrados, front, back and the
    outer (rectangular) surface. Built as quad strips so the intrados and the
    faces stay evenly tessellated."""
    c = Vector(center)
    r = span / 2
    outer_w, outer_h = r + thickness, rise_top
    front, back = [], []
    for k in range(segments + 1):
        a = math.pi * k / segments
        d = Vector((math.cos(a), 0, math.sin(a)))
        inner = c + d * r
        # The outer point: where the ray from the centre meets the rectangle.
        t = min(outer_w / abs(d.x) if abs(d.x) > 1e-6 else 1e9, outer_h / d.z if d.z > 1e-6 else 1e9)
        outer = c + d * t
        half = Vector((0, depth / 2, 0))
        front.append((bm.verts.new(inner - half), bm.verts.new(outer - half)))
        back.append((bm.verts.new(inner + half), bm.verts.new(outer + half)))
    for k in range(segments):
        fi, fo = front[k]
        gi, go = front[k + 1]
        bi, bo = back[k]
        hi, ho = back[k + 1]
        bm.faces.new((fi, gi, go, fo))      # front face (-y)
        bm.faces.new((bi, bo, ho, hi))      # back face (+y)
        bm.faces.new((fi, bi, hi, gi))      # intrados (facing the centre)
        bm.faces.new((fo, go, ho, bo))      # outer surface
    for (fi, fo), (bi, bo) in ((front[0], back[0]), (front[-1], back[-1])):
        bm.faces.new((fi, fo, bo, bi))      # springing faces (closed ends)


def make_object(name, build, color, receiver=True, closed=True, smooth=False):
    """A mesh object built by `build(bm)` in world space. Closed meshes get
    outward normals; open ones (floors, room walls) keep the winding that
    `build` gave them (u x v of their grids). `smooth`: Shade Smooth with
    Auto Smooth at 60 degrees, as artists shade curved props (edges sharper
    than that stay hard)."""
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    build(bm)
    bmesh.ops.remove_doubles(bm, verts=bm.verts, dist=1e-5)
    if closed:
        bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
    bm.to_mesh(mesh)
    bm.free()
    if smooth:
        mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
        mesh.use_auto_smooth = True
        mesh.auto_smooth_angle = math.radians(60)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.collection.objects.link(obj)
    obj["lmrefine_receiver"] = receiver
    material = bpy.data.materials.new(name + "Material")
    material.use_nodes = True
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*color, 1.0)
    material.diffuse_color = (*color, 1.0)
    mesh.materials.append(material)
    return obj


def add_light(name, kind, location, rotation=(0, 0, 0), **properties):
    data = bpy.data.lights.new(name, type=kind)
    for key, value in properties.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    obj.rotation_euler = rotation
    bpy.context.collection.objects.link(obj)
    return obj


def aim(location, target):
    """Euler rotation that points a light's -Z axis from `location` at `target`."""
    direction = Vector(target) - Vector(location)
    return direction.to_track_quat("-Z", "Y").to_euler()


def set_world(color):
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*color, 1.0)
    world.color = color
    bpy.context.scene.world = world


# --------------------------------------------------------------------------- scenes


def courtyard():
    """A sunlit courtyard: a floor, an arcade of round columns carrying arches
    on two sides, a low wall; low sun, hard shadows."""
    make_object("Floor", lambda bm: grid_faces(bm, (-6, -6, 0), (12, 0, 0), (0, 12, 0), 40, 40), (0.7, 0.68, 0.62),
                closed=False)

    def arcade(bm, y):
        for i in range(5):
            cylinder_faces(bm, (-4 + 2 * i, y, 0), 0.22, 2.2, segments=12)
        for i in range(4):
            arch_faces(bm, (-3 + 2 * i, y, 2.2), 2.0, 1.3, 0.5, 0.25, segments=10)
    make_object("ArcadeNorth", lambda bm: arcade(bm, 3.5), (0.8, 0.75, 0.65))
    make_object("ArcadeWest", lambda bm: [cylinder_faces(bm, (-4.5, -3 + 2 * i, 0), 0.22, 2.2, segments=12)
                                           for i in range(4)], (0.8, 0.75, 0.65))
    make_object("LowWall", lambda bm: box_faces(bm, (2.0, -3.5, 0.4), (5.0, 0.3, 0.8)), (0.6, 0.6, 0.62))
    make_object("Well", lambda bm: cylinder_faces(bm, (0.5, 0.0, 0), 0.7, 0.7, segments=20), (0.55, 0.55, 0.6))
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(55), 0.0, math.radians(150)), energy=4.0, angle=math.radians(0.6))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def room():
    """A closed room: sun through a window (hard-edged patch), a ceiling lamp
    with a radius (soft shadows of a table and a cabinet), indirect light
    from the bounce."""
    w, d, h = 6.0, 5.0, 3.0

    def shell(bm):
        # Inward-facing: u x v points into the room.
        grid_faces(bm, (-w / 2, -d / 2, 0), (w, 0, 0), (0, d, 0), cells(w), cells(d))            # floor
        grid_faces(bm, (-w / 2, -d / 2, h), (0, d, 0), (w, 0, 0), cells(d), cells(w))            # ceiling
        grid_faces(bm, (-w / 2, -d / 2, 0), (0, 0, h), (w, 0, 0), cells(h), cells(w))            # south wall
        grid_faces(bm, (w / 2, -d / 2, 0), (0, 0, h), (0, d, 0), cells(h), cells(d))             # east wall
        grid_faces(bm, (-w / 2, d / 2, 0), (w, 0, 0), (0, 0, h), cells(w), cells(h))             # north wall
        # West wall with a window: 1.47 m wide (5 of 17 cells), 1.2 m tall
        # (4 of 10 cells), sill at 0.9 m.
        grid_faces(bm, (-w / 2, -d / 2, 0), (0, d, 0), (0, 0, h), 17, 10,
                   holes=[((d / 2 - 0.75) / d, 0.9 / h, (d / 2 + 0.75) / d, 2.1 / h)])
    make_object("Shell", shell, (0.75, 0.72, 0.68), closed=False)
    make_object("Table", lambda bm: (box_faces(bm, (0.8, 0.3, 0.72), (1.4, 0.8, 0.06), 0.2),
                                     *[box_faces(bm, (0.8 + sx * 0.62, 0.3 + sy * 0.32, 0.345), (0.06, 0.06, 0.69), 0.2)
                                       for sx in (-1, 1) for sy in (-1, 1)]), (0.55, 0.4, 0.3))
    make_object("Cabinet", lambda bm: box_faces(bm, (2.5, 1.8, 0.9), (0.8, 0.5, 1.8), 0.25), (0.35, 0.45, 0.6))
    make_object("Lamp", lambda bm: cylinder_faces(bm, (0.8, 0.3, 2.55), 0.18, 0.12, segments=12, cell=0.12),
                (0.9, 0.9, 0.85), receiver=False)
    sun_at = Vector((-8.0, 0.6, 4.6))
    add_light("Sun", "SUN", sun_at, aim(sun_at, (-1.0, 0.2, 0.0)), energy=5.0, angle=math.radians(0.5))
    add_light("CeilingLamp", "POINT", (0.8, 0.3, 2.4), energy=150.0, shadow_soft_size=0.15)
    set_world((0.3, 0.4, 0.55))
    return {"passes": ["combined"]}  # direct + indirect


def fence_and_tree():
    """Complex casters over a floor: a picket fence and a small tree whose
    crown is hundreds of leaf cards (foliage-like cut-out geometry). The
    casters are not lightmapped; the floor and a back wall are."""
    make_object("Floor", lambda bm: grid_faces(bm, (-5, -5, 0), (10, 0, 0), (0, 10, 0), 40, 40), (0.45, 0.55, 0.35),
                closed=False)
    make_object("BackWall", lambda bm: box_faces(bm, (0, 4.6, 1.25), (10, 0.3, 2.5)), (0.7, 0.65, 0.6))

    def fence(bm):
        for i in range(22):
            box_faces(bm, (-4.2 + 0.38 * i, -1.5, 0.55), (0.09, 0.03, 1.1), cell=2.0)
        for z in (0.3, 0.85):
            box_faces(bm, (0.0, -1.48, z), (8.5, 0.03, 0.08), cell=9.0)
    make_object("Fence", fence, (0.6, 0.5, 0.4), receiver=False)

    def tree(bm):
        cylinder_faces(bm, (1.5, 1.5, 0), 0.12, 2.0, segments=8, cell=1.0)
        rng = np.random.default_rng(7)
        for _ in range(500):
            # Leaf cards in an ellipsoidal crown, random orientation.
            p = rng.normal(size=3)
            p = p / np.linalg.norm(p) * rng.uniform(0.2, 1.0) ** (1 / 3)
            centre = Vector((1.5 + 1.3 * p[0], 1.5 + 1.3 * p[1], 2.7 + 0.9 * p[2]))
            axes = np.linalg.qr(rng.normal(size=(3, 3)))[0]
            a, b = Vector(axes[:, 0] * 0.16), Vector(axes[:, 1] * 0.07)
            verts = [bm.verts.new(centre + a), bm.verts.new(centre + b), bm.verts.new(centre - a),
                     bm.verts.new(centre - b)]
            bm.faces.new(verts)
    make_object("Tree", tree, (0.25, 0.45, 0.2), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(55), 0.0, math.radians(20)), energy=4.0, angle=math.radians(0.8))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"], "smart_margin": 0.035}


def game_level():
    """A low-poly game-like level: a walled yard with crates, pillars, steps,
    a ramp and a platform, 20-odd objects sharing one atlas; a sun and two
    point lights."""
    make_object("Ground", lambda bm: grid_faces(bm, (-7, -7, 0), (14, 0, 0), (0, 14, 0), 40, 40), (0.5, 0.5, 0.52),
                closed=False)
    for name, center, size in (("WallN", (0, 6.8, 1.5), (14, 0.4, 3)), ("WallS", (0, -6.8, 1.0), (14, 0.4, 2)),
                               ("WallE", (6.8, 0, 1.5), (0.4, 13.2, 3))):
        make_object(name, lambda bm, c=center, s=size: box_faces(bm, c, s, 0.5), (0.65, 0.6, 0.55))
    rng = np.random.default_rng(3)
    for i in range(8):
        size = float(rng.uniform(0.6, 1.1))
        c = (float(rng.uniform(-5, 4)), float(rng.uniform(-5, 5)), size / 2)
        make_object(f"Crate{i}", lambda bm, c=c, s=size: box_faces(bm, c, (s, s, s), 0.35), (0.6, 0.45, 0.25))
    for i, (x, y) in enumerate(((-2, 3), (2, 3), (-2, -1), (2, -1))):
        make_object(f"Pillar{i}", lambda bm, x=x, y=y: box_faces(bm, (x, y, 1.5), (0.5, 0.5, 3.0), 0.5), (0.7, 0.7, 0.72))

    def steps(bm):
        for k in range(4):
            box_faces(bm, (-5.5, -5.0 + 0.4 * k + 0.8, 0.15 + 0.15 * k), (2.0, 1.6 - 0.4 * k, 0.3), 0.25)
    make_object("Steps", steps, (0.6, 0.6, 0.6))
    make_object("Platform", lambda bm: box_faces(bm, (4.5, 4.5, 0.6), (3.0, 3.0, 1.2), 0.4), (0.5, 0.55, 0.6))

    def ramp(bm):
        grid_faces(bm, (1.5, 3.75, 0.0), (1.5, 0, 1.2), (0, 1.5, 0), 6, 5)
    make_object("Ramp", ramp, (0.55, 0.5, 0.45), closed=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(50), 0.0, math.radians(-30)), energy=3.5, angle=math.radians(0.5))
    add_light("LampA", "POINT", (-3.5, 1.0, 2.5), energy=300.0, shadow_soft_size=0.1, color=(1.0, 0.8, 0.6))
    add_light("LampB", "POINT", (3.0, -3.0, 2.0), energy=200.0, shadow_soft_size=0.3, color=(0.6, 0.8, 1.0))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def atrium():
    """An atrium (holdout: never used to tune constants): a floor ringed by
    columns under an open lattice roof whose beams cast a grid of sun
    shadows, a back wall; a sun, a spot light and a rectangular area light."""
    make_object("Floor", lambda bm: grid_faces(bm, (-5, -5, 0), (10, 0, 0), (0, 10, 0), 34, 34), (0.72, 0.7, 0.66),
                closed=False)
    make_object("BackWall", lambda bm: box_faces(bm, (0, 4.85, 1.6), (10, 0.3, 3.2), 0.4), (0.68, 0.64, 0.6))

    def columns(bm):
        for x in (-3.6, -1.2, 1.2, 3.6):
            for y in (-3.6, 3.6):
                cylinder_faces(bm, (x, y, 0), 0.2, 3.2, segments=10, cell=0.4)
    make_object("Columns", columns, (0.82, 0.78, 0.7))

    def lattice(bm):
        for k in range(13):
            t = -3.6 + 0.6 * k
            box_faces(bm, (t, 0, 3.3), (0.12, 7.6, 0.16), cell=9.0)
            box_faces(bm, (0, t, 3.5), (7.6, 0.12, 0.16), cell=9.0)
    make_object("Lattice", lattice, (0.5, 0.45, 0.4), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(35), 0.0, math.radians(210)), energy=3.5,
              angle=math.radians(0.7))
    spot_at = Vector((4.2, -4.2, 2.8))
    add_light("Spot", "SPOT", spot_at, aim(spot_at, (1.5, -1.0, 0.0)), energy=600.0, shadow_soft_size=0.1,
              spot_size=math.radians(55), spot_blend=0.2, color=(1.0, 0.85, 0.7))
    area_at = Vector((-2.5, 2.0, 2.6))
    add_light("Panel", "AREA", area_at, aim(area_at, (-2.5, 1.0, 0.0)), energy=250.0, shape="RECTANGLE",
              size=1.2, size_y=0.4, color=(0.7, 0.8, 1.0))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def plaza():
    """A coarse plaza (holdout: never used to tune constants), modelled the
    way low-poly levels often are: a floor of 2 m quads, low blocks and
    benches of one face per side, a pergola whose beams throw sharp stripes
    across the big floor triangles; a low sun."""
    make_object("Floor", lambda bm: grid_faces(bm, (-6, -6, 0), (12, 0, 0), (0, 12, 0), 6, 6), (0.7, 0.68, 0.64),
                closed=False)

    def blocks(bm):
        for center, size in (((-3.0, 2.5, 0.5), (1.6, 1.6, 1.0)), ((3.2, -2.8, 0.6), (2.2, 1.0, 1.2)),
                             ((-2.5, -3.5, 0.25), (3.0, 0.5, 0.5)), ((2.8, 3.0, 0.25), (0.5, 3.0, 0.5))):
            box_faces(bm, center, size, cell=9.0)
    make_object("Blocks", blocks, (0.62, 0.6, 0.58))

    def pergola(bm):
        for k in range(9):
            box_faces(bm, (-1.6 + 0.4 * k, 0.0, 2.6), (0.1, 5.0, 0.14), cell=9.0)
        for x in (-1.8, 1.8):
            for y in (-2.4, 2.4):
                box_faces(bm, (x, y, 1.3), (0.14, 0.14, 2.6), cell=9.0)
    make_object("Pergola", pergola, (0.45, 0.35, 0.28), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(50), 0.0, math.radians(120)), energy=4.0,
              angle=math.radians(0.5))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def alley():
    """A narrow street (holdout: never used to tune constants) between two
    house fronts: a low sun from across the roofs puts the street in the
    west front's shadow, balconies on the sunlit east front throw their
    shadows down it, beams spanning the street stripe the floor and the
    walls; canopies over two doors in the shade, two warm wall lamps."""
    make_object("Street", lambda bm: grid_faces(bm, (-2, -6, 0), (4, 0, 0), (0, 12, 0), 14, 40), (0.55, 0.53, 0.5),
                closed=False)
    # House fronts facing the street (u x v points into it).
    make_object("WestFront", lambda bm: grid_faces(bm, (-2, -6, 0), (0, 12, 0), (0, 0, 4.5), 40, 15),
                (0.78, 0.7, 0.6), closed=False)
    make_object("EastFront", lambda bm: grid_faces(bm, (2, -6, 0), (0, 0, 4.5), (0, 12, 0), 15, 40),
                (0.8, 0.76, 0.68), closed=False)
    make_object("Balconies", lambda bm: [box_faces(bm, (1.57, y, 2.4), (0.8, 1.5, 0.15)) for y in (-3.5, 0.2, 3.8)],
                (0.6, 0.6, 0.62))
    make_object("Canopies", lambda bm: [box_faces(bm, (-1.52, y, 2.6), (0.9, 2.4, 0.08)) for y in (-2.0, 2.5)],
                (0.5, 0.3, 0.25))

    def beams(bm):
        for y in (-4.6, -1.5, 1.3, 4.4):
            box_faces(bm, (0, y, 4.4), (4.0, 0.12, 0.12), cell=9.0)
    make_object("Beams", beams, (0.4, 0.3, 0.22), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(35), 0.0, math.radians(-70)), energy=4.0,
              angle=math.radians(0.6))
    for name, y in (("LampSouth", -3.0), ("LampNorth", 3.2)):
        add_light(name, "POINT", (-1.8, y, 3.0), energy=120.0, shadow_soft_size=0.08, color=(1.0, 0.78, 0.5))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def village():
    """A village square (holdout: never used to tune constants; added to test
    the re-chart route's folds rule on a scene it was not written on): a
    house under a 30-degree pitched roof, an octagonal kiosk, a 25-degree
    ramp up to a platform, on a square that a pergola stripes with shadow; a
    sun from the south-west. Smart UV Project joins faces up to 66 degrees
    apart, so its charts fold over the ridge, the kiosk's sides and the
    ramp's crest, each lit differently by the sun."""
    make_object("Square", lambda bm: grid_faces(bm, (-6, -6, 0), (12, 0, 0), (0, 12, 0), 40, 40),
                (0.7, 0.67, 0.62), closed=False)
    make_object("House", lambda bm: box_faces(bm, (-2.0, 2.5, 1.25), (4.0, 3.0, 2.5)), (0.82, 0.78, 0.7))
    rise = 1.5 * math.tan(math.radians(30))

    def roof(bm):
        # Ridge along x at y = 2.5; each slope's u x v points up and out.
        grid_faces(bm, (-4.2, 0.8, 2.5), (4.4, 0, 0), (0, 1.7, rise * 1.7 / 1.5), cells(4.4), cells(2.0))
        grid_faces(bm, (-4.2, 4.2, 2.5), (0, -1.7, rise * 1.7 / 1.5), (4.4, 0, 0), cells(2.0), cells(4.4))
    make_object("Roof", roof, (0.55, 0.32, 0.26), closed=False)
    make_object("Kiosk", lambda bm: cylinder_faces(bm, (3.0, 2.8, 0), 1.1, 2.4, segments=8), (0.78, 0.74, 0.66))
    run = 2.4
    lift = run * math.tan(math.radians(25))

    def ramp(bm):
        grid_faces(bm, (-1.0, -4.5, 0), (run, 0, lift), (0, 2.0, 0), cells(run / math.cos(math.radians(25))),
                   cells(2.0))
        grid_faces(bm, (-1.0 + run, -4.5, lift), (1.8, 0, 0), (0, 2.0, 0), cells(1.8), cells(2.0))
    make_object("Ramp", ramp, (0.66, 0.64, 0.6), closed=False)

    def pergola(bm):
        for k in range(8):
            box_faces(bm, (-4.8 + 0.45 * k, -2.0, 2.4), (0.1, 3.2, 0.14), cell=9.0)
        for x in (-5.0, -1.5):
            for y in (-3.4, -0.6):
                box_faces(bm, (x, y, 1.2), (0.14, 0.14, 2.4), cell=9.0)
    make_object("Pergola", pergola, (0.45, 0.35, 0.28), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(48), 0.0, math.radians(-130)), energy=4.0,
              angle=math.radians(0.5))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def cloister():
    """A cloister garth (holdout: never used to tune constants; added as the
    first smooth-shaded scene, to test the re-chart route's reading of
    shading normals on a scene it was not written on): round columns of 16
    sides, a domed well head, a grassy mound and a barrel-vaulted walk, all
    shaded smooth with Auto Smooth 60 degrees as artists shade curved props,
    on a flat paving; a low sun from the west and a warm point light."""
    make_object("Paving", lambda bm: grid_faces(bm, (-6, -6, 0), (12, 0, 0), (0, 12, 0), 30, 30),
                (0.72, 0.7, 0.66), closed=False)
    for k in range(5):
        make_object(f"Column{k}", lambda bm, k=k: cylinder_faces(bm, (-4.0 + 2.0 * k, 3.2, 0), 0.28, 2.6),
                    (0.85, 0.82, 0.76), smooth=True)

    def vault(bm):
        # Half a cylinder along x over the walk behind the columns, open below, 20 sides.
        segments, length, radius = 20, 11.0, 1.3
        rows = [[bm.verts.new((-5.5 + length * i / 22, 4.6 + radius * math.cos(math.pi * s / segments),
                               2.6 + radius * math.sin(math.pi * s / segments)))
                 for s in range(segments + 1)] for i in range(23)]
        for i in range(22):
            for s in range(segments):
                bm.faces.new((rows[i][s], rows[i][s + 1], rows[i + 1][s + 1], rows[i + 1][s]))
    make_object("Vault", vault, (0.8, 0.76, 0.7), closed=False, smooth=True)

    def well(bm):
        cylinder_faces(bm, (1.5, -1.5, 0), 0.9, 0.8)
        # A dome of quad rings (no pole triangles: Lightmap Pack keeps its gutters), capped at 75 degrees.
        rings = [[bm.verts.new((1.5 + 0.6 * math.cos(math.radians(e)) * math.cos(2 * math.pi * k / 16),
                                -1.5 + 0.6 * math.cos(math.radians(e)) * math.sin(2 * math.pi * k / 16),
                                0.8 + 0.6 * math.sin(math.radians(e)))) for k in range(16)]
                 for e in (0, 15, 30, 45, 60, 75)]
        for low, high in zip(rings, rings[1:]):
            for k in range(16):
                bm.faces.new((low[k], low[(k + 1) % 16], high[(k + 1) % 16], high[k]))
        bm.faces.new(rings[-1])
    make_object("Well", well, (0.7, 0.72, 0.74), smooth=True)

    def mound(bm):
        grid_faces(bm, (-5.0, -5.0, 0.01), (4.0, 0, 0), (0, 4.0, 0), 16, 16)
        for vert in bm.verts:
            r2 = (vert.co.x + 3.0) ** 2 + (vert.co.y + 3.0) ** 2
            vert.co.z = 0.01 + 0.9 * math.exp(-r2 / 1.2)
    make_object("Mound", mound, (0.42, 0.55, 0.3), closed=False, smooth=True)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(62), 0.0, math.radians(-95)), energy=4.0,
              angle=math.radians(0.5))
    add_light("Lamp", "POINT", (3.5, 1.0, 2.2), energy=120.0, color=(1.0, 0.8, 0.6), shadow_soft_size=0.1)
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


def depot():
    """A goods depot (holdout: never used to tune constants; added after the
    baker's border fix, with props resting on the floor and on each other,
    so that many chart borders run along contact lines): crates on the
    floor and stacked, a pallet rack along the back wall, a loading ramp; a
    roof with a grid of skylights lets the sun in as bright patches, a
    rectangular panel light over the ramp and a lamp by the door."""
    make_object("Floor", lambda bm: grid_faces(bm, (-7, -5, 0), (14, 0, 0), (0, 10, 0), 46, 33), (0.6, 0.6, 0.58),
                closed=False)
    make_object("BackWall", lambda bm: grid_faces(bm, (-7, 5, 0), (14, 0, 0), (0, 0, 4.0), 46, 13),
                (0.74, 0.72, 0.68), closed=False)

    def crates(bm):
        for center, size in (((-4.5, -1.5, 0.5), (1.0, 1.0, 1.0)), ((-4.5, -1.5, 1.35), (0.7, 0.7, 0.7)),
                             ((-2.6, -2.8, 0.4), (1.6, 0.8, 0.8)), ((1.0, -1.0, 0.6), (1.2, 1.2, 1.2)),
                             ((2.2, -1.2, 0.35), (0.7, 0.9, 0.7)), ((1.0, -1.0, 1.6), (0.8, 0.8, 0.8)),
                             ((4.8, 1.5, 0.45), (0.9, 1.4, 0.9))):
            box_faces(bm, center, size)
    make_object("Crates", crates, (0.66, 0.52, 0.36))

    def rack(bm):
        for z in (0.9, 1.9, 2.9):
            box_faces(bm, (-1.0, 4.45, z), (9.0, 0.9, 0.06))
    make_object("RackShelves", rack, (0.55, 0.58, 0.62))

    def uprights(bm):
        for x in (-5.5, -2.5, 0.5, 3.5):
            for y in (4.05, 4.85):
                box_faces(bm, (x, y, 1.5), (0.08, 0.08, 3.0), cell=9.0)
    make_object("RackUprights", uprights, (0.3, 0.35, 0.6), receiver=False)
    run = 3.0
    lift = 0.9

    def ramp(bm):
        grid_faces(bm, (4.0, -4.8, 0), (2.4, 0, 0), (0, run, lift), cells(2.4), cells(math.hypot(run, lift)))
    make_object("Ramp", ramp, (0.62, 0.6, 0.56), closed=False)

    def roof(bm):
        # Skylights: a 3 x 2 grid of openings in a roof 4.6 m up (an occluder only).
        # Openings as (x0, y0, x1, y1) fractions; the grid's u runs along y, so it takes them as (y, x).
        holes = [(0.12 + 0.3 * i, 0.2 + 0.4 * j, 0.24 + 0.3 * i, 0.4 + 0.4 * j) for i in range(3) for j in range(2)]
        grid_faces(bm, (-7, -5, 4.6), (0, 10, 0), (14, 0, 0), 40, 56, holes=[(y0, x0, y1, x1) for x0, y0, x1, y1 in holes])
    make_object("Roof", roof, (0.5, 0.5, 0.5), receiver=False, closed=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(30), 0.0, math.radians(160)), energy=5.0,
              angle=math.radians(0.5))
    panel_at = Vector((5.2, -3.0, 3.0))
    add_light("Panel", "AREA", panel_at, aim(panel_at, (5.2, -3.0, 0.0)), energy=300.0, shape="RECTANGLE",
              size=1.6, size_y=0.3, color=(0.85, 0.9, 1.0))
    add_light("Lamp", "POINT", (-6.2, -4.0, 2.8), energy=150.0, shadow_soft_size=0.1, color=(1.0, 0.8, 0.55))
    set_world((0.04, 0.05, 0.07))
    return {"passes": ["direct"]}


def stairs():
    """Outdoor stairs (holdout: never used to tune constants; added in the
    round of the unflip back-off and run once): twelve steps up between a
    retaining wall and a balustrade of square balusters to a terrace; a low
    sun from the balustrade's side rakes the balusters' comb of shadows
    across the treads, the risers and the wall, and a lamp on the terrace
    lights the top of the flight."""
    steps, rise, going, width = 12, 0.17, 0.3, 2.4
    top, length = steps * rise, steps * going
    make_object("Ground", lambda bm: grid_faces(bm, (-2, -5, 0), (8, 0, 0), (0, 5, 0), cells(8), cells(5)),
                (0.5, 0.52, 0.48), closed=False)

    def flight(bm):
        for i in range(steps):
            # Riser (facing -y), then tread (facing up).
            grid_faces(bm, (0, i * going, i * rise), (width, 0, 0), (0, 0, rise), cells(width), 1)
            grid_faces(bm, (0, i * going, (i + 1) * rise), (width, 0, 0), (0, going, 0), cells(width), 1)
    make_object("Flight", flight, (0.7, 0.68, 0.64), closed=False)
    make_object("Wall", lambda bm: grid_faces(bm, (0, 0, 0), (0, length, 0), (0, 0, top + 1.0), cells(length),
                                              cells(top + 1.0)), (0.76, 0.7, 0.62), closed=False)
    make_object("Terrace", lambda bm: grid_faces(bm, (-1, length, top), (7, 0, 0), (0, 3, 0), cells(7), cells(3)),
                (0.62, 0.6, 0.57), closed=False)
    make_object("TerraceFront", lambda bm: grid_faces(bm, (width, length, 0), (6 - width, 0, 0), (0, 0, top),
                                                      cells(6 - width), cells(top)), (0.72, 0.68, 0.6), closed=False)

    def balusters(bm):
        for k in range(24):
            y = 0.08 + k * 0.15
            base = (int(y // going) + 1) * rise
            box_faces(bm, (width + 0.05, y, base + 0.4), (0.05, 0.05, 0.8), cell=9.0)
    make_object("Balusters", balusters, (0.8, 0.8, 0.78), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(60), 0.0, math.radians(70)), energy=5.0,
              angle=math.radians(0.5))
    add_light("Lamp", "POINT", (4.0, 5.0, top + 2.2), energy=120.0, shadow_soft_size=0.1, color=(1.0, 0.8, 0.55))
    set_world((0.05, 0.06, 0.09))
    return {"passes": ["direct"]}


def hillside():
    """Organic ground (holdout: never used to tune constants; added in the
    round of the route's concurrency test and run once): smooth-shaded,
    gently rolling terrain whose triangles follow no axis, five
    smooth-shaded boulders (displaced spheres) and a dead tree of slanted
    branches that is not lightmapped; a mid-height sun throws the boulders'
    soft-edged shadows and the branches' thin ones across the slopes, and a
    campfire-coloured point light near the ground lights the boulders'
    sides."""
    rng = np.random.default_rng(11)
    size, count = 12.0, cells(12.0, 0.35)
    phases = rng.uniform(0, 2 * math.pi, 4)

    def height(x, y):
        return (0.45 * math.sin(0.55 * x + phases[0]) * math.cos(0.4 * y + phases[1])
                + 0.2 * math.sin(1.3 * x + 0.7 * y + phases[2]) + 0.08 * math.cos(2.1 * y - 0.9 * x + phases[3]))

    def terrain(bm):
        verts = [[bm.verts.new((x, y, height(x, y)))
                  for y in np.linspace(-size / 2, size / 2, count + 1)]
                 for x in np.linspace(-size / 2, size / 2, count + 1)]
        for i in range(count):
            for j in range(count):
                bm.faces.new((verts[i][j], verts[i + 1][j], verts[i + 1][j + 1], verts[i][j + 1]))
    make_object("Terrain", terrain, (0.42, 0.46, 0.3), closed=False, smooth=True)

    def boulders(bm):
        for cx, cy, radius in ((-2.5, 1.0, 1.1), (1.8, -1.5, 0.8), (3.2, 2.4, 1.3), (-1.0, -3.2, 0.6),
                               (0.4, 3.6, 0.7)):
            centre = Vector((cx, cy, height(cx, cy) + 0.45 * radius))
            made = bmesh.ops.create_icosphere(bm, subdivisions=3, radius=radius)
            for vert in made["verts"]:
                d = vert.co.normalized()
                bump = 1 + 0.12 * math.sin(3.1 * d.x + 1.7 * d.y * cx) + 0.08 * math.cos(4.3 * d.z + cy)
                vert.co = centre + Vector((vert.co.x * bump, vert.co.y * bump * 0.9, vert.co.z * bump * 0.7))
    make_object("Boulders", boulders, (0.55, 0.52, 0.5), smooth=True)

    def dead_tree(bm):
        base = (-0.2, 0.2, height(-0.2, 0.2) - 0.1)
        cylinder_faces(bm, base, 0.14, 3.2, segments=10, cell=3.5)
        for k in range(9):
            angle = 2 * math.pi * k / 9 + rng.uniform(-0.3, 0.3)
            start = Vector(base) + Vector((0, 0, 1.6 + 0.18 * k))
            direction = Vector((math.cos(angle), math.sin(angle), rng.uniform(0.3, 0.8))).normalized()
            length = rng.uniform(1.2, 2.2)
            made = bmesh.ops.create_cone(bm, cap_ends=True, segments=6, radius1=0.05, radius2=0.015, depth=length)
            rotation = direction.to_track_quat("Z", "Y").to_matrix()
            for vert in made["verts"]:  # the cone runs from -length / 2 to length / 2 along z
                vert.co = start + rotation @ (vert.co + Vector((0, 0, length / 2)))
    make_object("DeadTree", dead_tree, (0.35, 0.3, 0.25), receiver=False)
    add_light("Sun", "SUN", (0, 0, 10), (math.radians(58), 0.0, math.radians(-35)), energy=4.5,
              angle=math.radians(1.0))
    add_light("Campfire", "POINT", (1.0, 0.6, height(1.0, 0.6) + 0.5), energy=90.0, shadow_soft_size=0.15,
              color=(1.0, 0.6, 0.3))
    set_world((0.05, 0.07, 0.1))
    return {"passes": ["direct"]}


# Which scenes tune the refiner's constants and which only report is in
# docs/evaluation.md ("Tuning scenes and holdout scenes").
SCENES = {"courtyard": courtyard, "room": room, "fence_and_tree": fence_and_tree, "game_level": game_level,
          "atrium": atrium, "plaza": plaza, "alley": alley, "village": village, "cloister": cloister,
          "depot": depot, "stairs": stairs, "hillside": hillside}


# --------------------------------------------------------------------------- UVs and export


def receivers():
    return [obj for obj in bpy.context.scene.objects if obj.type == "MESH" and obj.get("lmrefine_receiver", True)]


def select_only(objects):
    bpy.ops.object.select_all(action="DESELECT")
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]


# Smart UV Project's island margin is relative to the islands' sizes: this
# gives gutters of 3 to 5 texels at 256^2; scenes with few large islands set
# their own ("smart_margin") to keep at least 2.
SMART_ISLAND_MARGIN = 0.02


def unwrap(objects, smart_margin=SMART_ISLAND_MARGIN):
    """Two shared atlases over all receivers: "Lightmap" (Lightmap Pack) and
    "LightmapSmart" (Smart UV Project)."""
    for obj in objects:
        obj.data.uv_layers.new(name="Lightmap")
        obj.data.uv_layers.new(name="LightmapSmart")
    select_only(objects)
    for obj in objects:
        obj.data.uv_layers.active = obj.data.uv_layers["Lightmap"]
    bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True, PREF_NEW_UVLAYER=False,
                             PREF_BOX_DIV=12, PREF_MARGIN_DIV=LIGHTMAP_PACK_MARGIN)
    for obj in objects:
        obj.data.uv_layers.active = obj.data.uv_layers["LightmapSmart"]
    bpy.ops.object.mode_set(mode="EDIT")  # multi-object edit: one shared atlas
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(angle_limit=math.radians(66), island_margin=smart_margin,
                             area_weight=0.0, correct_aspect=True, scale_to_bounds=False)
    bpy.ops.object.mode_set(mode="OBJECT")
    for obj in objects:
        obj.data.uv_layers.active = obj.data.uv_layers["Lightmap"]


def mesh_arrays(obj, with_uvs):
    mesh = obj.data
    mesh.calc_loop_triangles()
    mesh.calc_normals_split()
    matrix = obj.matrix_world
    positions = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", positions)
    positions = positions.reshape(-1, 3) @ np.array(matrix.to_3x3()).T.astype(np.float32) + np.array(matrix.translation)
    count = len(mesh.loop_triangles)
    triangles = np.empty(count * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    loops = np.empty(count * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    polygons = np.empty(count, np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", polygons)
    normals = np.empty(count * 9, np.float32)
    mesh.loop_triangles.foreach_get("split_normals", normals)
    normal_matrix = np.array(matrix.to_3x3().inverted().transposed(), np.float32)
    normals = normals.reshape(-1, 3) @ normal_matrix.T
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    result = {"positions": positions.astype(np.float32), "triangles": triangles.reshape(-1, 3),
              "normals": normals.astype(np.float32), "polygons": polygons, "polygon_count": len(mesh.polygons)}
    if with_uvs:
        for layer, key in (("Lightmap", "uv_lightmap"), ("LightmapSmart", "uv_smart")):
            uv = np.empty(len(mesh.loops) * 2, np.float32)
            mesh.uv_layers[layer].data.foreach_get("uv", uv)
            result[key] = uv.reshape(-1, 2)[loops]
    return result


def concatenate(parts, keys):
    out, offset, faces = {k: [] for k in keys}, 0, 0
    for part in parts:
        for key in keys:
            shift = offset if key == "triangles" else faces if key == "polygons" else None
            out[key].append(part[key] if shift is None else part[key] + shift)
        offset += len(part["positions"])
        faces += part.get("polygon_count", 0)
    return {k: (np.concatenate(v) if v else np.zeros((0, 3), np.float32 if k != "triangles" else np.int32))
            for k, v in out.items()}


def light_description(obj):
    """The add-on's light (Blender's properties and matrix_world, which places
    it for the baker), plus its world position and direction for readers."""
    kind, params = light_params(obj)
    rotation = obj.matrix_world.to_3x3().normalized()
    return {"name": obj.name, "kind": kind, **params, "position": list(obj.matrix_world.translation),
            "direction": list((rotation @ Vector((0, 0, -1))).normalized())}


def export(path, info):
    objects = receivers()
    occluders = [o for o in bpy.context.scene.objects if o.type == "MESH" and o not in objects]
    parts, colors, object_ids = [], [], []
    for index, obj in enumerate(objects):
        part = mesh_arrays(obj, with_uvs=True)
        parts.append(part)
        color = obj.data.materials[0].diffuse_color[:3]
        colors.append(np.tile(np.array(color, np.float32), (len(part["triangles"]), 1)))
        object_ids.append(np.full(len(part["triangles"]), index, np.int32))
    arrays = concatenate(parts, ("positions", "triangles", "normals", "uv_lightmap", "uv_smart", "polygons"))
    blockers = concatenate([mesh_arrays(o, with_uvs=False) for o in occluders], ("positions", "triangles"))
    name = os.path.splitext(os.path.basename(path))[0]
    SampleScene(
        name=name, description=" ".join(SCENES[name].__doc__.split()),
        positions=arrays["positions"], triangles=arrays["triangles"].astype(np.int32), normals=arrays["normals"],
        uvs={"lightmap": arrays["uv_lightmap"], "smart": arrays["uv_smart"]},
        base_color=np.concatenate(colors), object_id=np.concatenate(object_ids), objects=[obj.name for obj in objects],
        lights=[light_description(o) for o in bpy.context.scene.objects if o.type == "LIGHT"],
        world=world_color(bpy.context.scene), passes=tuple(info["passes"]),
        occluder_positions=blockers["positions"].astype(np.float32),
        occluder_triangles=blockers["triangles"].astype(np.int32), polygons=arrays["polygons"].astype(np.int32),
    ).save(path, occluders=[obj.name for obj in occluders],
           uv_variants={"lightmap": "Lightmap (Lightmap Pack)", "smart": "LightmapSmart (Smart UV Project)"},
           min_resolution=MIN_RESOLUTION)
    return len(arrays["triangles"]), len(blockers["triangles"])


def export_again(out_dir, name):
    """The .npz of a scene written again from its saved .blend (no rebuild, no
    new unwrap: the layouts stay the ones the .blend holds), for a field
    added to the file."""
    blend = os.path.join(out_dir, name + ".blend")
    with np.load(os.path.join(out_dir, name + ".npz")) as data:
        passes = json.loads(str(data["meta"]))["passes"]
    bpy.ops.wm.open_mainfile(filepath=blend)
    triangles, blockers = export(os.path.join(out_dir, name + ".npz"), {"passes": passes})
    print(f"{name}: {triangles} receiver triangles, {blockers} occluder triangles, exported again from {blend}")


def main():
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    again = "--export-only" in args
    args = [arg for arg in args if arg != "--export-only"]
    out_dir = os.path.abspath(args[0] if args else os.path.dirname(os.path.abspath(__file__)))
    names = args[1:] or list(SCENES)
    for name in names:
        if name not in SCENES:
            raise SystemExit(f"unknown scene '{name}'; known: {', '.join(SCENES)}")
        if again:
            export_again(out_dir, name)
            continue
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups
        info = SCENES[name]()
        unwrap(receivers(), info.get("smart_margin", SMART_ISLAND_MARGIN))
        blend = os.path.join(out_dir, name + ".blend")
        bpy.ops.wm.save_as_mainfile(filepath=blend, compress=True)
        triangles, blockers = export(os.path.join(out_dir, name + ".npz"), info)
        print(f"{name}: {triangles} receiver triangles, {blockers} occluder triangles -> {blend}, {name}.npz")


main()
