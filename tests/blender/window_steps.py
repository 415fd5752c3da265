"""Steps in a real Blender window (under Xvfb) for the picture scripts: the 3D View, a screenshot, a plan of steps."""

import os
import subprocess
import traceback

import bpy


def view3d():
    """(window, the largest 3D View area) of the first window."""
    window = bpy.context.window_manager.windows[0]
    return window, max((a for a in window.screen.areas if a.type == 'VIEW_3D'), key=lambda a: a.width * a.height)


def shot(out, name):
    """A screenshot of the whole window into OUT/name.png."""
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screenshot(filepath=os.path.join(out, name + ".png"))


def frame(rotation, distance, location, sidebar=True):
    """The 3D View's camera: perspective, turned by `rotation` (XYZ Euler, radians), `distance` from
    `location`; no floor grid or axes; the sidebar shown or hidden. Returns the View's space."""
    from mathutils import Euler
    space = view3d()[1].spaces.active
    space.show_region_ui = sidebar
    space.overlay.show_floor = space.overlay.show_axis_x = space.overlay.show_axis_y = False
    view = space.region_3d
    view.view_perspective = 'PERSP'
    view.view_rotation = Euler(rotation).to_quaternion()
    view.view_distance, view.view_location = distance, location
    return space


def xdotool(*args):
    """An input event the window receives as a user's (Xvfb's pointer)."""
    subprocess.run(["xdotool", *args], check=True)


def click(x, y):
    xdotool("mousemove", str(x), str(y), "click", "1")


def shading(kind, color=None):
    """The 3D View's shading type (and Solid's colour type)."""
    space = view3d()[1].spaces.active
    space.shading.type = kind
    if color:
        space.shading.color_type = color


def show(which):
    """The add-on's Before / After switch ('BEFORE' or 'AFTER'); the operator's result."""
    window, area = view3d()
    with bpy.context.temp_override(window=window, area=area):
        return bpy.ops.object.lmrefine_show_preview(shown=which)


def run_plan(plan, interval, first=2.0):
    """Run the callables of `plan` one per timer tick, `interval` seconds apart
    (the window draws in between); a step that fails is printed and skipped."""
    def tick():
        step = plan.pop(0)
        try:
            step()
        except Exception:  # noqa: BLE001  (a picture tool: say what failed, keep going)
            traceback.print_exc()
        return interval if plan else None

    bpy.app.timers.register(tick, first_interval=first)
