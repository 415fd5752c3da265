"""Shader-node plumbing: finding a lightmap in a material, bake targets, preview.

Every node the add-on adds carries the custom property ``lmrefine_role`` (and
``lmrefine_object``: the object it belongs to), so it can be found and
removed again without guessing from names that the user may have changed.
"""

import contextlib

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


def _pop_only_material(mesh):
    """Remove the mesh's only material. materials.pop() would leave the objects one empty slot
    (their slot count is not updated); clear() updates it."""
    mesh.materials.clear()


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
                    _pop_only_material(obj.data)
                else:
                    obj.material_slots[0].material = None
            bpy.data.materials.remove(self.temporary_material)
        return False


# ------------------------------------------------------------------ preview
#
# The preview shows a lightmap on the object in every viewport mode and puts
# back exactly what it changed when it is removed:
#
# * in each node material it adds a UV Map node (naming the map the image was
#   baked with), an Image Texture node, an Emission shader and its own Material
#   Output, made the tree's active output. Material Preview (EEVEE) and
#   Rendered (Cycles) draw the output Blender picks for their engine: an
#   output set to that engine beats an 'All' one even when inactive, so the
#   user's engine-specific outputs are set to 'All' while the preview is on.
#   The user's nodes and links are not otherwise touched; which output and
#   node were active and the outputs' targets are recorded and put back;
# * the image node becomes the material's active node and the shown UV map the
#   mesh's active UV map: Solid shading with Texture colour (and Texture Paint)
#   draws the active image node through the active UV map;
# * an object without any material gets a material the preview owns.
#
# A material shared by several objects holds one set of preview nodes per
# object; the last one added is shown, and removing one shows the next.
# The before/after toggle only swaps the image and the UV map of the
# preview's own nodes (and the active UV map).
#
# A per-effect run (Layouts: Per Effect) shows several terms: one UV Map and
# Image Texture node per effect, each image sampled through its own UV map,
# added up (Vector Math Add) into the one Emission: direct + indirect is the
# combined light. Solid shading draws one image through one UV map, so there
# the first term (direct) is shown. The state keeps the terms' image and UV
# names joined by TERM_SEPARATOR.

PREVIEW = "lmrefine_preview"  # on the object: what the preview shows and what it replaced
PREVIOUS_OUTPUTS = "lmrefine_previous_outputs"  # on a preview image node: the output that was active
PREVIOUS_TARGETS = "lmrefine_previous_targets"  # on a preview image node: {output name: target} changed to 'All'
OWNED_MATERIAL = "lmrefine preview"
TERM = "lmrefine_term"  # on a preview UV or image node: which term (effect) it samples, from 0
TERM_SEPARATOR = "\n"  # image and UV names never hold a newline
NODE_NAMES = {  # explicit names: a preview put back by a rollback gets the same ones
    "preview_uv": "lmrefine UV", "preview_image": "lmrefine Lightmap", "preview_emission": "lmrefine Emission",
    "preview_output": "lmrefine Output", "preview_add": "lmrefine Add",
}


def has_preview(obj):
    return obj.get(PREVIEW) is not None


def preview_shown(obj):
    """'AFTER' (refined map), 'BEFORE' (source map), or None without a preview."""
    state = obj.get(PREVIEW)
    return None if state is None else state.get("shown", "AFTER")


def add_preview(obj, after_image, after_uv, before_image, before_uv, journal, shown='AFTER'):
    """Show the lightmap on `obj` in every viewport mode; see the section comment.

    `after_image` is the lightmap baked with UV map `after_uv` (the refined
    map), `before_image` the first lightmap, baked with the source map
    `before_uv` (None: no before/after toggle). An earlier preview of this
    object is replaced; the journal puts it back on rollback.
    """
    remove_preview(obj, journal)
    _apply_preview(obj, after_image.name, after_uv, before_image.name if before_image else "", before_uv or "",
                   shown)
    journal.on_rollback(lambda: remove_preview(obj))


def add_terms_preview(obj, after_images, after_uvs, before_images, before_uvs, journal, shown='AFTER'):
    """Like add_preview, for a light that is the sum of terms (the effects of a per-effect run): each
    after image sampled through its UV map, all added; `before_images` (baked with `before_uvs`, or
    None: no toggle) are added the same way."""
    remove_preview(obj, journal)
    before = TERM_SEPARATOR.join(image.name for image in before_images) if before_images else ""
    _apply_preview(obj, TERM_SEPARATOR.join(image.name for image in after_images), TERM_SEPARATOR.join(after_uvs),
                   before, TERM_SEPARATOR.join(before_uvs) if before_images else "", shown)
    journal.on_rollback(lambda: remove_preview(obj))


@contextlib.contextmanager
def previews_hidden(objects):
    """The previews of `objects` taken off while a bake reads the scene's
    materials, and put back as they were: a preview's Emission would be read
    as the surface's colour by lmrefine's baker and would shine as a light
    (or hide the surface) in a Cycles bake."""
    hidden = [(obj, _preview_params(obj)) for obj in objects
              if obj.type == 'MESH' and obj.library is None and has_preview(obj)]
    for obj, _ in hidden:
        remove_preview(obj)
    try:
        yield
    finally:
        for obj, params in hidden:
            if not has_preview(obj):
                _apply_preview(obj, **params)


def preview_terms(obj):
    """{"after": [(image name, UV map)...], "before": [...]} of the preview of `obj` (one pair per term)."""
    state = obj.get(PREVIEW) or {}
    return {key: list(zip(state.get(f"{key}_image", "").split(TERM_SEPARATOR),
                          state.get(f"{key}_uv", "").split(TERM_SEPARATOR))) if state.get(f"{key}_image") else []
            for key in ("after", "before")}


def _preview_params(obj):
    state = obj.get(PREVIEW)
    if state is None:
        return None
    return {key: state.get(key, "") for key in ("after_image", "after_uv", "before_image", "before_uv", "shown")}


def _apply_preview(obj, after_image, after_uv, before_image, before_uv, shown):
    mesh = obj.data
    state = {"after_image": after_image, "after_uv": after_uv, "before_image": before_image,
             "before_uv": before_uv, "shown": shown, "previous_uv": mesh.uv_layers.active.name
             if mesh.uv_layers.active is not None else "", "owned_material": 0}
    if not any(slot.material is not None for slot in obj.material_slots):
        material = bpy.data.materials.new(OWNED_MATERIAL)
        material.use_nodes = True
        material[ROLE], material[OWNER] = "preview_material", obj.name
        if len(obj.material_slots) == 0:
            mesh.materials.append(material)
            state["owned_material"] = 1  # appended: removal pops it
        else:
            obj.material_slots[0].material = material
            state["owned_material"] = 2  # filled the empty first slot: removal empties it
    obj[PREVIEW] = state
    terms = len(after_image.split(TERM_SEPARATOR))
    for material in _node_trees(obj):
        _add_preview_nodes(material.node_tree, obj.name, terms)
    _show(obj, shown)


def _add_preview_nodes(tree, owner, terms=1):
    nodes = tree.nodes
    others = [node for node in nodes if node.get(ROLE) == "preview_image" and node.get(OWNER) != owner]
    if others:  # a shared material: what the first preview replaced is what this one replaces
        previous_active = others[0].get(PREVIOUS_ACTIVE, "")
        previous_output = others[0].get(PREVIOUS_OUTPUTS, "")
        previous_targets = _plain_dict(others[0].get(PREVIOUS_TARGETS))
    else:
        previous_active = nodes.active.name if nodes.active is not None else ""
        outputs = [node for node in nodes if node.type == 'OUTPUT_MATERIAL']
        previous_output = next((node.name for node in outputs if node.is_active_output), "")
        previous_targets = {node.name: node.target for node in outputs if node.target != 'ALL'}
        for node in outputs:
            node.target = 'ALL'
    left = min((node.location.x for node in nodes), default=0.0)
    top = max((node.location.y for node in nodes), default=0.0) + 360.0

    def new(kind, role, x, term=0):
        node = nodes.new(kind)
        node[ROLE], node[OWNER] = role, owner
        node.name = NODE_NAMES[role] + (f" {term + 1}" if term else "")
        node.label = node.name
        node.location = (left + x, top - 300.0 * term)
        return node

    light = None  # the output socket of the light so far: the first term, then the running sum
    first_image = None
    for term in range(terms):
        uv_node = new("ShaderNodeUVMap", "preview_uv", -800.0, term)
        image_node = new("ShaderNodeTexImage", "preview_image", -600.0, term)
        uv_node[TERM] = image_node[TERM] = term
        # Every image node records what the preview replaced: removal reads it from any of them.
        image_node[PREVIOUS_ACTIVE] = previous_active
        image_node[PREVIOUS_OUTPUTS] = previous_output
        image_node[PREVIOUS_TARGETS] = previous_targets
        tree.links.new(uv_node.outputs["UV"], image_node.inputs["Vector"])
        if light is None:
            light, first_image = image_node.outputs["Color"], image_node
        else:
            add = new("ShaderNodeVectorMath", "preview_add", -300.0, term)
            add.operation = 'ADD'
            tree.links.new(light, add.inputs[0])
            tree.links.new(image_node.outputs["Color"], add.inputs[1])
            light = add.outputs["Vector"]
    emission = new("ShaderNodeEmission", "preview_emission", -100.0)
    output = new("ShaderNodeOutputMaterial", "preview_output", 100.0)
    tree.links.new(light, emission.inputs["Color"])
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    output.is_active_output = True  # Blender keeps one active output per tree: this clears the user's
    nodes.active = first_image


def show_preview(obj, shown):
    """Switch the preview of `obj` to 'AFTER' (refined map) or 'BEFORE' (source map); False if it has none."""
    state = obj.get(PREVIEW)
    if state is None or (shown == 'BEFORE' and not state.get("before_image")):
        return False
    state["shown"] = shown
    _show(obj, shown)
    return True


def _show(obj, shown):
    state = obj[PREVIEW]
    key = "before" if shown == 'BEFORE' else "after"
    images = [bpy.data.images.get(name) for name in state[f"{key}_image"].split(TERM_SEPARATOR)]
    uv_names = state[f"{key}_uv"].split(TERM_SEPARATOR)
    for material in _node_trees(obj):
        for node in _preview_nodes(material.node_tree, obj.name):
            if node[ROLE] == "preview_image":
                node.image = images[node.get(TERM, 0)]
            elif node[ROLE] == "preview_uv":
                node.uv_map = uv_names[node.get(TERM, 0)]
    uv_name = uv_names[0]  # Solid shading draws the active UV map: the first term's
    layers = obj.data.uv_layers
    if uv_name in layers:
        layers.active = layers[uv_name]


def _plain_dict(group):
    return {} if group is None else {str(key): str(value) for key, value in group.items()}


def _preview_nodes(tree, owner):
    return [node for node in tree.nodes if node.get(ROLE, "").startswith("preview") and node.get(OWNER) == owner]


def remove_preview(obj, journal=None):
    """Remove the preview of `obj` and put back what it replaced; returns how many nodes were removed.

    With a journal, a rollback puts the preview back."""
    removed = 0
    earlier = _preview_params(obj)
    for material in _node_trees(obj):
        tree = material.node_tree
        ours = _preview_nodes(tree, obj.name)
        if not ours:
            continue
        image_node = next((node for node in ours if node[ROLE] == "preview_image"), None)
        # Plain copies: the node's properties die with the node.
        record = {PREVIOUS_ACTIVE: image_node.get(PREVIOUS_ACTIVE, ""),
                  PREVIOUS_OUTPUTS: image_node.get(PREVIOUS_OUTPUTS, ""),
                  PREVIOUS_TARGETS: _plain_dict(image_node.get(PREVIOUS_TARGETS))} if image_node is not None else {}
        for node in ours:
            tree.nodes.remove(node)
            removed += 1
        remaining = [node for node in tree.nodes if node.get(ROLE, "").startswith("preview")]
        if remaining:  # another object's preview in this shared material: show it
            for node in remaining:
                if node[ROLE] == "preview_output":
                    node.is_active_output = True
                elif node[ROLE] == "preview_image":
                    tree.nodes.active = node
            continue
        for name, target in record.get(PREVIOUS_TARGETS, {}).items():
            if name in tree.nodes:
                tree.nodes[name].target = target
        output = tree.nodes.get(record.get(PREVIOUS_OUTPUTS, ""))
        if output is not None:
            output.is_active_output = True
        previous = record.get(PREVIOUS_ACTIVE, "")
        tree.nodes.active = tree.nodes.get(previous) if previous else None
    state = obj.get(PREVIEW)
    if state is not None:
        mesh = obj.data
        previous_uv = state.get("previous_uv", "")
        if previous_uv in mesh.uv_layers:
            mesh.uv_layers.active = mesh.uv_layers[previous_uv]
        owned = state.get("owned_material", 0)
        if owned:
            material = obj.material_slots[0].material if obj.material_slots else None
            if material is not None and material.get(ROLE) == "preview_material":
                if owned == 1:
                    _pop_only_material(mesh)
                else:
                    obj.material_slots[0].material = None
                removed += len(material.node_tree.nodes)
                bpy.data.materials.remove(material)
        del obj[PREVIEW]
    if journal is not None and earlier is not None:
        journal.on_rollback(lambda: _apply_preview(obj, **earlier))
    return removed
