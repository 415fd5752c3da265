"""The "Lightmap" tab of the 3D View sidebar: settings, the button, the last result."""

import bpy

from . import bridge


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


class LMREFINE_PT_refine(_LightmapTab, bpy.types.Panel):
    bl_idname = "LMREFINE_PT_refine"
    bl_label = "Refine Lightmap UVs"

    def draw(self, context):
        layout = self.split_layout()
        settings = context.scene.lmrefine
        obj = context.active_object

        column = layout.column()
        if obj is not None and obj.type == 'MESH':
            column.prop_search(settings, "source_layer", obj.data, "uv_layers", text="Source UV Map")
            if not settings.source_layer:
                default = bridge.default_source_layer(obj.data)
                column.label(text=f"Using: {default}" if default else "No UV map on the active object",
                             icon='INFO' if default else 'ERROR')
        else:
            column.prop(settings, "source_layer", text="Source UV Map")
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
        for name in ("strength", "max_magnification", "min_shrink", "delta", "passes", "border", "wavelet",
                     "directional"):
            column.prop(settings, name)


class LMREFINE_PT_refine_stages(_LightmapTab, bpy.types.Panel):
    bl_label = "Stages and Tessellation"
    bl_parent_id = "LMREFINE_PT_refine"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        settings = context.scene.lmrefine
        column = self.split_layout().column()
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
        layout.prop(settings, "preview")
        layout.operator("object.lmrefine_remove_preview", icon='X')


class LMREFINE_PT_refine_result(_LightmapTab, bpy.types.Panel):
    bl_label = "Last Result"
    bl_parent_id = "LMREFINE_PT_refine"

    def draw(self, context):
        layout = self.layout
        result = context.scene.lmrefine.result
        if not result.valid:
            layout.label(text="No run yet")
            return
        column = layout.column(align=True)
        column.label(text=f"Objects: {result.objects}")
        if result.moved == 0:  # every figure below would be 1x: say what happened instead
            column.label(text="Nothing moved", icon='ERROR')
            column.label(text="Refined map = source map")
            column.label(text="The Info log says why")
        else:
            column.label(text=f"Moved: {result.moved} object(s)")
            column.label(text=f"Edges: {result.transition_widening:.2f}x texels")
            column.label(text=f"Density: {result.density_min:.2f}x to {result.density_max:.2f}x")
        if result.limited_by:
            column.label(text=f"Limited by: {result.limited_by}", icon='INFO')
        if result.tessellated:
            column.label(text=f"Tessellation: +{result.vertices_added} vertices", icon='MOD_TRIANGULATE')
        if result.stages > 1:
            column.label(text=f"Stages kept: {result.stages_kept} of {result.stages}", icon='SORTTIME')
            for entry in result.stages_stopped.split("; "):
                if entry:  # an object whose next stage moved its texels too little (under 5%)
                    column.label(text=entry)
        for entry in result.timings.split("  "):
            if entry:
                column.label(text=entry, icon='TIME')


CLASSES = (LMREFINE_PT_refine, LMREFINE_PT_refine_options, LMREFINE_PT_refine_stages, LMREFINE_PT_refine_bake,
           LMREFINE_PT_refine_result)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
