"""Batch refinement of many levels (.blend files) on Dask distributed.

``python3 -m lmrefine batch LEVEL.blend|DIR ... --out OUT``: one task per
level, each running headless Blender with the add-on's batch entry; a
manifest in OUT makes the batch resumable. Guide: docs/batch.md.
"""

from .runner import BatchOptions, run_batch  # noqa: F401
