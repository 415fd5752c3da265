"""Speed of the layout side of refine_uvs (docs/refiner.md, "Speed of the
layout side"): the original's coverage and gutter texels and check, and the
warp and check of the result (timings "setup" + "warp_and_check"), on the
bench_refine plane (128 x 128 quads) at 512^2 and 1024^2.

Baselines, measured in the same run:
  separate calls   this build, one call per use as refine_uvs made them
                   before LayoutChecker: coverage_mask, gutter_texels and
                   check_layout of the original, then backoff.accept of the
                   refined grid without the shared checker (each call
                   rasterizes and analyses the original on its own).
  --baseline DIR   another build's refine_uvs (e.g. a checkout of main built
                   with `make build`: DIR = its python/ directory), run in a
                   subprocess; a build without LayoutChecker computes the
                   gutter texels in its automaton stage, so they are timed
                   apart and added.

    PYTHONPATH=python /usr/bin/python3 bench/bench_layout_stages.py [--baseline DIR] [--repeats 3]
"""

import argparse
import json
import os
import subprocess
import sys
import time

# Runs as a script in this process and as the child for --baseline builds.
CHILD = r'''
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
import lmrefine
from lmrefine import _native
from bench_refine import scene
from layouts import finite_difference_gradient
resolution, repeats = int(sys.argv[2]), int(sys.argv[3])
uvs, tris, lightmap = scene(resolution)
mask = lmrefine.coverage_mask(uvs, tris, resolution)
gradient = finite_difference_gradient(lightmap, mask)  # the same gradient map for every build
best = float("inf")
for _ in range(repeats):
    report = lmrefine.refine_uvs(None, uvs, tris, resolution, gradient=gradient).report
    seconds = report["timings"]["setup"] + report["timings"]["warp_and_check"]
    if not hasattr(_native, "LayoutChecker"):
        start = time.perf_counter()
        _native.gutter_texels(uvs, tris, resolution)
        seconds += time.perf_counter() - start
    best = min(best, seconds)
print(json.dumps(best))
'''

HERE = os.path.dirname(os.path.abspath(__file__))
TESTS = os.path.join(HERE, "..", "tests")


def refine_layout_stages(python_dir, resolution, repeats):
    env = dict(os.environ, PYTHONPATH=python_dir)
    done = subprocess.run([sys.executable, "-c", CHILD, HERE + os.pathsep + TESTS, str(resolution), str(repeats)],
                          env=env, capture_output=True, text=True, check=True, cwd=HERE)
    return json.loads(done.stdout.strip().splitlines()[-1])


def separate_calls(resolution, repeats):
    import numpy as np
    import lmrefine
    from lmrefine import backoff
    from bench_refine import scene
    uvs, tris, lightmap = scene(resolution)
    uvs, tris = np.asarray(uvs, np.float32), np.asarray(tris, np.int32)
    full = lmrefine.refine_uvs(lightmap, uvs, tris, resolution).grid
    identity = lmrefine.identity_grid(resolution)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        lmrefine.coverage_mask(uvs, tris, resolution)
        lmrefine._native.gutter_texels(uvs, tris, resolution)
        original = lmrefine.check_layout(uvs, tris, resolution, 2)
        # Without the caller's checker, accept analyses the original again.
        backoff.accept(full, identity, uvs, tris, (resolution, resolution), 2, original)
        best = min(best, time.perf_counter() - start)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="python/ directory of another lmrefine build")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    this = os.path.join(HERE, "..", "python")
    print(f"threads: {os.environ.get('LMREFINE_THREADS', os.cpu_count())}; load average "
          f"{os.getloadavg()[0]:.1f} (a shared machine: compare ratios); best of {args.repeats}")
    print(f"{'size':>6} {'layout stages ms':>17} {'separate calls ms':>18} {'ratio':>6}"
          + (f" {'baseline ms':>12} {'ratio':>6}" if args.baseline else ""))
    sys.path[:0] = [HERE, TESTS]
    for resolution in (512, 1024):
        ours = refine_layout_stages(this, resolution, args.repeats)
        separate = separate_calls(resolution, args.repeats)
        line = f"{resolution:>5}^2 {ours * 1e3:>17.1f} {separate * 1e3:>18.1f} {separate / ours:>5.2f}x"
        if args.baseline:
            base = refine_layout_stages(os.path.abspath(args.baseline), resolution, args.repeats)
            line += f" {base * 1e3:>12.1f} {base / ours:>5.2f}x"
        print(line, flush=True)


if __name__ == "__main__":
    main()
