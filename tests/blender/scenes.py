"""Small scenes the add-on tests build inside headless Blender (no .blend files checked in)."""

import bpy
import numpy as np


def reset():
    """An empty scene (factory startup has a cube, camera and light)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    return scene


def _material(name, color):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*color, 1.0)
    return material


def _set_lightmap_layer(mesh, name="Lightmap", margin=0.05):
    """A second UV map: the first map squeezed into [margin, 1 - margin] (one chart with a gutter)."""
    uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    mesh.uv_layers[0].data.foreach_get("uv", uvs)
    layer = mesh.uv_layers.new(name=name)
    layer.data.foreach_set("uv", margin + uvs * (1.0 - 2.0 * margin))
    return layer


def _set_face_charts_layer(mesh, name="Lightmap", columns=3, rows=2, margin=0.05):
    """A lightmap UV map with every (quad) face its own chart in a grid of cells, like Lightmap Pack."""
    uvs = np.zeros((len(mesh.loops), 2), dtype=np.float32)
    corners = np.array([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
    for index, polygon in enumerate(mesh.polygons):
        cell = np.array([index % columns, index // columns], dtype=np.float64)
        size = np.array([1.0 / columns, 1.0 / rows])
        quad = (cell + margin / size + corners * (1.0 - 2.0 * margin / size)) * size
        uvs[polygon.loop_start:polygon.loop_start + 4] = quad[:polygon.loop_total]
    layer = mesh.uv_layers.new(name=name)
    layer.data.foreach_set("uv", uvs.ravel())
    return layer


def shadow_scene():
    """A finely tessellated floor 'Floor' (UVMap + Lightmap), a box 'Blocker' above it, a sun.

    The box's Lightmap map has six charts (one per face) with gutters of
    6 texels at 64 x 64, like a Lightmap Pack.

    The box's shadow draws a hard edge across the floor: where a refinement
    should put more texels.
    """
    scene = reset()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=24, y_subdivisions=24, size=4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.name = "FloorMesh"
    _set_lightmap_layer(floor.data)
    floor.data.materials.append(_material("FloorMaterial", (0.8, 0.8, 0.8)))

    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.3, 0.2, 1.0))
    blocker = bpy.context.active_object
    blocker.name = "Blocker"
    _set_face_charts_layer(blocker.data)
    blocker.data.materials.append(_material("BlockerMaterial", (0.5, 0.5, 0.5)))

    bpy.ops.object.light_add(type='SUN', location=(0.0, 0.0, 5.0))
    sun = bpy.context.active_object
    sun.name = "Sun"
    sun.data.energy = 3.0
    sun.data.angle = 0.02
    sun.rotation_euler = (0.3, 0.2, 0.0)

    select_only(floor)
    return scene


def smoothed_suzanne():
    """Suzanne 'Monkey' above the shadow scene's floor, her 'Lightmap' map from Smart UV Project (angle
    45, margin 0.01: no triangle of it flips or overlaps), under a Subdivision Surface modifier whose UV
    Smooth (Keep Boundaries, Blender's default) folds that map where the bake reads it (9 flipped and
    10 overlapping of 3,936 triangles at level 1, at 64 x 64 texels)."""
    import math
    bpy.ops.mesh.primitive_monkey_add(location=(-0.8, -0.6, 0.8))
    monkey = bpy.context.active_object
    monkey.name = "Monkey"
    monkey.data.uv_layers.new(name="Lightmap")
    monkey.data.uv_layers.active = monkey.data.uv_layers["Lightmap"]
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.uv.smart_project(angle_limit=math.radians(45.0), island_margin=0.01)
    bpy.ops.object.mode_set(mode='OBJECT')
    monkey.modifiers.new("Subdivision", 'SUBSURF')
    return monkey


def select_only(*objects):
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in objects)
    bpy.context.view_layer.objects.active = objects[0] if objects else None


def degenerate_mesh():
    """A mesh 'Sliver' whose second face has zero area (three collinear vertices)."""
    mesh = bpy.data.meshes.new("SliverMesh")
    vertices = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (2, 0, 0), (3, 0, 0)]
    mesh.from_pydata(vertices, [], [(0, 1, 2), (1, 3, 4)])
    mesh.update()
    mesh.uv_layers.new(name="UVMap")
    layer = mesh.uv_layers.new(name="Lightmap")
    corners = np.array([(0.1, 0.1), (0.4, 0.1), (0.4, 0.4), (0.5, 0.5), (0.9, 0.5), (0.7, 0.9)], np.float32)
    layer.data.foreach_set("uv", corners.ravel())
    obj = bpy.data.objects.new("Sliver", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _mesh_object(name, vertices, faces, uvs=None):
    mesh = bpy.data.meshes.new(name + "Mesh")
    mesh.from_pydata(vertices, [], faces)
    mesh.update()
    if uvs is not None:
        layer = mesh.uv_layers.new(name="Lightmap")
        layer.data.foreach_set("uv", np.asarray(uvs, np.float32).ravel())
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def flat_mesh():
    """A mesh 'Flat' whose only face has zero area in 3-D (collinear vertices)."""
    return _mesh_object("Flat", [(0, 0, 0), (1, 0, 0), (2, 0, 0)], [(0, 1, 2)],
                        [(0.1, 0.1), (0.9, 0.1), (0.5, 0.9)])


def nan_mesh():
    """A mesh 'Broken': a triangle with one vertex at NaN."""
    return _mesh_object("Broken", [(0, 0, 0), (1, 0, 0), (float("nan"), 1, 0)], [(0, 1, 2)],
                        [(0.1, 0.1), (0.9, 0.1), (0.5, 0.9)])


def bare_mesh():
    """A mesh 'Bare' with no UV map at all."""
    mesh = bpy.data.meshes.new("BareMesh")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0)], [], [(0, 1, 2)])
    mesh.update()
    obj = bpy.data.objects.new("Bare", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def coarse_shadow_scene(quads=4):
    """shadow_scene with a coarse floor: quads x quads faces, each its own chart of the Lightmap map
    (seams everywhere, like Lightmap Pack), so the box's shadow edge crosses triangles of many texels.
    Besides UVMap and Lightmap, the floor has a corner colour attribute 'Tint' that, like UVMap, is
    a linear function of the position: tessellation must keep both so."""
    scene = shadow_scene()
    floor = bpy.data.objects["Floor"]
    old = floor.data
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=quads, y_subdivisions=quads, size=4.0)
    coarse = bpy.context.active_object
    mesh = coarse.data
    floor.data = mesh
    bpy.data.objects.remove(coarse)
    bpy.data.meshes.remove(old)
    mesh.name = "FloorMesh"
    _set_face_charts_layer(mesh, columns=quads, rows=quads)
    mesh.materials.append(bpy.data.materials["FloorMaterial"])
    positions = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", positions)
    loop_vertex = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loop_vertex)
    corner = positions.reshape(-1, 3)[loop_vertex]
    tint = mesh.color_attributes.new("Tint", 'FLOAT_COLOR', 'CORNER')
    colors = np.stack([0.5 + 0.1 * corner[:, 0], 0.5 - 0.05 * corner[:, 1], 0.25 + 0 * corner[:, 0],
                       np.ones(len(corner))], axis=1).astype(np.float32)
    tint.data.foreach_set("color", colors.ravel())
    select_only(floor)
    return scene


def _fit_layer(mesh, box, name="Lightmap"):
    """Squeeze UV map `name` of `mesh` into the rectangle box = (u0, v0, u1, v1). No mesh.update(), as
    a user's script may forget it: the add-on must bake the UVs it refines all the same."""
    layer = mesh.uv_layers[name]
    uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    layer.data.foreach_get("uv", uvs)
    uvs = uvs.reshape(-1, 2)
    low, high = uvs.min(axis=0), uvs.max(axis=0)
    corner, size = np.array(box[:2], np.float32), np.array(box[2:], np.float32) - np.array(box[:2], np.float32)
    layer.data.foreach_set("uv", (corner + (uvs - low) / (high - low) * size).ravel())


def floor_and_blocker_atlas():
    """coarse_shadow_scene's Floor and Blocker laid out in one atlas: the floor's map in the left half,
    the blocker's on the right. Returns (floor, blocker)."""
    floor, blocker = bpy.data.objects["Floor"], bpy.data.objects["Blocker"]
    _fit_layer(floor.data, (0.03, 0.03, 0.5, 0.97))
    _fit_layer(blocker.data, (0.55, 0.03, 0.97, 0.97))
    return floor, blocker


def atlas_scene():
    """shadow_scene plus a post 'Post' and a plate 'Lonely', all four with a 'Lightmap' map. Floor,
    Blocker and Post share one atlas, as one Lightmap Pack of the three would lay them out: the floor
    in the left half, the box's six charts top right, the post's bottom right, 3+ texels apart at 64^2.
    Lonely's map fills the square on its own (its own lightmap), overlapping theirs."""
    scene = shadow_scene()
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(-1.0, -0.8, 0.6))
    post = bpy.context.active_object
    post.name = "Post"
    post.scale = (1.0, 1.0, 3.0)
    _set_face_charts_layer(post.data)
    post.data.materials.append(_material("PostMaterial", (0.6, 0.6, 0.6)))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(1.4, -1.4, 0.3))
    lonely = bpy.context.active_object
    lonely.name = "Lonely"
    _set_lightmap_layer(lonely.data)
    lonely.data.materials.append(_material("LonelyMaterial", (0.7, 0.7, 0.7)))
    _fit_layer(bpy.data.objects["Floor"].data, (0.05, 0.05, 0.5, 0.95))
    _fit_layer(bpy.data.objects["Blocker"].data, (0.56, 0.53, 0.95, 0.95))
    _fit_layer(post.data, (0.56, 0.05, 0.95, 0.47))
    select_only(bpy.data.objects["Floor"], bpy.data.objects["Blocker"], post, lonely)
    return scene


def hilly_floor_scene(quads=12):
    """coarse_shadow_scene's floor made hilly (heights of 1.8 m over its 4 m, faces up to 52 degrees
    apart), quads x quads faces, each its own chart of the Lightmap map: the re-charting's angle would
    cut chart borders through quads' diagonals, which a UV map (one UV per loop) cannot hold."""
    scene = coarse_shadow_scene(quads)
    mesh = bpy.data.objects["Floor"].data
    positions = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", positions)
    positions = positions.reshape(-1, 3)
    positions[:, 2] = 0.9 * np.sin(1.5 * positions[:, 0]) * np.cos(positions[:, 1])
    mesh.vertices.foreach_set("co", positions.ravel())
    mesh.update()
    return scene


def roof_scene(quads=8):
    """A ridge roof 'Roof' (two slopes 90 degrees apart, quads x quads faces) under a sun that lights one
    slope more than the other, with a 'Lightmap' map that is one chart over the ridge, the roof unfolded
    (as Smart UV Project joins faces up to 66 degrees apart): a layout with room whose chart folds over
    a lit crease."""
    scene = reset()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=quads, y_subdivisions=quads, size=2.0)
    roof = bpy.context.active_object
    roof.name = "Roof"
    mesh = roof.data
    flat = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", flat)
    flat = flat.reshape(-1, 3)
    x = flat[:, 0] / np.sqrt(2.0)  # arc length along x stays the grid's: the unfolded chart keeps texel sizes
    mesh.vertices.foreach_set("co", np.column_stack([x, flat[:, 1], -np.abs(x)]).astype(np.float32).ravel())
    mesh.update()
    _set_lightmap_layer(mesh)
    mesh.materials.append(_material("RoofMaterial", (0.8, 0.8, 0.8)))
    sun = bpy.data.lights.new("Sun", 'SUN')
    sun.energy, sun.angle = 3.0, 0.01
    light = bpy.data.objects.new("Sun", sun)
    scene.collection.objects.link(light)
    light.rotation_euler = (0.0, -0.67, 0.0)  # from -x, 38 degrees off vertical: the -x slope faces it
    select_only(roof)
    return scene


def striped_scene(tile=2.0, quads=4):
    """Nine floor tiles in one object 'Tiles' (a Lightmap map with one island per tile, 3 x 3 like atlas
    cells), thin beams 'Beams' above the two back-left tiles and a sun straight above: the beams' shadows
    are stripes across x on those tiles, where a chart stretched across them gains texels."""
    import bmesh

    scene = reset()
    bm = bmesh.new()
    layer = bm.loops.layers.uv.new("Lightmap")
    for row in range(3):
        for column in range(3):
            x0, y0 = column * tile * 1.1, row * tile * 1.1
            grid = [[bm.verts.new((x0 + i * tile / quads, y0 + j * tile / quads, 0.0)) for i in range(quads + 1)]
                    for j in range(quads + 1)]
            for j in range(quads):
                for i in range(quads):
                    face = bm.faces.new((grid[j][i], grid[j][i + 1], grid[j + 1][i + 1], grid[j + 1][i]))
                    for loop in face.loops:
                        loop[layer].uv = (0.02 + column / 3 + (loop.vert.co.x - x0) / tile * 0.29,
                                          0.02 + row / 3 + (loop.vert.co.y - y0) / tile * 0.29)
    mesh = bpy.data.meshes.new("TilesMesh")
    bm.to_mesh(mesh)
    bm.free()
    tiles = bpy.data.objects.new("Tiles", mesh)
    scene.collection.objects.link(tiles)
    tiles.data.materials.append(_material("TilesMaterial", (0.8, 0.8, 0.8)))
    beams = bmesh.new()
    for k in range(10):  # 5 cm wide, 40 cm apart, along y over the back row's first two tiles
        bmesh.ops.create_cube(beams, size=1.0, matrix=_box_matrix((0.2 + 0.4 * k, 2 * tile * 1.1 + tile / 2, 1.0),
                                                                  (0.05, tile * 1.2, 0.05)))
    mesh = bpy.data.meshes.new("BeamsMesh")
    beams.to_mesh(mesh)
    beams.free()
    blocker = bpy.data.objects.new("Beams", mesh)
    scene.collection.objects.link(blocker)
    light = bpy.data.lights.new("Sun", 'SUN')  # straight down; made without operators, so any context will do
    light.energy, light.angle = 3.0, 0.01
    sun = bpy.data.objects.new("Sun", light)
    sun.location = (0.0, 0.0, 5.0)
    scene.collection.objects.link(sun)
    select_only(tiles)
    return scene


def _box_matrix(centre, size):
    from mathutils import Matrix

    return Matrix.Translation(centre) @ Matrix.Diagonal((*size, 1.0))
