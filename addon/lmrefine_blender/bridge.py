"""bpy <-> numpy: what the native core needs from a Blender scene, and back.

Nothing here decides anything about the method; it converts. Conventions:

* Layouts are per-loop (Blender's "face corner") UVs (L, 2) float32 and loop
  triangles (T, 3) int32 indices into them, so a refined layout maps back onto
  the same loops of the same UV map.
* Geometry for the baker is per loop as well: positions (L, 3) and split
  normals (L, 3) in world space, indexed by the same loop triangles, so the
  baker sees exactly the UVs, normals and faces Blender renders.
* Images are (H, W, 4) float32, row 0 at the top (v = 1); Blender's
  Image.pixels is bottom-up, so rows are flipped here and nowhere else.
"""

import re
from dataclasses import dataclass

import bpy
import numpy as np

from .errors import UserError

# Geometry that can become a mesh and so can cast shadows.
GEOMETRY_TYPES = {'MESH', 'CURVE', 'SURFACE', 'META', 'FONT'}

DEFAULT_BASE_COLOR = (0.8, 0.8, 0.8)


@dataclass
class Layout:
    """A UV layout of one mesh, as refine_uvs takes it."""

    uvs: np.ndarray  # (L, 2) float32, per loop
    triangles: np.ndarray  # (T, 3) int32, loop indices
    positions: np.ndarray = None  # (L, 3) float64, per loop, world space: the mesh for refine_uvs' re-chart route
    normals: np.ndarray = None  # (L, 3) float32, per loop, split normals in world space: where it is smooth-shaded


@dataclass
class MeshExport:
    """One evaluated mesh in world space, ready for lmrefine.Scene.add_mesh."""

    name: str
    positions: np.ndarray  # (L, 3) float32, per loop
    normals: np.ndarray  # (L, 3) float32, split normals
    triangles: np.ndarray  # (T, 3) int32, loop indices
    uvs: np.ndarray | None  # (L, 2) float32 from the requested UV map, or None
    base_color: np.ndarray  # (T, 3) float32, the material's base colour per triangle
    polygons: np.ndarray | None = None  # (T,) int32, the face each triangle belongs to


# ---------------------------------------------------------------- UV layouts

def default_source_layer(mesh):
    """The lightmap UV map a user most likely means, or None if there is none.

    A map named like "Lightmap"/"LM"/"UVMap.001" wins; else the second map
    (the first is by convention the texture UVs); a single map is used as is.
    """
    # The add-on's own output maps (`<source>_refined`, and a per-effect run's `<source>_refined_<effect>`)
    # are never a source: refining a refined map takes texels from the light changes it gave them.
    names = [layer.name for layer in mesh.uv_layers if not re.search(r"_refined(_[a-z]+)?$", layer.name)]
    for name in names:
        lowered = name.lower()
        if "lightmap" in lowered or lowered in {"lm", "uvmap.001", "uv2", "uvmap2"}:
            return name
    if len(names) >= 2:
        return names[1]
    return names[0] if names else None


def read_layout(mesh, uv_name, matrix_world=None):
    """The loop UVs of `uv_name` and the loop triangles of an (original) mesh, welded,
    and each loop's position and split normal (times `matrix_world`, when given).

    Blender stores one UV per face corner, and corners of one vertex that a
    user sees as connected often differ in the last bits (even in Blender's
    own primitives). lmrefine joins charts by bit-identical UVs, so such a
    layout would read as many charts touching each other. Corners of the same
    vertex within Blender's connect limit therefore get one UV, and UVs a
    rounding error outside [0, 1] are clamped. The refined map is computed
    from this welded layout; the source map is never written (the rule:
    lmrefine.layout_input.weld_uvs).
    """
    from lmrefine.layout_input import weld_uvs  # here: the add-on registers even without the core
    mesh.calc_loop_triangles()
    triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", triangles)
    uvs = read_uv_layer(mesh, uv_name)
    loop_vertex = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loop_vertex)
    vertices = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", vertices)
    vertices = vertices.reshape(-1, 3).astype(np.float64)
    normals = loop_normals(mesh)
    if matrix_world is not None:
        matrix = np.array(matrix_world, dtype=np.float64)
        vertices = vertices @ matrix[:3, :3].T + matrix[:3, 3]
        with np.errstate(all="ignore"):  # a zero scale: the normals are not finite, their edges count as hard
            normals = (normals.astype(np.float64) @ np.linalg.pinv(matrix[:3, :3])).astype(np.float32)
    return Layout(weld_uvs(uvs, loop_vertex), triangles.reshape(-1, 3), vertices[loop_vertex], normals)


def loop_normals(mesh):
    """The split (shading) normal of each loop (L, 3) float32, as the mesh is
    shaded: face normals where it is flat, vertex normals where smooth, and
    Auto Smooth's sharp edges and custom normals as set. The temporary
    normals layer is freed again: the mesh is left as it was."""
    mesh.calc_normals_split()
    normals = np.empty(len(mesh.loops) * 3, dtype=np.float32)
    mesh.loops.foreach_get("normal", normals)
    mesh.free_normals_split()
    return normals.reshape(-1, 3)


def read_uv_layer(mesh, uv_name):
    uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    mesh.uv_layers[uv_name].data.foreach_get("uv", uvs)
    return uvs.reshape(-1, 2)


def write_uv_layer(mesh, uv_name, uvs):
    """Create (or overwrite) UV map `uv_name` with per-loop `uvs` (L, 2)."""
    uvs = np.ascontiguousarray(uvs, dtype=np.float32)
    if uvs.shape != (len(mesh.loops), 2):
        raise ValueError(f"refined UVs have shape {uvs.shape}, mesh '{mesh.name}' has {len(mesh.loops)} loops")
    layer = mesh.uv_layers.get(uv_name) or mesh.uv_layers.new(name=uv_name, do_init=False)
    if layer is None:  # Blender refuses a 9th UV map
        raise UserError(f"mesh '{mesh.name}' already has the maximum of 8 UV maps: remove one to make room "
                         f"for '{uv_name}'")
    layer.data.foreach_set("uv", uvs.ravel())
    mesh.update()
    return layer


def inside_out_shells(mesh):
    """lmrefine.layout_input.inside_out_shells of an (original) mesh, in its own space."""
    from lmrefine.layout_input import inside_out_shells
    mesh.calc_loop_triangles()
    triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", positions)
    return inside_out_shells(positions.reshape(-1, 3), triangles.reshape(-1, 3))


def geometry_problems(obj, layout, resolution):
    """lmrefine.layout_input.geometry_problems of `obj` (world space, as baked)."""
    from lmrefine.layout_input import geometry_problems
    mesh = obj.data
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", positions)
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    with np.errstate(all="ignore"):
        world = positions.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
    corner_vertex = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", corner_vertex)
    return geometry_problems(world, corner_vertex, layout.uvs, layout.triangles, resolution)


# ----------------------------------------------------------------- geometry

def _material_base_color(material):
    if material is None:
        return DEFAULT_BASE_COLOR
    if material.use_nodes and material.node_tree is not None:
        output = material.node_tree.get_output_node('CYCLES')
        surface = output.inputs["Surface"] if output is not None else None
        if surface is not None and surface.is_linked:
            shader = surface.links[0].from_node
            color = shader.inputs.get("Base Color") or shader.inputs.get("Color")
            if color is not None:
                # A texture in the colour slot is not sampled: its constant is used.
                return tuple(color.default_value[:3])
    return tuple(material.diffuse_color[:3])


def export_mesh(obj_eval, matrix_world, uv_name=None, name=None):
    """An evaluated object (modifiers applied) as world-space per-loop arrays.

    None when there is nothing to bake or to cast a shadow: no faces, or a
    transform that flattens them (a zero scale).
    """
    matrix = np.array(matrix_world, dtype=np.float64)
    linear = matrix[:3, :3]
    if abs(np.linalg.det(linear)) < 1e-12:
        return None
    mesh = obj_eval.to_mesh()
    try:
        if mesh is None or len(mesh.polygons) == 0:
            return None
        mesh.calc_loop_triangles()
        mesh.calc_normals_split()
        loop_count = len(mesh.loops)
        triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("loops", triangles)
        material_index = np.empty(len(mesh.loop_triangles), dtype=np.int32)
        mesh.loop_triangles.foreach_get("material_index", material_index)
        polygons = np.empty(len(mesh.loop_triangles), dtype=np.int32)
        mesh.loop_triangles.foreach_get("polygon_index", polygons)

        vertex_co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", vertex_co)
        loop_vertex = np.empty(loop_count, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vertex)
        normals = np.empty(loop_count * 3, dtype=np.float32)
        mesh.loops.foreach_get("normal", normals)

        positions = vertex_co.reshape(-1, 3)[loop_vertex] @ linear.T + matrix[:3, 3]
        # Normals transform with the inverse transpose (non-uniform scale).
        normals = normals.reshape(-1, 3) @ np.linalg.inv(linear)
        lengths = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = normals / np.where(lengths > 0.0, lengths, 1.0)

        uvs = None
        if uv_name is not None:
            layer = mesh.uv_layers.get(uv_name)
            if layer is None:
                raise UserError(f"object '{obj_eval.name}' loses UV map '{uv_name}' in its modifier stack: "
                                 "move the modifier that drops it, or apply it")
            uvs = np.empty(loop_count * 2, dtype=np.float32)
            layer.data.foreach_get("uv", uvs)
            uvs = uvs.reshape(-1, 2)

        palette = [_material_base_color(slot.material) for slot in obj_eval.material_slots] or [DEFAULT_BASE_COLOR]
        palette = np.asarray(palette, dtype=np.float32)
        base_color = palette[np.clip(material_index, 0, len(palette) - 1)]

        return MeshExport(
            name=name or obj_eval.name,
            positions=np.ascontiguousarray(positions, dtype=np.float32),
            normals=np.ascontiguousarray(normals, dtype=np.float32),
            triangles=triangles.reshape(-1, 3),
            uvs=uvs,
            base_color=base_color,
            polygons=polygons,
        )
    finally:
        obj_eval.to_mesh_clear()


def faceless_problem(obj, obj_eval, matrix_world=None):
    """Why mesh object `obj` (evaluated: `obj_eval`, placed by `matrix_world`,
    default its own) has no face to bake, naming the fix: a mesh without
    faces, a zero scale, or modifiers that remove every face (the cases
    export_mesh returns None for); None when it has faces to bake."""
    mesh = obj.data
    if len(mesh.vertices) == 0:
        return f"'{obj.name}' is an empty mesh (no vertices): there is nothing to lightmap"
    if len(mesh.polygons) == 0:
        return (f"'{obj.name}' is a mesh without faces ({len(mesh.vertices)} vertices, {len(mesh.edges)} edges): "
                "a lightmap needs faces: fill them in (Edit Mode > Face > Fill)")
    matrix = np.array(obj_eval.matrix_world if matrix_world is None else matrix_world, dtype=np.float64)
    if abs(np.linalg.det(matrix[:3, :3])) < 1e-12:
        return (f"'{obj.name}' has a zero scale, so its faces have no area: give it a non-zero scale "
                "(Object Properties > Transform)")
    if len(obj_eval.data.polygons):  # the evaluated mesh: its modifiers applied
        return None
    removing = [m.name for m in obj.modifiers if m.show_render]
    which = f"its modifiers ({', '.join(removing)})" if removing else "its modifiers"
    return f"'{obj.name}': {which} remove every face: disable the modifier that removes them"


def evaluated_problem(depsgraph, obj, uv_name, layout, resolution):
    """What keeps `obj`, as its modifiers and transform make it, from being
    baked (a message naming the fix), or None. The bake exports the same.
    `layout` is the source map before the modifiers (read_layout)."""
    from lmrefine.layout_input import MAX_COORDINATE
    obj_eval = obj.evaluated_get(depsgraph)
    try:
        export = export_mesh(obj_eval, obj_eval.matrix_world, uv_name=uv_name, name=obj.name)
    except UserError as error:
        return str(error)
    if export is None:
        return faceless_problem(obj, obj_eval)
    if not (np.abs(export.positions) <= MAX_COORDINATE).all():
        return (f"'{obj.name}' has vertices at NaN, Inf or beyond 1e9 units after its modifiers and transform: "
                "disable the modifier that puts them there, or check the object's scale")
    if not np.isfinite(export.uvs).all():
        return (f"'{obj.name}' has NaN or Inf UVs in '{uv_name}' after its modifiers: disable the modifier that "
                "makes them, or re-unwrap")
    return copied_faces_problem(obj, uv_name, layout, export, resolution)


def copied_faces_problem(obj, uv_name, layout, export, resolution):
    """A message naming the fix when `obj`'s modifiers copy faces with their
    UVs (an Array, a Mirror), so that copies of UV map `uv_name` lie on top
    of each other at `resolution`, else None. `layout` is the map before the
    modifiers (read_layout), `export` the object as the bake exports it."""
    import lmrefine
    from lmrefine.layout_input import COPYING_MODIFIERS, copied_overlap
    # Unchanged by modifiers up to the weld (read_layout moves a UV by at most the connect limit): no copies.
    if export.uvs.shape == layout.uvs.shape and np.allclose(export.uvs, layout.uvs, rtol=0.0, atol=1e-4):
        return None
    copied = copied_overlap(lmrefine.check_layout(layout.uvs, layout.triangles, resolution), len(layout.triangles),
                            lmrefine.check_layout(export.uvs, export.triangles, resolution), len(export.triangles))
    if not copied:
        return None
    # A lightmap texel holds the light of one place: copies sharing their UVs share their light.
    copying = [m.name for m in obj.modifiers if m.type in COPYING_MODIFIERS and m.show_render]
    which = f"modifiers ({', '.join(copying)})" if copying else "modifiers"
    return (f"'{obj.name}': its {which} copy faces with their UVs, so {copied} triangles of UV map "
            f"'{uv_name}' lie on top of others and would share one lightmap: apply the modifiers (Object > "
            "Apply > Visual Geometry to Mesh), then unwrap the map again (UV > Lightmap Pack) so every "
            "copy has texels of its own")


# Modifiers that can move a UV map's UVs without copying faces, and the setting that stops it where
# there is one: a subdivision smooths UVs inside the islands unless its UV Smooth is None.
UV_SMOOTHING = {'SUBSURF': "Subdivision Surface", 'MULTIRES': "Multiresolution"}
# The share of a map's triangles folded (flipped or overlapping) where the bake reads it that is worth a
# warning: a subdivision flips a piece or two of a quad whose UVs are not convex even without smoothing
# (2 of Suzanne's 3,936 at UV Smooth None), and only applying it helps there.
FOLDED_SHARE = 0.001


def modifier_folds_problem(depsgraph, obj, uv_name, resolution):
    """A message naming the fix when `obj`'s modifiers fold UV map `uv_name` where the bake reads it,
    else None: more than FOLDED_SHARE of its evaluated triangles flip or overlap (check_layout at
    `resolution`), and more than twice the share of the map's own on the mesh, which is what was
    refined (a Subdivision Surface's UV smoothing draws the UVs inside an island together, and a
    warp's small triangles fold over)."""
    import lmrefine
    if not any(m.show_render and m.show_viewport for m in obj.modifiers):
        return None
    layout = read_layout(obj.data, uv_name)
    obj_eval = obj.evaluated_get(depsgraph)
    try:
        export = export_mesh(obj_eval, obj_eval.matrix_world, uv_name=uv_name, name=obj.name)
    except UserError:  # a map the modifiers drop: the bake says so
        return None
    if export is None or len(layout.triangles) == 0:
        return None
    if export.uvs.shape == layout.uvs.shape and np.allclose(export.uvs, layout.uvs, rtol=0.0, atol=1e-4):
        return None
    own = lmrefine.check_layout(layout.uvs, layout.triangles, resolution)
    baked = lmrefine.check_layout(export.uvs, export.triangles, resolution)
    folded, own_folded = baked["flipped"] + baked["overlapping"], own["flipped"] + own["overlapping"]
    if (folded <= FOLDED_SHARE * len(export.triangles)
            or folded * len(layout.triangles) <= 2 * own_folded * len(export.triangles)):
        return None
    found = (f"where the bake reads UV map '{uv_name}', {baked['overlapping']} of its {len(export.triangles)} "
             f"triangles overlap and {baked['flipped']} flip (the map on the mesh: {own['overlapping']} and "
             f"{own['flipped']} of {len(layout.triangles)}): light bleeds there")
    smoothing = [m for m in obj.modifiers if m.type in UV_SMOOTHING and m.show_render and m.uv_smooth != 'NONE']
    if smoothing:
        modifier = smoothing[0]
        kind = UV_SMOOTHING[modifier.type]
        label = modifier.bl_rna.properties["uv_smooth"].enum_items[modifier.uv_smooth].name
        return (f"'{obj.name}': its {kind} modifier '{modifier.name}' smooths the UVs (UV Smooth: {label}), so "
                f"{found}; set its UV Smooth to None (Modifier Properties > {modifier.name} > Advanced), so that "
                "the bake reads the map as it was refined, and run again")
    names = ", ".join(m.name for m in obj.modifiers if m.show_render)
    return (f"'{obj.name}': its modifiers ({names}) move the UVs, so {found}; apply them (Object > Apply > Visual "
            "Geometry to Mesh) and run again")


def renders(obj):
    """Whether a (non-instanced) object takes part in a bake: visible and enabled for render."""
    return obj.visible_get() and not obj.hide_render


def export_scene(context, receivers, uv_name_of, left_out=None):
    """Receivers (with the UV map `uv_name_of[obj.name]`) and occluders of the scene.

    Returns (receiver exports in `receivers` order, occluder exports): every
    other visible, render-enabled geometry, instances included, casts shadows.
    An occluder with a vertex at NaN, Inf or beyond 1e9 units (which the baker
    refuses) is left out and its name appended to `left_out`; a receiver
    like that is a UserError.
    """
    from lmrefine.layout_input import MAX_COORDINATE
    depsgraph = context.evaluated_depsgraph_get()
    receiver_names = {obj.name for obj in receivers}
    by_name = {}
    occluders = []
    for instance in depsgraph.object_instances:
        obj_eval = instance.object
        if obj_eval.type not in GEOMETRY_TYPES:
            continue
        original = obj_eval.original
        if not instance.is_instance and original.name in receiver_names:
            export = export_mesh(obj_eval, instance.matrix_world, uv_name=uv_name_of[original.name],
                                 name=original.name)
            if export is None:
                raise UserError(faceless_problem(original, obj_eval, instance.matrix_world))
            if not (np.abs(export.positions) <= MAX_COORDINATE).all():
                raise UserError(f"'{original.name}' has vertices at NaN, Inf or beyond 1e9 units after its "
                                "modifiers and transform: disable the modifier that puts them there")
            by_name[original.name] = export
            continue
        if instance.is_instance:
            if instance.parent is None or not renders(instance.parent.original):
                continue
        elif not renders(original):
            continue
        export = export_mesh(obj_eval, instance.matrix_world, name=original.name)
        if export is None:
            continue
        if not (np.abs(export.positions) <= MAX_COORDINATE).all():
            if left_out is not None and original.name not in left_out:
                left_out.append(original.name)
            continue
        occluders.append(export)
    missing = receiver_names - by_name.keys()
    if missing:
        raise UserError(f"objects {sorted(missing)} are not in the evaluated scene: make them visible in "
                         "the view layer")
    return [by_name[obj.name] for obj in receivers], occluders


# ------------------------------------------------------------------- lights

def light_params(obj):
    """A Blender light object as (kind, params) in Blender's own names and units.

    The light is placed by its world matrix (rows, as lmrefine.Scene.add_light's
    `matrix` takes it), which the baker reads as Cycles does: position, where
    it points (-Z), its spin (+X), and an area light's size stretched by the
    object's scale. Sizes stay Blender's unscaled properties."""
    light = obj.data
    params = {
        "energy": float(light.energy),
        "color": tuple(float(c) for c in light.color),
        "matrix": tuple(tuple(float(c) for c in row) for row in obj.matrix_world),
    }
    kind = light.type
    if kind == 'POINT':
        params["shadow_soft_size"] = float(light.shadow_soft_size)
    elif kind == 'SPOT':
        params["shadow_soft_size"] = float(light.shadow_soft_size)
        params["spot_size"] = float(light.spot_size)
        params["spot_blend"] = float(light.spot_blend)
    elif kind == 'SUN':
        params["angle"] = float(light.angle)
    elif kind == 'AREA':
        params["shape"] = light.shape  # SQUARE, RECTANGLE, DISK or ELLIPSE, as the baker takes them
        params["size"] = float(light.size)
        params["size_y"] = float(light.size_y)
    else:
        raise UserError(f"light '{obj.name}' has unknown type {kind}: delete it or change its type")
    return kind.lower(), params


def scene_lights(context, named=False):
    """Every visible, render-enabled light with non-zero energy, as (kind,
    params), or (object, (kind, params)) when `named`."""
    lights = [obj for obj in context.scene.objects if obj.type == 'LIGHT' and renders(obj) and obj.data.energy > 0.0]
    return [(obj, light_params(obj)) if named else light_params(obj) for obj in lights]


def world_color(scene):
    """The uniform world colour (Background colour x strength), black without a world."""
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0)
    if world.use_nodes and world.node_tree is not None:
        output = world.node_tree.get_output_node('CYCLES')
        surface = output.inputs["Surface"] if output is not None else None
        if surface is not None and surface.is_linked:
            node = surface.links[0].from_node
            if node.type == 'BACKGROUND':
                strength = node.inputs["Strength"].default_value
                return tuple(float(c) * strength for c in node.inputs["Color"].default_value[:3])
        return (0.0, 0.0, 0.0)
    return tuple(float(c) for c in world.color)


# ------------------------------------------------------------------- images

def image_to_array(image):
    """Image pixels as (H, W, 4) float32, row 0 at the top."""
    width, height = image.size
    pixels = np.empty(width * height * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return np.ascontiguousarray(pixels.reshape(height, width, 4)[::-1])


def array_to_image(image, array):
    """Write (H, W, 4) top-down float32 `array` into `image` (resized to fit)."""
    height, width = array.shape[:2]
    if tuple(image.size) != (width, height):
        image.scale(width, height)
    pixels = np.ascontiguousarray(array[::-1], dtype=np.float32)
    image.pixels.foreach_set(pixels.ravel())
    image.update()


def new_float_image(name, resolution):
    """A linear float RGBA image (HDR lightmaps need more than 8 bits)."""
    return bpy.data.images.new(name, resolution, resolution, alpha=True, float_buffer=True)
