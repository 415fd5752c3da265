"""Steps in a real Blender window (under Xvfb) for the picture scripts: the 3D View, a screenshot, a plan of steps."""

import os
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
