"""Blender's own Cycles bake, driven so that it leaves the scene as it found it.

Pass mapping (lmrefine's pass names -> Cycles bake):
    direct   -> DIFFUSE, pass filter {DIRECT}            (colour off)
    indirect -> DIFFUSE, pass filter {INDIRECT}          (colour off)
    combined -> DIFFUSE, pass filter {DIRECT, INDIRECT}  (colour off)
    ao       -> AO
"""

from contextlib import contextmanager

import bpy

from . import bridge
from .materials import BakeTarget

BAKE_ARGS = {
    "direct": {"type": 'DIFFUSE', "pass_filter": {'DIRECT'}},
    "indirect": {"type": 'DIFFUSE', "pass_filter": {'INDIRECT'}},
    "combined": {"type": 'DIFFUSE', "pass_filter": {'DIRECT', 'INDIRECT'}},
    "ao": {"type": 'AO', "pass_filter": set()},
}


@contextmanager
def render_settings(context, samples):
    """Cycles with denoising off (Debian's Blender has no OpenImageDenoise); everything restored on exit."""
    scene = context.scene
    view_layer = context.view_layer
    saved_engine = scene.render.engine
    saved_selection = [obj for obj in view_layer.objects if obj.select_get()]
    saved_active = view_layer.objects.active
    scene.render.engine = 'CYCLES'  # scene.cycles exists once Cycles is the engine
    cycles = scene.cycles
    saved_cycles = {name: getattr(cycles, name) for name in
                    ("samples", "use_denoising", "use_preview_denoising", "use_adaptive_sampling")}
    try:
        cycles.samples = samples
        cycles.use_denoising = False
        cycles.use_preview_denoising = False
        cycles.use_adaptive_sampling = False  # bakes have no adaptive sampling: keep the settings honest
        yield
    finally:
        for name, value in saved_cycles.items():
            setattr(cycles, name, value)
        scene.render.engine = saved_engine
        for obj in view_layer.objects:
            obj.select_set(obj in saved_selection)
        view_layer.objects.active = saved_active


def bake_object(context, obj, uv_name, pass_name, resolution, margin):
    """Bake `pass_name` of `obj` with UV map `uv_name`; returns (R, R, 4) float32, row 0 at the top.

    Call inside render_settings(). Only `obj` is selected while it bakes, into
    a temporary float image that is removed afterwards.
    """
    arguments = BAKE_ARGS[pass_name]
    view_layer = context.view_layer
    image = bridge.new_float_image(f"lmrefine bake {obj.name}", resolution)
    try:
        with BakeTarget(obj, image):
            for other in view_layer.objects:
                other.select_set(other == obj)
            view_layer.objects.active = obj
            result = bpy.ops.object.bake(
                type=arguments["type"], pass_filter=arguments["pass_filter"], uv_layer=uv_name,
                margin=margin, margin_type='EXTEND', use_clear=True, use_selected_to_active=False,
                target='IMAGE_TEXTURES', save_mode='INTERNAL')
            if 'FINISHED' not in result:
                raise RuntimeError(f"Cycles could not bake '{obj.name}' (see the console)")
        return bridge.image_to_array(image)
    finally:
        bpy.data.images.remove(image)
