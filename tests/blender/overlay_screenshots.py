"""Screenshots of the Texel Density overlay in a real Blender window (docs/images/blender_texel_density.png); not a test.

    xvfb-run -a -s "-screen 0 1600x900x24" blender --factory-startup blend_samples/courtyard.blend \\
        --python tests/blender/overlay_screenshots.py -- OUT                     # OUT/*.png, then quits

Refines the courtyard sample's LightmapSmart map at 256 x 256 (Embree, as
the README's batch example does), turns the overlay on and takes a
screenshot with the refined map, then one with the source map, then one
of the sidebar (overlay_panel.png). The docs' picture puts the first two side
by side:

    /usr/bin/python3 tests/blender/overlay_screenshots.py --docs OUT docs/images/blender_texel_density.png
"""

import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

if "--docs" in sys.argv:  # plain Python: crop and join the two screenshots
    import matplotlib.image as mpimg
    import numpy as np
    out, target = sys.argv[sys.argv.index("--docs") + 1:][:2]
    # The courtyard, left: source map, right: refined map, at half size; under them the
    # refined shot's legend and the Texel Density panel at full size (readable).
    shots = [mpimg.imread(os.path.join(out, name))[:, :, :3] for name in ("overlay_source.png", "overlay_refined.png")]
    crops = [shot[150:880, 60:1360] for shot in shots]
    gap = np.ones((crops[0].shape[0], 8, 3), crops[0].dtype)
    row = np.concatenate([crops[0], gap, crops[1]], axis=1)
    height, width = row.shape[0] // 2 * 2, row.shape[1] // 2 * 2
    row = row[:height, :width].reshape(height // 2, 2, width // 2, 2, 3).mean(axis=(1, 3))
    legend = shots[1][775:875, 65:545]
    panel = mpimg.imread(os.path.join(out, "overlay_panel.png"))[:, :, :3][395:530, 1375:1575]
    under = np.full((panel.shape[0] + 8, row.shape[1], 3), 1.0, row.dtype)
    under[8:8 + legend.shape[0], :legend.shape[1]] = legend
    under[8:, legend.shape[1] + 16:legend.shape[1] + 16 + panel.shape[1]] = panel
    mpimg.imsave(target, np.clip(np.concatenate([row, under], axis=0), 0.0, 1.0))
    raise SystemExit(0)

OUT = os.path.abspath(sys.argv[sys.argv.index("--") + 1])
sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), os.path.dirname(__file__)]

import bpy  # noqa: E402


import window_steps  # noqa: E402
from window_steps import click, run_plan, shot, view3d, xdotool  # noqa: E402


def prepare():
    import lmrefine_blender
    lmrefine_blender.register()
    settings = bpy.context.scene.lmrefine
    settings.source_layer, settings.resolution, settings.samples = "LightmapSmart", 256, 8
    settings.preview = False  # the overlay, not the lightmap, on the surfaces
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.type == 'MESH')
    bpy.context.view_layer.objects.active = bpy.data.objects["Floor"]
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screen_full_area()
    space = window_steps.frame((1.0, 0.0, -0.6), 19.0, (0.0, 0.5, 0.5), sidebar=False)
    space.overlay.show_extras = space.overlay.show_cursor = False  # the sun's line, the 3D cursor
    space.shading.type = 'SOLID'


def show_panel():
    """The sidebar's Lightmap tab with Second Bake and Last Result closed and Texel Density open (for this picture
    only: a panel's first open state is its bl_options when it is first drawn)."""
    from lmrefine_blender import panels
    order = (panels.LMREFINE_PT_refine_bake, panels.LMREFINE_PT_refine_result, panels.LMREFINE_PT_density)
    for cls in order:
        bpy.utils.unregister_class(cls)
    panels.LMREFINE_PT_refine_bake.bl_options = panels.LMREFINE_PT_refine_result.bl_options = {'DEFAULT_CLOSED'}
    panels.LMREFINE_PT_density.bl_options = set()
    for cls in order:
        bpy.utils.register_class(cls)
    view3d()[1].spaces.active.show_region_ui = True


def refine():
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.object.lmrefine_refine_uvs('EXEC_DEFAULT')
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)  # no selection outline over the colours


def overlay(which):
    settings = bpy.context.scene.lmrefine
    settings.density_map = which
    settings.density_overlay = True


PLAN = [prepare, refine, lambda: overlay('REFINED'), lambda: None, lambda: shot(OUT, "overlay_refined"),
        lambda: overlay('SOURCE'), lambda: None, lambda: shot(OUT, "overlay_source"),
        lambda: overlay('REFINED'), show_panel, lambda: click(1586, 253),
        lambda: xdotool("mousemove", "800", "880"), lambda: shot(OUT, "overlay_panel"),  # the Lightmap tab
        lambda: os._exit(0)]


run_plan(PLAN, 3.0)
