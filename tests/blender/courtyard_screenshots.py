"""Screenshots of the add-on on the bundled courtyard as an artist uses it (default settings but 256 texels and
8 samples); not a test.

    xvfb-run -a -s "-screen 0 1600x1300x24" blender --factory-startup blend_samples/courtyard.blend \\
        --python tests/blender/courtyard_screenshots.py -- OUT          # OUT/*.png, then quits
    /usr/bin/python3 tests/blender/courtyard_screenshots.py --docs OUT docs/images/blender_panel.png

All five objects selected, Refine Lightmap UVs (their Lightmap Pack map, one shared atlas, re-charted),
then: the panel before and after the run, Material Preview after and before, Solid > Texture, Rendered,
the Texel Density overlay, Material Preview after Remove Preview, and the panel after a Strength 0 run
(nothing moved). The EXRs land beside the .blend (blend_samples/Floor_atlas_lightmap_*.exr): delete them.
"""
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if "--docs" in sys.argv:  # plain Python: the panel after the run, at the default sidebar width
    import matplotlib.image as mpimg
    out, target = sys.argv[sys.argv.index("--docs") + 1:][:2]
    mpimg.imsave(target, mpimg.imread(os.path.join(out, "01_panel_after.png"))[80:1020, 1380:1600, :3])
    raise SystemExit(0)
OUT = os.path.abspath(sys.argv[sys.argv.index("--") + 1])
sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), os.path.join(REPO, "tests", "blender")]
import bpy  # noqa: E402

import window_steps  # noqa: E402
from window_steps import click, run_plan, shading, view3d  # noqa: E402


def shot(name):
    window_steps.shot(OUT, name)


def park():
    window_steps.xdotool("mousemove", "800", "1280")


def prepare():
    import lmrefine_blender
    lmrefine_blender.register()
    s = bpy.context.scene.lmrefine
    s.resolution, s.samples = 256, 8
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.type == 'MESH')
    bpy.context.view_layer.objects.active = bpy.data.objects["Floor"]
    window, area = view3d()
    area.spaces.active.show_region_ui = True
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screen_full_area()
    window_steps.frame((1.0, 0.0, -0.6), 19.0, (0.0, 0.5, 0.5))


def refine():
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        print("RUN", bpy.ops.object.lmrefine_refine_uvs('EXEC_DEFAULT'))
    r = bpy.context.scene.lmrefine.result
    print("RESULT", r.message)


def show(which):
    print("SHOW", which, window_steps.show(which))


def remove():
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.type == 'MESH')
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        print("REMOVE", bpy.ops.object.lmrefine_remove_preview())


def overlay(on, which='REFINED'):
    s = bpy.context.scene.lmrefine
    s.density_map = which
    s.density_overlay = on


def strength0():
    bpy.context.scene.lmrefine.strength = 0.0


PLAN = [prepare, lambda: click(1586, 253), park, lambda: shot("00_panel_before"),
        refine, lambda: None, lambda: shot("01_panel_after"),
        lambda: shading('MATERIAL'), lambda: None, lambda: None, lambda: shot("02_material_after"),
        lambda: show('BEFORE'), lambda: None, lambda: shot("03_material_before"),
        lambda: show('AFTER'), lambda: shading('SOLID', 'TEXTURE'), lambda: shot("04_solid_texture_after"),
        lambda: shading('RENDERED'), lambda: None, lambda: None, lambda: shot("05_rendered_after"),
        lambda: shading('SOLID', 'MATERIAL'), lambda: overlay(True), lambda: None, lambda: shot("06_density_refined"),
        lambda: overlay(False), remove, lambda: shading('MATERIAL'), lambda: None, lambda: shot("07_removed_material"),
        lambda: shading('SOLID', 'MATERIAL'), strength0, refine, lambda: None, lambda: shot("08_nothing_moved"),
        lambda: os._exit(0)]
run_plan(PLAN, 4.0)
