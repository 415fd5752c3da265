"""Tessellation along light transitions, written into the object's mesh.

The splits come from the core (lmrefine.tessellate: which edges to bisect,
in which order); here they are replayed on the mesh with bmesh, so Blender
itself interpolates every attribute of the new vertex and its face corners:
positions, every UV map (seams included), vertex colours, custom
attributes. Each bisection puts the new vertex at the middle of the edge and
connects it to the opposite corner of every triangle on that edge, so the
split lies on the same surface.

The core splits triangles; a Blender face may be a quad or an n-gon, whose
triangles (the loop triangles, which the bakers see) are not faces. Faces
that a split touches are therefore first cut into their own loop triangles,
so every edge the core bisects is a real edge of the mesh.

The change is journalled: the untouched mesh is kept as a copy until the run
ends; a rollback puts it back in place of the tessellated one (bit for bit),
a commit deletes it.
"""

import bmesh
import bpy
import numpy as np


def problem(obj):
    """Why the object's mesh is not tessellated (the run refines it without splitting), as (reason, fix):
    the reason reads after "its" or "their" (no object named), the fix after "to split it, ". None when
    it can be split."""
    mesh = obj.data
    if len(obj.modifiers):
        names = ", ".join(modifier.name for modifier in obj.modifiers)
        return (f"modifiers ({names}), which would change the split mesh again",
                "apply or remove them (Object > Apply)")
    if obj.instance_type != 'NONE':
        return (f"instancing on its {obj.instance_type.lower()}, which would add instances at new vertices",
                "set Object Properties > Instancing to None")
    users = mesh.users - int(mesh.use_fake_user)
    if users > 1:
        return (f"mesh '{mesh.name}', shared with {users - 1} other object(s) (or a library override), which a "
                "split would change too", "make it single-user (Object > Relations > Make Single User > Object & "
                "Data)")
    if mesh.shape_keys is not None:
        return ("shape keys, of which a split would change the basis only",
                "apply or remove them (Object Data > Shape Keys)")
    return None


def unsplit_warnings(unsplit):
    """One warning per reason for the objects refined without splitting: `unsplit` [(object name, (reason,
    fix))], in run order."""
    by_reason = {}
    for name, why in unsplit:
        by_reason.setdefault(why, []).append(f"'{name}'")
    warnings = []
    for (reason, fix), names in by_reason.items():
        whose, them = ("its", "it") if len(names) == 1 else ("their", "them")
        listed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
        warnings.append(f"Not tessellated, refined without splitting: {listed} ({whose} {reason}): "
                        f"to split {them}, {fix}")
    return warnings


def mesh_arrays(mesh, layout):
    """What lmrefine.tessellate takes, from the mesh and its loop-triangle `layout`:
    (vertex positions (V, 3), triangles as vertex indices (T, 3), lightmap UVs per corner (3T, 2))."""
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", positions)
    loop_vertex = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", loop_vertex)
    return positions.reshape(-1, 3), loop_vertex[layout.triangles], layout.uvs[layout.triangles.ravel()]


def write(obj, result, journal):
    """Replay `result` (a lmrefine TessellationResult made from mesh_arrays of the
    object's current mesh) on the mesh; returns the number of vertices added."""
    mesh = obj.data
    splits = np.asarray(result.splits, np.int64)
    if len(splits) == 0:
        return 0
    mesh.calc_loop_triangles()
    triangle_face = np.empty(len(mesh.loop_triangles), dtype=np.int64)
    mesh.loop_triangles.foreach_get("polygon_index", triangle_face)
    triangle_vertices = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", triangle_vertices)
    triangle_vertices = triangle_vertices.reshape(-1, 3)
    vertex_count = len(mesh.vertices)

    backup = mesh.copy()  # every datablock setting and attribute, for an exact rollback
    backup.use_fake_user = False

    def restore():
        tessellated = obj.data
        name, fake_user = tessellated.name, tessellated.use_fake_user
        obj.data = backup
        bpy.data.meshes.remove(tessellated)
        backup.name = name
        backup.use_fake_user = fake_user

    journal.on_rollback(restore)
    journal.on_commit(lambda: bpy.data.meshes.remove(backup))

    bm = bmesh.new()
    try:
        bm.from_mesh(mesh)
        # Triangles that were split at all: each one's parent got an appended half.
        split_parents = np.unique(np.asarray(result.parent)[len(triangle_vertices):])
        _cut_into_loop_triangles(bm, np.unique(triangle_face[split_parents]), triangle_face, triangle_vertices)
        _replay(bm, splits, vertex_count)
        bm.verts.ensure_lookup_table()
        positions = np.array([bm.verts[i].co[:] for i in range(vertex_count, len(bm.verts))], dtype=np.float64)
        expected = np.asarray(result.positions, np.float64)[vertex_count:]
        scale = max(1.0, float(np.abs(expected).max()))
        if positions.shape != expected.shape or not np.allclose(positions, expected, rtol=0, atol=1e-5 * scale):
            raise RuntimeError(f"replaying the tessellation of '{obj.name}' gave {len(positions)} new vertices at "
                               f"other places than lmrefine.tessellate's {len(expected)}; this is a bug in "
                               "lmrefine, please report it with the .blend")
        bm.to_mesh(mesh)
    finally:
        bm.free()
    mesh.update()
    return len(mesh.vertices) - vertex_count


def _cut_into_loop_triangles(bm, faces, triangle_face, triangle_vertices):
    """Cut each of `faces` (polygon indices) into its loop triangles, by the
    triangles' diagonals: the core's triangles become faces of the mesh."""
    bm.faces.ensure_lookup_table()
    bm.verts.ensure_lookup_table()
    bm.verts.index_update()
    originals = [bm.faces[int(index)] for index in faces]
    for index, face in zip(faces, originals):
        if len(face.verts) == 3:
            continue
        ring = [vertex.index for vertex in face.verts]
        boundary = {frozenset(pair) for pair in zip(ring, ring[1:] + ring[:1])}
        pieces = [face]
        for corners in triangle_vertices[triangle_face == index].tolist():
            for a, b in ((corners[0], corners[1]), (corners[1], corners[2]), (corners[2], corners[0])):
                if frozenset((a, b)) in boundary:
                    continue
                boundary.add(frozenset((a, b)))  # each diagonal is cut once
                va, vb = bm.verts[a], bm.verts[b]
                piece = next((f for f in pieces if va in f.verts and vb in f.verts), None)
                if piece is None:
                    raise RuntimeError(f"face {index} has no piece holding its loop triangle's diagonal {a}-{b}")
                new_face, _ = bmesh.utils.face_split(piece, va, vb)
                pieces.append(new_face)


def _replay(bm, splits, vertex_count):
    """Each split (a, b, m): bisect edge a-b at its middle (the new vertex is
    m) and connect m to the opposite corner of every triangle on it."""
    bm.verts.ensure_lookup_table()
    verts = list(bm.verts)
    for a, b, m in splits.tolist():
        if m != len(verts):
            raise RuntimeError(f"split {a}-{b} makes vertex {m}, expected {len(verts)}")
        va, vb = verts[a], verts[b]
        edge = bm.edges.get((va, vb))
        if edge is None:
            raise RuntimeError(f"the tessellation bisects {a}-{b}, which is no edge of the mesh")
        opposite = []
        for face in edge.link_faces:
            if len(face.verts) != 3:
                raise RuntimeError(f"edge {a}-{b} borders a face of {len(face.verts)} corners, not a triangle")
            opposite.append((face, next(v for v in face.verts if v is not va and v is not vb)))
        _, vm = bmesh.utils.edge_split(edge, va, 0.5)
        verts.append(vm)
        for face, corner in opposite:
            bmesh.utils.face_split(face, vm, corner)
