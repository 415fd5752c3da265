"""Screenshots of the add-on as a user sees it (docs/images/blender_*.png); not a test.

    blender -b --factory-startup --python tests/blender/screenshots.py -- OUT          # writes OUT/shadow.blend
    xvfb-run -a -s "-screen 0 1600x900x24" blender --factory-startup OUT/shadow.blend \\
        --python tests/blender/screenshots.py -- OUT                                   # OUT/*.png, then quits
    xvfb-run -a -s "-screen 0 1600x900x24" blender --factory-startup OUT/atlas.blend \\
        --python tests/blender/screenshots.py -- OUT                                   # OUT/atlas_*.png

The second run opens a real window (Xvfb), switches the sidebar to the
Lightmap tab with xdotool (Blender 3.4 has no API for the tab), runs Refine
Lightmap UVs on the shadow scene of the tests and takes a screenshot per
viewport mode and before/after. On atlas.blend (the tests' shared-atlas
scene: three objects in one atlas, one with a lightmap of its own) it shows
Material Preview after and before, the Last Result panel (in those shots) and the atlas image in an Image Editor.
On effects.blend (the shadow scene again) it runs with Layouts: Per Effect
and shows Material Preview after and before, Rendered, and the panel. The docs' pictures are crops of these:
    convert 5_panel.png -crop 220x820+1380+80 blender_panel.png
    convert 2_material_before.png 1_material_after.png -crop 500x330+500+330 +append -resize 80% ...
"""

import os
import sys

OUT = os.path.abspath(sys.argv[sys.argv.index("--") + 1])
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), os.path.dirname(__file__)]

import bpy  # noqa: E402

if bpy.app.background:
    import scenes
    os.makedirs(OUT, exist_ok=True)
    scenes.shadow_scene()
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(OUT, "shadow.blend"))
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(OUT, "effects.blend"))  # the same scene, Per Effect
    scenes.atlas_scene()
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(OUT, "atlas.blend"))
    raise SystemExit(0)


import window_steps  # noqa: E402
from window_steps import click, run_plan, shading, show, view3d  # noqa: E402


def shot(name):
    window_steps.shot(OUT, name)


def park_mouse():  # a tick after the click: Blender must see the click where it was made
    window_steps.xdotool("mousemove", "800", "880")


def full_screen():
    import lmrefine_blender
    lmrefine_blender.register()
    settings = bpy.context.scene.lmrefine
    settings.resolution, settings.samples = 128, 8
    window, area = view3d()
    area.spaces.active.show_region_ui = True  # the sidebar, before the area is made full screen
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screen_full_area()


def frame():
    window_steps.frame((0.9, 0.0, 0.5), 7.0, (0.2, 0.3, 0.0))


def refine():
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.object.lmrefine_refine_uvs('EXEC_DEFAULT')


PLAN = [
    full_screen, frame, lambda: click(1586, 253), park_mouse,  # the Lightmap tab
    lambda: shot("0_panel_before_run"), refine,
    lambda: shading('MATERIAL'), lambda: None, lambda: None,  # EEVEE compiles its shaders
    lambda: shot("1_material_after"), lambda: show('BEFORE'), lambda: shot("2_material_before"),
    lambda: show('AFTER'), lambda: shading('SOLID', 'TEXTURE'), lambda: shot("3_solid_texture_after"),
    lambda: shading('RENDERED'), lambda: shot("4_rendered_after"),
    lambda: shading('SOLID', 'MATERIAL'), lambda: click(1440, 305), park_mouse,  # open Refinement
    lambda: shot("5_panel"), lambda: os._exit(0),
]


def image_editor(image_name):
    """Turn the 3D View into an Image Editor showing image `image_name` at 5x (then shot_editor)."""
    window, area = view3d()
    area.ui_type = 'IMAGE_EDITOR'
    area.spaces.active.image = bpy.data.images[image_name]
    region = next(region for region in area.regions if region.type == 'WINDOW')
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.image.view_zoom_ratio(ratio=5.0)


def shot_editor(name):
    window = bpy.context.window_manager.windows[0]
    area = next(area for area in window.screen.areas if area.type == 'IMAGE_EDITOR')
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screenshot(filepath=os.path.join(OUT, name + ".png"))


def atlas_frame():
    frame()
    view3d()[1].spaces.active.region_3d.view_distance = 8.5


ATLAS_PLAN = [
    full_screen, atlas_frame, lambda: click(1586, 253), park_mouse, refine,
    lambda: shading('MATERIAL'), lambda: None, lambda: None,
    lambda: shot("atlas_1_material_after"), lambda: show('BEFORE'), lambda: shot("atlas_2_material_before"),
    lambda: show('AFTER'),
    lambda: image_editor(next(i.name for i in bpy.data.images if i.name.endswith("_atlas_lightmap_direct"))),
    lambda: shot_editor("atlas_3_image"), lambda: os._exit(0),
]


def per_effect():
    bpy.context.scene.lmrefine.layouts = 'PER_EFFECT'


EFFECTS_PLAN = [
    full_screen, frame, lambda: click(1586, 253), park_mouse, per_effect, refine,
    lambda: shading('MATERIAL'), lambda: None, lambda: None,
    lambda: shot("effects_1_material_after"), lambda: show('BEFORE'), lambda: shot("effects_2_material_before"),
    lambda: show('AFTER'), lambda: shading('RENDERED'), lambda: shot("effects_3_rendered_after"),
    lambda: shading('SOLID', 'MATERIAL'), lambda: shot("effects_4_panel"), lambda: os._exit(0),
]
if os.path.basename(bpy.data.filepath) == "atlas.blend":
    PLAN = ATLAS_PLAN
elif os.path.basename(bpy.data.filepath) == "effects.blend":
    PLAN = EFFECTS_PLAN


run_plan(PLAN, 6.0)
