"""lmrefine for Blender: refine lightmap UV layouts so shadow edges get more texels.

A thin layer over the lmrefine package (native C++ core): bridge.py turns the
scene into numpy arrays, pipeline.py runs the job, operators/panels/properties
are the UI, overlay.py draws the texel-density overlay. The native core
(lmrefine) loads when the operator first runs.
"""

bl_info = {
    "name": "lmrefine: Refine Lightmap UVs",
    "author": "lmrefine contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "3D View > Sidebar > Lightmap",
    "description": "Deform lightmap UVs so light/shadow transitions get more texels, then bake again",
    "category": "UV",
}

import os
import sys

# The release zip carries the lmrefine package (with its compiled extension)
# in lib/ beside this file; a development checkout puts python/ on sys.path.
_LIB = os.path.join(os.path.dirname(__file__), "lib")
if os.path.isdir(_LIB) and _LIB not in sys.path:
    sys.path.insert(0, _LIB)

from . import operators, overlay, panels, properties  # noqa: E402  (after the sys.path set-up)


def register():
    properties.register()
    operators.register()
    panels.register()
    overlay.register()


def unregister():
    overlay.unregister()
    panels.unregister()
    operators.unregister()
    properties.unregister()
