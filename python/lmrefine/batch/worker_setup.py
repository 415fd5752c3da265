"""Preloaded into the local cluster's worker processes (Dask's `preload`).

A terminal's Ctrl-C reaches every process of the foreground group. The batch
driver handles it (cancels, writes the manifest, closes the cluster, which
ends the workers and their Blenders); workers that also died of it would
print tracebacks and race the driver, so they ignore it.
"""

import signal


def dask_setup(worker):  # noqa: ARG001 - Dask's preload hook
    signal.signal(signal.SIGINT, signal.SIG_IGN)
