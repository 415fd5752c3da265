"""The "Lightmap" tab of the 3D View sidebar: settings, the button, the last result.

Labels are short enough for the sidebar's default width (tooltips carry the
detail), and every panel draws the same rows whatever the state, greying out
what does not apply, so the layout never jumps under the mouse.
"""

import textwrap

import bpy

from . import bridge, materials, overlay


class _LightmapTab:
    """Where every panel of the add-on lives: 3D View > Sidebar > Lightmap."""

    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Lightmap"

    def split_layout(self):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        return layout


# What held a refinement back (refine_uvs' report["limited_by"]) in plain words: a short name for the
# panel's "Limit:" row, where two fit the default sidebar width and more are counted ("Limit: flips +2"),
# and what it means, for the operator's report. Settings go by their panel labels; the order is the row's.
LIMITS = {
    "max_magnification": ("Max Growth", "some texels grew as much as it allows"),
    "min_shrink": ("Min Shrink", "some texels shrank as much as it allows"),
    "gutter": ("Padding", "the deformation was scaled back where charts would come closer than Padding"),
    "original_gutter": ("tight gaps", "the source map has charts closer than Padding: they keep their own "
                                      "distance"),
    "flipped": ("flips", "the deformation was scaled back where UV triangles would turn over"),
    "overlapping": ("overlaps", "the deformation was scaled back where UV triangles would overlap"),
    "degenerate": ("collapses", "the deformation was scaled back where UV triangles would lose their area"),
    "out_of_bounds": ("map edge", "the deformation was scaled back where UVs would leave the map"),
    "grid": ("cell folds", "the deformation was scaled back further where the automaton's grid would fold"),
    "step_cap": ("steps", "the automaton stopped at its step limit before the texel densities settled "
                          "within Delta"),
    "aligned_steps": ("texel-aligned", "the light's steps lie on texel boundaries that the layout's edges run "
                                       "along, so the layout was kept as it is"),
}
LIMIT_ROW_CHARACTERS = 23  # the default sidebar's width beside an icon


def limit_words(limited_by):
    """[(short name, meaning)] for a result's limited_by ("flipped, step_cap"), in LIMITS' order; a key it
    does not know comes last, its underscores as spaces."""
    keys = [key for key in limited_by.split(", ") if key]
    order = list(LIMITS)
    keys.sort(key=lambda key: order.index(key) if key in LIMITS else len(order))
    return [LIMITS.get(key, (key.replace("_", " "),) * 2) for key in keys]


def limit_row(limited_by):
    """The panel's "Limit:" row: as many short names as fit the sidebar, then a count of the others."""
    names = [short for short, _ in limit_words(limited_by)]
    if not names:
        return "Limit: none"
    for shown in range(len(names), 0, -1):
        text = "Limit: " + "/".join(names[:shown]) + (f" +{len(names) - shown}" if shown < len(names) else "")
        if len(text) <= LIMIT_ROW_CHARACTERS:
            return text
    return text  # one name that does not fit alone (none of LIMITS' does): the sidebar elides it


def source_line(settings, obj):
    """The row under the source field: which map a run refines, or why none (always one row)."""
    if obj is None or obj.type != 'MESH':
        return "Select a mesh", 'INFO', False
    mesh = obj.data
    source = settings.source_layer.strip() or bridge.default_source_layer(mesh)
    if source is None:
        return "No UV map", 'ERROR', True
    if source not in mesh.uv_layers:
        return f"No map '{source}'", 'ERROR', True
    if settings.source_layer.strip() == "":
        return f"Auto: {source}", 'UV', True  # the map the empty field stands for
    return f"Into: {source}_refined", 'UV', False


class LMREFINE_PT_refine(_LightmapTab, bpy.types.Panel):
    bl_idname = "LMREFINE_PT_refine"
    bl_label = "Refine Lightmap UVs"

    def draw(self, context):
        layout = self.split_layout()
        settings = context.scene.lmrefine
        obj = context.active_object

        column = layout.column()
        if obj is not None and obj.type == 'MESH':
            column.prop_search(settings, "source_layer", obj.data, "uv_layers")
        else:
            column.prop(settings, "source_layer")
        text, icon, enabled = source_line(settings, obj)
        row = column.row()
        row.enabled = enabled
        row.label(text=text, icon=icon)
        column.prop(settings, "resolution")
        column.prop(settings, "padding")

        column = layout.column()
        column.prop(settings, "first_lightmap")
        if settings.first_lightmap == 'IMAGE':
            column.template_ID(settings, "lightmap_image", open="image.open")
        else:
            column.prop(settings, "driving_pass")

        layout.operator("object.lmrefine_refine_uvs", icon='UV')


class LMREFINE_PT_refine_options(_LightmapTab, bpy.types.Panel):
    bl_label = "Refinement"
    bl_parent_id = "LMREFINE_PT_refine"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        settings = context.scene.lmrefine
        column = self.split_layout().column()
        for name in ("strength", "max_magnification", "min_shrink", "max_stretch", "triangle_stretch", "delta",
                     "passes", "border", "wavelet", "directional"):
            column.prop(settings, name)
        column.prop(settings, "rechart", text="Re-chart if Better")


class LMREFINE_PT_refine_stages(_LightmapTab, bpy.types.Panel):
    bl_label = "Stages and Tessellation"
    bl_parent_id = "LMREFINE_PT_refine"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        settings = context.scene.lmrefine
        column = self.split_layout().column()
        column.prop(settings, "layouts", expand=True)
        row = column.row()
        row.active = settings.layouts == 'PER_EFFECT'
        row.prop(settings, "per_effect_rule")
        column.prop(settings, "stages")
        column.prop(settings, "tessellate")
        row = column.row()
        row.active = settings.tessellate
        row.prop(settings, "tessellate_budget")


class LMREFINE_PT_refine_bake(_LightmapTab, bpy.types.Panel):
    bl_label = "Second Bake"
    bl_parent_id = "LMREFINE_PT_refine"

    def draw(self, context):
        layout = self.split_layout()
        settings = context.scene.lmrefine
        layout.prop(settings, "backend")
        layout.column(heading="Passes").prop(settings, "bake_passes")
        layout.prop(settings, "samples")
        layout.prop(settings, "exr_float32")
        layout.prop(settings, "shared_atlas")
        layout.prop(settings, "preview")
        # Before/after and removal: always drawn, greyed out when the active object has no preview.
        obj = context.active_object
        shown = materials.preview_shown(obj) if obj is not None else None
        row = layout.row(heading="Show", align=True)
        row.enabled = shown is not None
        for value, text in (('BEFORE', "Before"), ('AFTER', "After")):
            row.operator("object.lmrefine_show_preview", text=text, depress=shown == value).shown = value
        row = layout.row()
        row.enabled = shown is not None
        row.operator("object.lmrefine_remove_preview", text="Remove Preview", icon='X')


class LMREFINE_PT_refine_result(_LightmapTab, bpy.types.Panel):
    bl_label = "Last Result"
    bl_parent_id = "LMREFINE_PT_refine"

    def draw(self, context):
        """The same rows in every state (with one stage; placeholders greyed out), so the panel keeps its size."""
        result = context.scene.lmrefine.result
        column = self.layout.column(align=True)
        rows = []
        # A count, not the names: five names do not fit the sidebar (the operator's report lists them).
        count = len([name for name in result.objects.split(", ") if name])
        if not result.valid:
            rows = [("No run yet", 'INFO', False)] + [("", 'BLANK1', False)] * 3
        elif result.moved == 0:  # every figure would be 1x: say what happened instead
            rows = [(f"Objects: {count}", 'OBJECT_DATA', True),
                    ("Nothing moved", 'ERROR', True),
                    ("Refined = source map", 'BLANK1', True),
                    ("The warnings say why", 'BLANK1', True)]
        else:
            rows = [(f"Objects: {count}", 'OBJECT_DATA', True),
                    (f"Moved: {result.moved} object(s)", 'CHECKMARK', True),
                    (f"Edges: {result.transition_widening:.2f}x texels", 'SHARPCURVE', True),
                    # A triangle's new / old texels, on the output: the repack's chart scale comes on top of
                    # the automaton's bounds (Min Shrink, Max Growth bound its cells), so it can exceed them.
                    (f"Triangles: {result.density_min:.2g}x-{result.density_max:.3g}x", 'MOD_UVPROJECT', True)]
        rows.append((limit_row(result.limited_by), 'INFO', bool(result.limited_by)))
        warnings = result.warnings if result.valid else 0
        rows.append((f"Warnings: {warnings} (below)" if warnings else "Warnings: none", 'ERROR' if warnings
                     else 'INFO', bool(warnings)))
        images = result.images if result.valid else 0
        # Layouts: Per Effect writes one image per effect for each map, whatever the bake passes.
        each = "effect" if result.valid and result.effects else "pass"
        rows.append((f"Images: {images} per {each}" if images else "Images: -", 'IMAGE_DATA', bool(images)))
        if result.valid and result.effects:  # Layouts: Per Effect: a row per effect, its map side and its edges
            # "Indirect: 125px, 2.39x": its map's side and its edges' widening (23 characters at most)
            rows += [(f"{entry.split()[0].capitalize()}: {entry.split()[1]}, {entry.split()[2]}", 'LIGHT', True)
                     for entry in result.effects.split("; ")]
        shared = [entry.split(": ", 1) for entry in result.shared.split("; ") if entry] if result.valid else []
        rows.append((f"Atlas: {shared[0][0]} ({len(shared[0][1].split(', '))})"  # (objects sharing it)
                     + (f" +{len(shared) - 1}" if len(shared) > 1 else "") if shared else "Atlas: none",
                     'LINKED' if shared else 'UNLINKED', bool(shared)))
        recharted = result.valid and result.recharted > 0
        rows.append((f"Re-charted: {result.recharted}" if recharted else "Re-charted: none", 'UV_DATA',
                     recharted))
        stretched = result.valid and result.stretched > 0
        triangles = result.valid and result.stretched_triangles > 0
        if stretched or not triangles:  # "none" only when neither stretch was kept
            rows.append((f"Stretched: {result.stretched} charts" if stretched else "Stretched: none",
                         'FULLSCREEN_ENTER', stretched))
        if triangles:
            rows.append((f"Stretched: {result.stretched_triangles} triangles", 'FULLSCREEN_ENTER', True))
        tessellated = result.valid and result.tessellated
        rows.append((f"New vertices: {result.vertices_added}" if tessellated else "Tessellation: off",
                     'MOD_TRIANGULATE', tessellated))
        staged = result.valid and result.stages > 1
        rows.append((f"Stages kept: {result.stages_kept} of {result.stages}" if staged else "Stages: 1", 'SORTTIME',
                     staged))
        if staged:  # more than one stage is a setting: its rows come with it
            # An object whose next stage moved its texels too little, backed off or gave edges no texels:
            # its name, then why on a row of its own, so that the sidebar does not elide the reason.
            for entry in filter(None, result.stages_stopped.split("; ")):
                name, _, why = entry.partition(": ")
                rows += [(f"{name}:", 'BLANK1', True), (why, 'BLANK1', True)]
        timings = dict(entry.rsplit(" ", 1) for entry in result.timings.split("  ") if entry)
        for stage in ("first bake", "refine", "second bake"):
            seconds = timings.get(stage)
            rows.append((f"{stage.capitalize()}: {seconds}" if seconds else f"{stage.capitalize()}: -", 'TIME',
                         seconds is not None))
        for text, icon, enabled in rows:
            row = column.row()
            row.enabled = enabled
            row.label(text=text, icon=icon)


# The Warnings panel lists this many of the last run's warnings; the Info log has them all.
SHOWN_WARNINGS = 5


def wrap(text, region):
    """`text` in lines that fit the sidebar `region` beside an icon (about 23 characters at its default
    width; None: that width)."""
    if region is None or region.width <= 1:
        width = LIMIT_ROW_CHARACTERS
    else:  # the UI font's mean character, the panel's margins and the icon, in pixels at this UI scale
        scale = bpy.context.preferences.system.ui_scale
        width = max(LIMIT_ROW_CHARACTERS, int((region.width - 56 * scale) / (7 * scale)))
    return textwrap.wrap(text, width) or [""]


def warning_rows(result, region=None):
    """The Warnings panel's rows (text, icon): each warning of the last run wrapped to the sidebar, the first
    line with a warning icon; one row when there is none."""
    warnings = [text for text in result.warning_text.split("\n") if text] if result.valid else []
    if not warnings:
        return [("No warnings" if result.valid else "No run yet", 'INFO')]
    rows = []
    for text in warnings[:SHOWN_WARNINGS]:
        lines = wrap(text, region)
        rows += [(lines[0], 'ERROR')] + [(line, 'BLANK1') for line in lines[1:]]
    if len(warnings) > SHOWN_WARNINGS:
        rows.append((f"{len(warnings) - SHOWN_WARNINGS} more in the Info log", 'INFO'))
    return rows


class LMREFINE_PT_refine_warnings(_LightmapTab, bpy.types.Panel):
    """The last run's warnings, kept after the run (the status bar shows only the last report)."""

    bl_label = "Warnings"
    bl_parent_id = "LMREFINE_PT_refine_result"

    def draw(self, context):
        result = context.scene.lmrefine.result
        column = self.layout.column(align=True)
        column.enabled = bool(result.valid and result.warnings)
        for text, icon in warning_rows(result, context.region):
            column.label(text=text, icon=icon)


def density_rows(settings):
    """The Texel Density panel's three rows (text, enabled): the same rows whether the overlay is on or off."""
    view = overlay.current_view()
    if view is None:
        return [("Off: tick the box above", False), ("", False), ("", False)]
    if not view.drawn:
        return [("No object with a lightmap map", True), ("", False), ("", False)]
    number = overlay.format_density
    return [(f"Median: {number(view.median)} texels/m", True),
            (f"Range: {number(view.minimum)} to {number(view.maximum)}", True),
            (f"Green: {number(view.reference)} (source median)", True)]


class LMREFINE_PT_density(_LightmapTab, bpy.types.Panel):
    bl_label = "Texel Density"
    bl_parent_id = "LMREFINE_PT_refine"
    bl_options = {'DEFAULT_CLOSED'}

    def draw_header(self, context):
        self.layout.prop(context.scene.lmrefine, "density_overlay", text="")

    def draw(self, context):
        settings = context.scene.lmrefine
        layout = self.layout
        layout.row().prop(settings, "density_map", expand=True)
        column = layout.column(align=True)
        for text, enabled in density_rows(settings):
            row = column.row()
            row.enabled = enabled
            row.label(text=text)


CLASSES = (LMREFINE_PT_refine, LMREFINE_PT_refine_options, LMREFINE_PT_refine_stages, LMREFINE_PT_refine_bake,
           LMREFINE_PT_refine_result, LMREFINE_PT_refine_warnings, LMREFINE_PT_density)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
