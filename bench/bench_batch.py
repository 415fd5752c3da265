"""Benchmark of `python3 -m lmrefine batch` (docs/batch.md), as ratios measured in one run.

Levels: LEVELS tiny generated levels (tests/blender/make_levels.py: a floor,
a cube, a sun; refined at 64^2). Baselines, all in the same run:

  sequential   a plain loop running the same Blender commands one after the
               other (blender_command, all cores to each Blender);
  dask 1       the batch on a LocalCluster of 1 worker: its overhead over the
               loop (target: at most 5%), and that overhead split into the
               cluster's start (measured on its own, in a fresh process: once
               per batch) and the rest, per level;
  dask 2       2 workers against 1: parallel efficiency
               time(1) / (2 * time(2)) (target: at least 0.8 on 2 cores);
  resume       a re-run of a finished batch of RESUME_LEVELS levels (copies of
               one level): every level skipped, no Blender started
               (target: under 2 s for 100 levels).

    PYTHONPATH=python /usr/bin/python3 bench/bench_batch.py [--levels 6] [--resume-levels 100] [--resolution 64]

Tiny levels take about a second each, so the cluster's fixed start shows as
a large share of them; `--resolution 256` makes levels of a few seconds.
"""

import argparse
import io
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "python"))
from lmrefine.batch import BatchOptions, run_batch  # noqa: E402
from lmrefine.batch.blender_command import (blender_command, blender_environment,  # noqa: E402
                                            find_batch_script, find_blender)

FLAGS = ["--objects", "all", "--resolution", "64", "--samples", "4"]

# The cold start and close of a 1-worker LocalCluster, in a fresh process
# (the fork server starts with the first cluster a process makes).
CLUSTER_START = """
import time
if __name__ == "__main__":
    from lmrefine.batch.cluster import Cluster
    started = time.perf_counter()  # imports done, as in the benchmark's own process
    Cluster(workers=1).close()
    print(time.perf_counter() - started)
"""


def cluster_start():
    with tempfile.TemporaryDirectory() as folder:
        script = os.path.join(folder, "start.py")
        with open(script, "w") as handle:
            handle.write(CLUSTER_START)
        env = dict(os.environ, PYTHONPATH=os.path.join(REPO, "python"))
        done = subprocess.run([sys.executable, script], check=True, capture_output=True, text=True, env=env,
                              timeout=120)
        return float(done.stdout.strip().splitlines()[-1])


def make_levels(folder, count):
    blender = find_blender()
    names = [f"level{i:03d}:{i}" for i in range(count)]
    subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                    os.path.join(REPO, "tests", "blender", "make_levels.py"), "--", folder, *names],
                   check=True, capture_output=True, timeout=600)
    return sorted(os.path.join(folder, f) for f in os.listdir(folder) if f.endswith(".blend"))


def sequential(levels, out):
    blender, script = find_blender(), find_batch_script()
    started = time.perf_counter()
    for path in levels:
        level_out = os.path.join(out, os.path.splitext(os.path.basename(path))[0])
        subprocess.run(blender_command(blender, script, path, level_out, FLAGS, None), check=True,
                       capture_output=True, env=blender_environment(None), timeout=600)
    return time.perf_counter() - started


def dask_batch(levels, out, workers):
    started = time.perf_counter()
    summary = run_batch(levels, out, BatchOptions(flags=FLAGS, workers=workers), stream=io.StringIO())
    seconds = time.perf_counter() - started
    if not summary["ok"]:
        raise SystemExit(f"the batch failed: {summary}")
    return seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", type=int, default=6)
    parser.add_argument("--resume-levels", type=int, default=100)
    parser.add_argument("--resolution", type=int, default=64)
    args = parser.parse_args()
    FLAGS[FLAGS.index("--resolution") + 1] = str(args.resolution)
    work = tempfile.mkdtemp(prefix="lmrefine_bench_batch_")
    try:
        levels = make_levels(os.path.join(work, "levels"), args.levels)
        loop = sequential(levels, os.path.join(work, "loop"))
        one = dask_batch(levels, os.path.join(work, "dask1"), 1)
        two = dask_batch(levels, os.path.join(work, "dask2"), 2)
        start = min(cluster_start() for _ in range(2))
        print(f"{len(levels)} levels at {args.resolution}^2, {os.cpu_count()} cores")
        print(f"  sequential loop       {loop:7.2f} s   {loop / len(levels):.2f} s a level")
        print(f"  dask, 1 worker        {one:7.2f} s   overhead over the loop {one / loop - 1:+.1%}  (target <= +5%)")
        print(f"    of which the cluster's start, once a batch: {start:.2f} s; the rest "
              f"{(one - loop - start) / len(levels) * 1000:+.0f} ms a level ({(one - start) / loop - 1:+.1%})")
        print(f"  dask, 2 workers       {two:7.2f} s   parallel efficiency {one / (2 * two):.2f}  (target >= 0.8)")

        # Resume: RESUME_LEVELS copies of one level, done once, then re-run with nothing to do.
        many = os.path.join(work, "many")
        os.makedirs(many)
        for i in range(args.resume_levels):
            shutil.copy(levels[0], os.path.join(many, f"copy{i:03d}.blend"))
        out = os.path.join(work, "resume")
        dask_batch([many], out, 2)
        started = time.perf_counter()
        summary = run_batch([many], out, BatchOptions(flags=FLAGS, workers=2), stream=io.StringIO())
        resume = time.perf_counter() - started
        skipped = sum(1 for row in summary["levels"] if str(row["status"]).startswith("skipped"))
        print(f"  resume, {args.resume_levels} done levels {resume:7.2f} s   {skipped} skipped  (target < 2 s)")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
