"""Shader-node plumbing: finding a lightmap in a material, bake targets, preview.

Every node the add-on adds carries the custom property ``lmrefine_role`` (and
``lmrefine_object``: the object it belongs to), so it can be found and
removed again without guessing from names that the user may have changed.
"""

import bpy

from .errors import UserError

ROLE = "lmrefine_role"
OWNER = "lmrefine_object"
PREVIOUS_ACTIVE = "lmrefine_previous_active"  # on a preview image node: the active node it replaced


def _node_trees(obj):
    seen = set()
    for slot in obj.material_slots:
        material = slot.material
        if material is None or not material.use_nodes or material.node_tree is None:
            continue
        if material.name in seen:
            continue
        seen.add(material.name)
        yield material


def find_lightmap_image(obj, uv_name):
    """The image a material samples with UV map `uv_name`, else one named like a lightmap, else None."""
    by_name = None
    for material in _node_trees(obj):
        for node in material.node_tree.nodes:
            if node.type != 'TEX_IMAGE' or node.image is None or node.get(ROLE):
                continue
            vector = node.inputs["Vector"]
            if vector.is_linked:
                source = vector.links[0].from_node
                if source.type == 'UVMAP' and source.uv_map == uv_name:
                    return node.image
            label = f"{node.name} {node.label} {node.image.name}".lower()
            if by_name is None and "lightmap" in label:
                by_name = node.image
    return by_name


def image_problem(image):
    """Why an image cannot serve as a lightmap, or None if it can."""
    if image.source == 'FILE' and image.packed_file is None and not image.has_data:
        image.reload()  # a file image is read lazily; has_data is False until then
    width, height = image.size
    if width == 0 or height == 0:
        path = bpy.path.abspath(image.filepath) if image.filepath else "(no file path)"
        return (f"image '{image.name}' has no pixels (file {path} missing or unreadable): relink it in the "
                "Image Editor (Image > Replace), or bake the first lightmap with Embree or Cycles")
    return None


# --------------------------------------------------------------- bake target

class BakeTarget:
    """Temporarily make `image` the active Image Texture node of every material of `obj`.

    Cycles bakes into the active image node of each material. Objects without a
    material get a temporary one. Everything is undone on exit, success or not.
    """

    def __init__(self, obj, image):
        self.obj = obj
        self.image = image
        self.added_nodes = []  # (material, node, previous active node)
        self.temporary_material = None

    def __enter__(self):
        obj = self.obj
        if not any(slot.material is not None for slot in obj.material_slots):
            material = bpy.data.materials.new("lmrefine bake")
            material.use_nodes = True
            if len(obj.material_slots) == 0:
                obj.data.materials.append(material)
            else:
                obj.material_slots[0].material = material  # restored in __exit__
            self.temporary_material = material
        else:
            for slot in obj.material_slots:
                if slot.material is not None and not slot.material.use_nodes:
                    raise UserError(f"material '{slot.material.name}' of '{obj.name}' does not use nodes, "
                                     "which a Cycles bake needs: enable 'Use Nodes' or bake with Embree")
        for material in _node_trees(obj):
            nodes = material.node_tree.nodes
            previous = nodes.active
            node = nodes.new("ShaderNodeTexImage")
            node[ROLE] = "bake"
            node.image = self.image
            nodes.active = node
            self.added_nodes.append((material, node, previous))
        return self

    def __exit__(self, *exc):
        for material, node, previous in reversed(self.added_nodes):
            nodes = material.node_tree.nodes
            nodes.remove(node)
            if previous is not None:
                nodes.active = previous
        if self.temporary_material is not None:
            obj = self.obj
            if obj.material_slots and obj.material_slots[0].material == self.temporary_material:
                if len(obj.data.materials) == 1 and obj.data.materials[0] == self.temporary_material:
                    obj.data.materials.pop(index=0)
                else:
                    obj.material_slots[0].material = None
            bpy.data.materials.remove(self.temporary_material)
        return False


# ------------------------------------------------------------------ preview

def add_preview(obj, image, uv_name, journal):
    """Show `image` through a UV Map node set to `uv_name` in every material of `obj`.

    The image node becomes the material's active node, which is what Solid
    shading (Texture colour) and Texture Paint display. The material's shading
    itself is not rewired. Earlier preview nodes of this object are replaced.
    """
    remove_preview(obj, journal)
    for material in _node_trees(obj):
        nodes = material.node_tree.nodes
        previous = nodes.active
        uv_node = nodes.new("ShaderNodeUVMap")
        uv_node[ROLE], uv_node[OWNER] = "preview_uv", obj.name
        uv_node.uv_map = uv_name
        uv_node.label = "lmrefine UV"
        image_node = nodes.new("ShaderNodeTexImage")
        image_node[ROLE], image_node[OWNER] = "preview_image", obj.name
        image_node[PREVIOUS_ACTIVE] = previous.name if previous is not None else ""
        image_node.image = image
        image_node.label = "lmrefine lightmap"
        left = min((node.location.x for node in nodes if node not in (uv_node, image_node)), default=0.0)
        image_node.location = (left - 320.0, 300.0)
        uv_node.location = (left - 520.0, 300.0)
        material.node_tree.links.new(uv_node.outputs["UV"], image_node.inputs["Vector"])
        nodes.active = image_node
        journal.on_rollback(lambda tree=material.node_tree, a=uv_node.name, b=image_node.name, p=previous:
                            _remove_nodes(tree, (a, b), p))


def remove_preview(obj, journal=None):
    """Remove this object's preview nodes; returns how many were removed."""
    removed = 0
    for material in _node_trees(obj):
        tree = material.node_tree
        ours = [node for node in tree.nodes if node.get(ROLE, "").startswith("preview") and node.get(OWNER) == obj.name]
        if not ours:
            continue
        if journal is not None:
            journal.on_rollback(_recreate_preview_nodes(tree, ours))
        previous = next((node.get(PREVIOUS_ACTIVE) for node in ours if node.get(PREVIOUS_ACTIVE)), None)
        for node in ours:
            tree.nodes.remove(node)
            removed += 1
        if previous and previous in tree.nodes:
            tree.nodes.active = tree.nodes[previous]
    return removed


def _remove_nodes(tree, names, previous_active):
    for name in names:
        node = tree.nodes.get(name)
        if node is not None:
            tree.nodes.remove(node)
    if previous_active is not None:
        try:
            tree.nodes.active = previous_active
        except ReferenceError:
            pass


def _recreate_preview_nodes(tree, nodes):
    """A rollback action that puts removed preview nodes back as they were."""
    saved = []
    for node in nodes:
        saved.append({
            "bl_idname": node.bl_idname, "name": node.name, "label": node.label,
            "location": tuple(node.location), "role": node[ROLE], "owner": node[OWNER],
            "previous_active": node.get(PREVIOUS_ACTIVE), "active": tree.nodes.active == node,
            "image": getattr(node, "image", None), "uv_map": getattr(node, "uv_map", None),
        })

    def recreate():
        created = {}
        for item in saved:
            node = tree.nodes.new(item["bl_idname"])
            node.name, node.label, node.location = item["name"], item["label"], item["location"]
            node[ROLE], node[OWNER] = item["role"], item["owner"]
            if item["previous_active"] is not None:
                node[PREVIOUS_ACTIVE] = item["previous_active"]
            if item["image"] is not None:
                node.image = item["image"]
            if item["uv_map"] is not None:
                node.uv_map = item["uv_map"]
            created[item["role"]] = node
            if item["active"]:
                tree.nodes.active = node
        if "preview_uv" in created and "preview_image" in created:
            tree.links.new(created["preview_uv"].outputs["UV"], created["preview_image"].inputs["Vector"])

    return recreate
