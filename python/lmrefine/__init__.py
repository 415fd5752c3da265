"""lmrefine: sharper baked lightmaps from the same texels.

Bake a lightmap, find where light changes fast with a wavelet gradient map,
deform the lightmap UV layout with a cellular automaton so those places get
more texels, and bake again. numpy in, numpy out; the heavy lifting is in the
native extension ``lmrefine._native``, re-exported here.

Array conventions (shared by every function):

* Lightmaps are float32 arrays (H, W) or (H, W, C), row 0 at the top of the
  image (v = 1), linear light. Texel (i, j) covers u in [j/W, (j+1)/W],
  v in [1-(i+1)/H, 1-i/H].
* UV layouts are per-corner UVs (N, 2) and triangles (T, 3) of indices.
"""

import os as _os

try:
    from . import _native
except ImportError as error:  # pragma: no cover - depends on the build state
    raise ImportError(
        "lmrefine's native extension is not built or does not match this Python "
        f"({error}). Run `make build` in the lmrefine checkout (or `make install`)."
    ) from error

from ._native import (  # noqa: F401  (re-exports)
    CancelledError,
    LayoutChecker,
    Scene,
    check_layout,
    coverage_mask,
    dwt,
    dwt2,
    find_charts,
    gradient_map,
    grid_cell_areas,
    idwt,
    idwt2,
    read_image,
    run_automaton,
    warp_uvs,
    write_image,
)
from .baker import BakeResult, bake, dilate, evaluate, trace_rays  # noqa: F401  (re-exports)
from .charting import RechartResult, rechart  # noqa: F401
from .packer import CHART_TOLERANCE, PackResult, pack_charts  # noqa: F401
from .refine import RefineResult, identity_grid, refine_uvs  # noqa: F401
from .tessellation import (TessellationResult, tessellate, tessellated_refine_options,  # noqa: F401
                           transition_strength_of)

__version__ = _native.__version__

# oneTBB, which runs the native loops, does not survive a fork taken while its
# workers run: a child made by fork() runs them serially (same results).
if hasattr(_os, "register_at_fork"):
    _os.register_at_fork(after_in_child=_native._serial_after_fork)

__all__ = [
    "CHART_TOLERANCE",
    "BakeResult",
    "CancelledError",
    "LayoutChecker",
    "PackResult",
    "RechartResult",
    "RefineResult",
    "Scene",
    "TessellationResult",
    "bake",
    "check_layout",
    "coverage_mask",
    "dilate",
    "dwt",
    "dwt2",
    "evaluate",
    "find_charts",
    "gradient_map",
    "grid_cell_areas",
    "identity_grid",
    "idwt",
    "idwt2",
    "pack_charts",
    "read_image",
    "rechart",
    "refine_uvs",
    "run_automaton",
    "trace_rays",
    "tessellate",
    "tessellated_refine_options",
    "transition_strength_of",
    "warp_uvs",
    "write_image",
]
