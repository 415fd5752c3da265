"""lmrefine's packer against libnest2d (Debian libnest2d-dev: no-fit-polygon
irregular nesting, first-fit selection) on the same charts (docs/packer.md,
"Why a texel raster packer").

libnest2d packs polygons: each chart's outer outline (its boundary loop of
largest area; holes are filled), in texels. Both search the largest global
scale (libnest2d: bisection, `--iterations` nests); both may turn charts by
0 or 90 degrees; padding 2 texels (libnest2d's minimum distance between
items, plus 0.01 texel for rounding). Both outputs are measured the same way: utilisation =
coverage_mask of the output layout, validity = check_layout with the padding.

Needs `apt-get install libnest2d-dev libpolyclipping-dev libnlopt-cxx-dev`
(a measurement only: lmrefine does not use libnest2d; named compare_*, not
bench_*, so `make bench` / bench/run.py do not need those packages).

    PYTHONPATH=python /usr/bin/python3 bench/compare_libnest2d.py [--resolution 512] [--iterations 8] [--timeout 600]
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import lmrefine  # noqa: E402
from bench_packer import SAMPLES, many_charts  # noqa: E402


def build():
    binary = os.path.join(tempfile.gettempdir(), "lmrefine_libnest2d_pack")
    source = os.path.join(HERE, "libnest2d_pack.cpp")
    if not os.path.exists(binary) or os.path.getmtime(binary) < os.path.getmtime(source):
        # The definitions libnest2d's CMake package would add (Libnest2DTargets.cmake).
        subprocess.run(["g++", "-std=c++17", "-O2", "-DLIBNEST2D_THREADING_std", "-DLIBNEST2D_GEOMETRIES_clipper",
                        "-DLIBNEST2D_OPTIMIZER_nlopt", source, "-o", binary, "-lpolyclipping", "-lnlopt", "-pthread"],
                       check=True)
    return binary


def convex_hull(points):
    points = sorted(set(map(tuple, points)))
    if len(points) < 3:
        return np.array(points)

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(points), half(reversed(points))
    return np.array(lower[:-1] + upper[:-1])


def outline(uvs, tris):
    """The chart's outer boundary loop (counter-clockwise), or its convex
    hull where the boundary does not chain into simple loops."""
    keys = {}
    ids = np.array([keys.setdefault((float(u), float(v)), len(keys)) for u, v in uvs[tris.ravel()]])
    ids = ids.reshape(-1, 3)
    points = np.zeros((len(keys), 2))
    points[ids.ravel()] = uvs[tris.ravel()]
    edges = {}
    for a, b, c in ids:
        for e in ((a, b), (b, c), (c, a)):
            key = (min(e), max(e))
            edges[key] = edges.get(key, 0) + 1
    boundary = [e for e, n in edges.items() if n == 1]
    neighbours = {}
    for a, b in boundary:
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    if not boundary or any(len(n) != 2 for n in neighbours.values()):
        return convex_hull(points[ids.ravel()])
    loops, seen = [], set()
    for start in neighbours:
        if start in seen:
            continue
        loop, previous, current = [start], None, start
        seen.add(start)
        while True:
            a, b = neighbours[current]
            nxt = b if a == previous else a
            if nxt == start:
                break
            loop.append(nxt)
            seen.add(nxt)
            previous, current = current, nxt
        loops.append(points[loop])

    def area(p):
        return 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])

    best = max(loops, key=lambda p: abs(area(p)))
    return best if area(best) > 0 else best[::-1]


def libnest2d_pack(binary, uvs, tris, resolution, padding, iterations, timeout):
    # The charts as lmrefine's packer leaves them (the same shapes, scaled
    # alike): their corners within the tolerance are bit-exact, so outlines
    # chain; libnest2d still chooses every position and turn itself.
    uvs, report = lmrefine.pack_charts(uvs, tris, None, None, resolution, padding)
    charts = report["chart_ids"]
    count = report["charts"]
    # libnest2d keeps the distance exactly; 0.01 texel more survives its
    # integer coordinates and the float32 output (else gutters of 1.999).
    lines = [f"{resolution} {padding + 0.01} 1 {iterations}", str(count)]
    shapes = []
    for c in range(count):
        t = tris[charts == c]
        shape = outline(uvs, t) * resolution
        shapes.append(shape)
        lines.append(f"{len(shape)} " + " ".join(f"{x:.6f} {y:.6f}" for x, y in shape))
    start = time.perf_counter()
    try:
        done = subprocess.run([binary], input="\n".join(lines), capture_output=True, text=True, timeout=timeout,
                              check=True)
    except subprocess.TimeoutExpired:
        return None, None, time.perf_counter() - start
    rows = done.stdout.split("\n")
    scale, seconds = map(float, rows[0].split())
    out = uvs.copy()
    if scale == 0:
        return None, 0.0, seconds
    for c in range(count):
        rotation, tx, ty = map(float, rows[1 + c].split())
        m = np.array([[np.cos(rotation), -np.sin(rotation)], [np.sin(rotation), np.cos(rotation)]])
        corners = np.unique(tris[charts == c])
        p = uvs[corners].astype(np.float64) * resolution * scale
        out[corners] = (p @ m.T + (tx, ty)) / resolution
    return out, scale * report["global_scale"], seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--resolution", type=int, default=512)
    parser.add_argument("--iterations", type=int, default=8)
    parser.add_argument("--timeout", type=float, default=600)
    parser.add_argument("--many", type=int, default=500, help="charts in the random many-charts layout")
    args = parser.parse_args()
    binary = build()
    padding, resolution = 2.0, args.resolution
    cases = []
    for name in ("courtyard", "game_level", "fence_and_tree", "room"):
        data = np.load(os.path.join(SAMPLES, name + ".npz"))
        cases.append((f"{name} smart", data["uv_smart"]))
    uvs, tris = many_charts(args.many)
    cases.append((f"{args.many} random charts", (uvs, tris)))
    print(f"{resolution}^2, padding {padding:g}, libnest2d NfpPlacer + FirstFitSelection, {args.iterations} bisection steps")
    print(f"{'layout':22} {'charts':>6} | {'lmrefine util':>13} {'s':>7} | {'libnest2d util':>14} {'s':>8} {'valid':>6}")
    for label, layout in cases:
        if isinstance(layout, tuple):
            uvs, tris = layout
        else:
            uvs, tris = layout, np.arange(len(layout), dtype=np.int32).reshape(-1, 3)
        start = time.perf_counter()
        _, report = lmrefine.pack_charts(uvs, tris, None, None, resolution, padding)
        ours = time.perf_counter() - start
        out, scale, seconds = libnest2d_pack(binary, uvs, tris, resolution, padding, args.iterations, args.timeout)
        if out is None:
            theirs = f"{'(none)':>14} {seconds:8.1f} {'':>6}"
        else:
            check = lmrefine.check_layout(out, tris, resolution, padding)
            util = lmrefine.coverage_mask(out, tris, resolution).mean()
            theirs = f"{util:14.3f} {seconds:8.2f} {str(check['valid']):>6}"
        print(f"{label:22} {report['charts']:6} | {report['utilisation']:13.3f} {ours:7.3f} | {theirs}", flush=True)


if __name__ == "__main__":
    main()
