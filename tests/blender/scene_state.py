"""Digests of the scene parts the add-on may touch, to tell exactly what a run changed
(shared by the add-on checks and the add-on fuzz cases)."""

import hashlib

import bpy
import numpy as np


def _digest(*items):
    h = hashlib.sha256()
    for item in items:
        h.update(item.tobytes() if isinstance(item, np.ndarray) else repr(item).encode())
    return h.hexdigest()[:16]


def _array(collection, attribute, width, dtype=np.float32):
    values = np.empty(len(collection) * width, dtype=dtype)
    collection.foreach_get(attribute, values)
    return values


def fingerprint():
    """Digests of everything the add-on may touch, by part, so a failing test says which part changed."""
    parts = {}
    for mesh in bpy.data.meshes:
        layers = [(layer.name, layer.active, layer.active_render, _digest(_array(layer.data, "uv", 2)))
                  for layer in mesh.uv_layers]
        parts[f"mesh:{mesh.name}"] = _digest(
            _array(mesh.vertices, "co", 3), _array(mesh.loops, "vertex_index", 1, np.int32),
            _array(mesh.polygons, "loop_start", 1, np.int32), layers, mesh.uv_layers.active_index,
            [m.name if m else None for m in mesh.materials])
    for material in bpy.data.materials:
        tree = material.node_tree
        nodes = [(n.name, n.bl_idname, getattr(n, "image", None) and n.image.name, getattr(n, "uv_map", None),
                  getattr(n, "target", None), getattr(n, "is_active_output", None)) for n in tree.nodes] if tree else []
        links = [(l.from_node.name, l.to_node.name) for l in tree.links] if tree else []
        active = tree.nodes.active.name if tree and tree.nodes.active else None
        parts[f"material:{material.name}"] = _digest(nodes, links, active)
    parts["images"] = _digest(sorted(image.name for image in bpy.data.images))
    parts["materials"] = _digest(sorted(m.name for m in bpy.data.materials))
    view_layer = bpy.context.view_layer
    parts["selection"] = _digest(sorted(o.name for o in view_layer.objects if o.select_get()),
                                 view_layer.objects.active.name if view_layer.objects.active else None)
    scene = bpy.context.scene
    parts["render"] = _digest(scene.render.engine)
    parts["result"] = _digest(scene.lmrefine.result.valid, scene.lmrefine.result.message)
    return parts


def changed(before, after):
    return sorted(key for key in set(before) | set(after) if before.get(key) != after.get(key))
