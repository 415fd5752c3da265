"""Speed of find_charts with a tolerance (the weld the packer and the chart
stages use) when corners crowd together: every corner at one point (UVs left
at 0), or thousands within a fraction of the tolerance. A crash hunt found
both quadratic (11 s for 20,000 triangles at one point); the weld now joins
a crowd in near-linear time.

Baseline, measured in the same run: the same number of triangles spread as a
per-corner layout of one grid chart (the ordinary case). The ratio crowd /
spread stays near 1 or below at every size when the weld is near-linear; a
quadratic weld's ratio grows with the size.

    PYTHONPATH=python /usr/bin/python3 bench/bench_charts.py [--repeats 3]
"""

import argparse
import os
import time

import numpy as np

import lmrefine


def spread_layout(triangles):
    """A per-corner grid chart of about `triangles` triangles in [0, 1]^2."""
    n = max(1, int(np.sqrt(triangles / 2)))
    grid = np.stack(np.meshgrid(np.arange(n + 1), np.arange(n + 1)), -1).reshape(-1, 2) / n
    quad = np.arange(n * n)
    a = (quad // n) * (n + 1) + quad % n
    shared = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    uvs = grid[shared.ravel()].astype(np.float32)
    return uvs, np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)


def crowded_layout(triangles, spread, seed=1):
    """`triangles` per-corner triangles whose corners lie within `spread` of one point."""
    rng = np.random.default_rng(seed)
    uvs = (0.5 + rng.normal(0.0, spread, (3 * triangles, 2))).astype(np.float32)
    return uvs, np.arange(3 * triangles, dtype=np.int32).reshape(-1, 3)


def best_cpu(repeats, call):
    best = float("inf")
    for _ in range(repeats):
        start = time.process_time()
        call()
        best = min(best, time.process_time() - start)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    tolerance = lmrefine.CHART_TOLERANCE
    print(f"threads: {os.environ.get('LMREFINE_THREADS', os.cpu_count())}; CPU time, best of {args.repeats}; "
          f"tolerance {tolerance:g}")
    print(f"{'triangles':>10} {'spread ms':>10} {'one point ms':>13} {'ratio':>6} {'crowd ms':>9} {'ratio':>6}")
    for triangles in (20000, 80000, 320000):
        uvs, tris = spread_layout(triangles)
        spread = best_cpu(args.repeats, lambda: lmrefine.find_charts(uvs, tris, tolerance))
        point = crowded_layout(len(tris), 0.0)
        at_point = best_cpu(args.repeats, lambda: lmrefine.find_charts(*point, tolerance))
        crowd = crowded_layout(len(tris), tolerance / 10)
        within = best_cpu(args.repeats, lambda: lmrefine.find_charts(*crowd, tolerance))
        print(f"{len(tris):>10} {spread * 1e3:>10.1f} {at_point * 1e3:>13.1f} {at_point / spread:>5.2f}x"
              f" {within * 1e3:>9.1f} {within / spread:>5.2f}x", flush=True)


if __name__ == "__main__":
    main()
