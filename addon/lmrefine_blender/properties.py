"""Settings of the refinement (Scene.lmrefine) and the last result shown in the panel.

Every property lives in one PropertyGroup attached to the Scene under the
prefixed name ``lmrefine``, so the add-on never collides with other add-ons'
Scene properties. The batch entry fills the same group from its flags.
"""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from . import overlay

FIRST_LIGHTMAP_ITEMS = (
    ('IMAGE', "Image",
     "Use the lightmap already baked into the object's material (an Image Texture node fed by a UV Map "
     "node set to the source layer, or one named like 'lightmap'), or the image picked below"),
    ('EMBREE', "Embree", "Bake the first lightmap now with lmrefine's Embree baker (fast)"),
    ('CYCLES', "Cycles", "Bake the first lightmap now with Blender's Cycles bake"),
)

BACKEND_ITEMS = (
    ('EMBREE', "Embree", "Bake with lmrefine's Embree baker (fast, same light model as Cycles' diffuse bake)"),
    ('CYCLES', "Cycles", "Bake with Blender's own Cycles bake"),
)

# Pass names are the lmrefine baker's; Cycles equivalents are in cycles_bake.py.
PASS_ITEMS = (
    ('DIRECT', "Direct", "Direct diffuse light with shadows (Cycles: Diffuse bake, Direct only, Color off)"),
    ('INDIRECT', "Indirect", "Indirect diffuse light (Cycles: Diffuse bake, Indirect only, Color off)"),
    ('COMBINED', "Combined", "Direct + indirect diffuse light (Cycles: Diffuse bake, Direct + Indirect, Color off)"),
    ('AO', "AO", "Ambient occlusion (Cycles: Ambient Occlusion bake)"),
)

# Enum identifiers are lmrefine.refine_uvs' option values, upper-cased.
BORDER_ITEMS = (
    ('SAME', "Same Rule", "Border cells follow the same rule as every other cell (thesis variant 1)"),
    ('BORDER_RULE', "Border Rule", "Border cells follow their own spring rule (thesis variant 2)"),
    ('EXTRA_RING', "Extra Ring", "An extra ring of cells around the grid, removed after convergence (variant 3)"),
)

DENSITY_MAP_ITEMS = (
    ('REFINED', "Refined", "Draw the refined map ('<source>_refined'); objects without one show their source map"),
    ('SOURCE', "Source", "Draw the source map the refinement starts from"),
)

WAVELET_ITEMS = (
    ('D4', "D4", "Daubechies D4, the thesis' choice: copes with noisy bakes"),
    ('HAAR', "Haar", "Shortest filter: sharpest response, most sensitive to noise"),
    ('D12', "D12", "Daubechies D12, a longer filter: about the same result as D4, slower"),
    ('D20', "D20", "Daubechies D20: the longest Daubechies filter"),
    ('CDF53', "CDF 5/3", "Cohen-Daubechies-Feauveau 5/3"),
    ('CDF97', "CDF 9/7", "Cohen-Daubechies-Feauveau 9/7"),
)


class LMREFINE_PG_result(bpy.types.PropertyGroup):
    """The last run's numbers, shown in the panel (not an input)."""

    valid: BoolProperty(name="Has Result", default=False)
    objects: StringProperty(name="Objects", description="Objects the last run refined")
    moved: IntProperty(name="Moved", description="Objects whose refined UV map differs from the source map")
    transition_widening: FloatProperty(
        name="Transition Widening",
        description="Texel density at light/shadow transitions, relative to before (higher = sharper edges)")
    density_min: FloatProperty(
        name="Min Density", description="Smallest new / old texel count of a triangle (its UV area ratio) in the "
        "refined map. Min Shrink bounds the automaton's cells; the chart repack scales whole charts on top")
    density_max: FloatProperty(
        name="Max Density", description="Largest new / old texel count of a triangle (its UV area ratio) in the "
        "refined map. Max Growth bounds the automaton's cells; the chart repack scales whole charts on top, so "
        "this can exceed Max Growth")
    limited_by: StringProperty(name="Limited By", description="What kept the refinement from going further")
    warnings: IntProperty(name="Warnings", description="Warnings of the last run (in the Info log)")
    warning_text: StringProperty(name="Warning Text",
                                 description="The last run's warnings, one a line, as the Last Result panel "
                                             "shows them")
    timings: StringProperty(name="Timings", description="Seconds per stage of the last run")
    message: StringProperty(name="Message", description="Summary of the last run")
    vertices_added: IntProperty(name="Vertices Added",
                                description="Vertices the tessellation along transitions added to the meshes")
    tessellated: BoolProperty(name="Tessellated", description="Whether the last run tessellated", default=False)
    stages: IntProperty(name="Stages", description="Refinement stages asked for in the last run", default=1)
    stages_kept: IntProperty(name="Stages Kept", description="Refinement stages the last run kept (the most of "
                             "any object)", default=1)
    images: IntProperty(name="Images", description="Images the last run wrote per pass, or per effect with "
                        "Layouts: Per Effect (one per atlas group)")
    shared: StringProperty(name="Shared Images",
                           description="Atlas groups of the last run that several objects share ('name: objects; ...')")
    effects: StringProperty(name="Effects", description="Layouts: Per Effect: each effect's resolution and "
                            "widening ('direct 181px 1.42x; indirect 181px 1.05x'), empty otherwise")
    stages_stopped: StringProperty(name="Stages Stopped",
                                   description="Objects whose stages stopped early: the stage that moved too "
                                               "little, backed off or gave the light changes no texels")
    recharted: IntProperty(name="Re-charted", description="Objects whose source map gave the refiner no room or "
                           "folded over sharp edges, re-charted from the mesh and refined", default=0)
    stretched: IntProperty(name="Stretched", description="Charts of the refined maps stretched across their light "
                           "changes (more texels across the shadows' edges, fewer along them), summed over the maps",
                           default=0)
    stretched_triangles: IntProperty(name="Stretched Triangles",
                                     description="Triangles of the refined maps stretched across the light changes "
                                     "inside them (Tri Stretch), summed over the maps", default=0)


class LMREFINE_PG_settings(bpy.types.PropertyGroup):
    source_layer: StringProperty(
        name="Source",
        description="Lightmap UV map to refine (left untouched; the result goes to '<name>_refined'). "
                    "Empty: a map named like 'Lightmap' or 'UVMap.001', else the second UV map",
    )
    resolution: IntProperty(
        name="Resolution", description="Lightmap width and height in texels",
        default=512, min=16, max=16384, soft_max=4096,
    )
    padding: IntProperty(
        name="Padding", description="Gutter between charts in texels that the refined layout must keep",
        default=2, min=0, max=64,
    )
    first_lightmap: EnumProperty(
        name="First Map",
        description="The first lightmap, which decides where texels go: bake it now (Embree or Cycles) with the "
                    "source UV map, or use an existing image baked with it",
        items=FIRST_LIGHTMAP_ITEMS, default='EMBREE',
    )
    lightmap_image: PointerProperty(
        name="Lightmap Image", type=bpy.types.Image,
        description="Lightmap to use for every selected object (optional; default: found in each material)",
    )
    driving_pass: EnumProperty(
        name="Pass", description="Which light the first bake measures to decide where texels go",
        items=PASS_ITEMS, default='DIRECT',
    )

    # Refinement (lmrefine.refine_uvs options).
    strength: FloatProperty(
        name="Strength",
        description="How much texels at the strongest light change may grow: such a texel wants (1 + strength) "
                    "times the area of one in flat light. 0 leaves the layout unchanged",
        default=24.0, min=0.0, soft_max=40.0,
    )
    max_magnification: FloatProperty(
        name="Max Growth", description="Max magnification: largest growth of a texel's area (texel-density ratio)",
        default=8.0, min=1.0, max=64.0,
    )
    min_shrink: FloatProperty(
        name="Min Shrink", description="Smallest a texel's area may become in flat light (texel-density ratio)",
        default=0.15, min=0.01, max=1.0,
    )
    max_stretch: FloatProperty(
        name="Max Stretch",
        description="A chart whose light changes run mostly one way (stripes of beams, railings) may be "
                    "stretched across them by up to this and squeezed along them as much, its texel area kept; "
                    "only where the predicted lightmap error (blur at the light changes) is lower and the atlas "
                    "stays as full. 1 turns it off",
        default=2.0, min=1.0, max=4.0,
    )
    triangle_stretch: FloatProperty(
        name="Tri Stretch",
        description="After the charts are scaled and packed, stretch each triangle across the light changes that "
                    "run one way inside it (a picket's shadow) by up to this, squeezed along them, and pack again; "
                    "kept only where the predicted lightmap error (blur at the light changes) is lower, packing "
                    "included. 1 turns it off",
        default=2.0, min=1.0, max=4.0,
    )
    delta: FloatProperty(
        name="Delta",
        description="The automaton stops when neighbouring texel densities differ by less than this (relative)",
        default=0.02, min=1e-5, max=0.5, precision=4,
    )
    passes: IntProperty(
        name="Passes",
        description="Refinement passes of the automaton: each extra pass reruns the finest level with fresh energies, "
                    "deforming further",
        default=1, min=1, max=8,
    )
    border: EnumProperty(name="Border", description="How the grid's outer cells behave", items=BORDER_ITEMS,
                         default='SAME')
    directional: BoolProperty(
        name="Directional", description="Four energies per cell (one per direction) instead of one",
        default=False,
    )
    wavelet: EnumProperty(name="Wavelet", description="Filter of the gradient map", items=WAVELET_ITEMS,
                          default='D4')
    layouts: EnumProperty(
        name="Layouts",
        description="One refined UV map and one image per pass, or one per light effect",
        items=(('ONE', "One", "One refined UV map '<source>_refined', one image per bake pass"),
               ('PER_EFFECT', "Per Effect", "Direct and indirect light each get their own refined UV map "
                "('<source>_refined_direct', '_indirect') and image, at resolutions that split Resolution^2 "
                "texels between them; the preview adds them. Measured to lose against One on the combined "
                "light (docs/refiner.md)")),
        default='ONE',
    )
    per_effect_rule: EnumProperty(
        name="Split",
        description="How Per Effect splits the texels of one Resolution x Resolution map between the effects",
        items=(('SQRT', "Sqrt", "In proportion to the square root of each effect's gradient energy"),
               ('ENERGY', "Energy", "In proportion to each effect's gradient energy"),
               ('EQUAL', "Equal", "Half each")),
        default='SQRT',
    )
    rechart: BoolProperty(
        name="Re-chart when the source map is a poor start",
        description="When the source map gives the refiner no room (one chart per face, as Lightmap Pack makes) "
                    "or its charts fold over sharp edges whose light differs (as Smart UV Project's do), "
                    "re-chart the mesh (charts of faces whose normals are within 20 degrees, conformal unwrap) "
                    "and refine that layout instead, if its predicted lightmap error (blur at the light changes) "
                    "is lower. The source map is never changed; the refined map gets the new layout",
        default=True,
    )
    stages: IntProperty(
        name="Stages",
        description="Bake, refine, bake, refine...: each further stage refines the layout again from a bake "
                    "with it. An object stops at the first stage that changes its layout by less than 5%, "
                    "backs off to under a tenth of its deformation (its triangles flipped; from the third "
                    "stage on) or gives the light changes no more texels",
        default=1, min=1, max=8,
    )
    tessellate: BoolProperty(
        name="Tessellate",
        description="Before refining, split the mesh's triangles that strong light transitions cross and that "
                    "cover many texels, so the refinement can move texels inside them. Writes into the mesh "
                    "(same surface, every attribute interpolated; undone with the run)",
        default=False,
    )
    tessellate_budget: FloatProperty(
        name="Vertex Budget",
        description="Most vertices the tessellation may add, as a fraction of each object's vertex count "
                    "(a mesh of few vertices, such as a one-quad floor, needs hundreds: type the value)",
        default=0.25, min=0.0, max=1024.0, soft_max=1.0, subtype='FACTOR',
    )

    # Second bake.
    backend: EnumProperty(name="Baker", description="Baker of the final lightmaps (the second bake)", items=BACKEND_ITEMS,
                          default='EMBREE')
    bake_passes: EnumProperty(
        name="Bake Passes", description="Lightmaps to bake with the refined layout (one image each)",
        items=PASS_ITEMS, default={'DIRECT'}, options={'ENUM_FLAG'},
    )
    samples: IntProperty(name="Samples", description="Samples per texel for both bakes", default=16, min=1,
                         max=4096)
    exr_float32: BoolProperty(
        name="Float32 EXR",
        description="Write the lightmaps as 32-bit float EXR. Off: half float (16-bit), which holds lighting "
                    "values with about 3 significant digits at half the size; both use lossless ZIP compression",
        default=False,
    )
    shared_atlas: BoolProperty(
        name="Shared Atlas",
        description="Objects whose lightmap UV maps share one atlas (laid out together, their charts apart) are "
                    "refined together and baked into one image per pass, named after the first of them "
                    "('<object>_atlas_lightmap_<pass>'). Off: one image per object",
        default=True,
    )
    preview: BoolProperty(
        name="Preview",
        description="Show the baked lightmap on the objects in every viewport mode, through the refined UV map "
                    "(Solid with Texture colour, Material Preview, Rendered), with a before/after switch. The "
                    "user's nodes are not rewired; 'Remove Preview' puts back the active output, node and UV map",
        default=True,
    )

    # The texel-density overlay: its on/off state is the overlay's own (handlers
    # installed or not), never stored in the file.
    density_overlay: BoolProperty(
        name="Texel Density",
        description="Draw the texels per metre of the lightmap UV map on the objects in the 3D viewport, as a "
                    "heatmap with a legend (blue 1/4x, green 1x, red 4x the source maps' median). Draws only: "
                    "nothing is written into the meshes or materials",
        get=lambda self: overlay.enabled(),
        set=lambda self, value: overlay.set_enabled(value),
    )
    density_map: EnumProperty(
        name="Map", description="Which lightmap UV map the texel-density overlay draws", items=DENSITY_MAP_ITEMS,
        default='REFINED', update=overlay.settings_changed,
    )

    result: PointerProperty(type=LMREFINE_PG_result)


CLASSES = (LMREFINE_PG_result, LMREFINE_PG_settings)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)


def register():
    _register_classes()
    bpy.types.Scene.lmrefine = PointerProperty(type=LMREFINE_PG_settings)


def unregister():
    del bpy.types.Scene.lmrefine
    _unregister_classes()
