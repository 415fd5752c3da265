"""The Dask cluster a batch runs on: a LocalCluster sized to this machine, or an existing one."""

import importlib.util
import logging
import multiprocessing
import os
from collections import Counter


class Cluster:
    """A connected distributed.Client and how many cores each Blender gets.

    Local: `workers` process workers (default: one per core), one task
    each at a time, every Blender given cores // workers threads. Existing
    (--scheduler): every worker's Blender gets its host's cores divided by
    the workers on that host (the task works it out where it runs)."""

    def __init__(self, scheduler=None, workers=None, retries=2):
        import dask
        from distributed import Client, LocalCluster

        self.local = None
        dashboard = ":0" if importlib.util.find_spec("bokeh") else None
        if scheduler:
            self.client = Client(scheduler, timeout="20s")
            infos = self.client.scheduler_info()["workers"].values()
            if not infos:
                self.client.close()
                raise OSError(f"the scheduler at {scheduler} has no workers: start `dask-worker {scheduler}` "
                              "on the machines with Blender and lmrefine (docs/batch.md)")
            hosts = Counter(info["host"] for info in infos)
            self.threads = dict(hosts)
            self.workers = sum(hosts.values())
        else:
            cores = os.cpu_count() or 1
            self.workers = workers or cores
            if self.workers < 1:
                raise ValueError(f"--workers must be at least 1, got {self.workers}")
            # A worker that dies with its task (a killed process): Dask reruns the task
            # elsewhere this many times before giving up on it.
            dask.config.set({"distributed.scheduler.allowed-failures": max(0, retries)})
            # Worker processes set up their logging from the environment when they import
            # distributed, before silence_logs reaches them: without this each one prints
            # INFO lines about the preload. A user's own setting wins.
            os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "warning")
            # Workers forked from a fork server start in a fraction of the time spawned
            # ones take (they do not import Python, Dask and lmrefine anew), and unlike a
            # plain fork they inherit none of this process's threads. Spawn where there is none.
            if "forkserver" in multiprocessing.get_all_start_methods():
                dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"})
            self.local = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                      dashboard_address=dashboard, silence_logs=logging.ERROR,
                                      host="127.0.0.1", preload=["lmrefine.batch.worker_setup"])
            self.client = Client(self.local)
            self.threads = max(1, cores // self.workers)
        self.dashboard = self._dashboard_link()

    def _dashboard_link(self):
        """The dashboard's address when it can show anything (it needs bokeh,
        which Debian's python3-distributed does not pull in)."""
        if self.local is not None and not importlib.util.find_spec("bokeh"):
            return None
        try:
            services = self.client.scheduler_info().get("services", {})
        except Exception:  # noqa: BLE001 - a link is a nicety
            return None
        return self.client.dashboard_link if "dashboard" in services else None

    def close(self):
        try:
            self.client.close()
        finally:
            if self.local is not None:
                self.local.close()
