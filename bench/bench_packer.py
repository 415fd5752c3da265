"""Benchmark of the atlas packer (docs/packer.md).

1. Speed: 5,000 charts (1-18 triangles, random sizes) at 1024^2, padding 2.
   Baselines measured in the same run:
     refine_uvs 1024   today's refine_uvs on bench_refine's plane at 1024^2
                       (the in-chart refinement the packer is added to);
     shelf packer      bounding boxes, tallest first, on shelves, with the
                       same search for the largest global scale (numpy;
                       what "bounding boxes" would give).
   The target is the packer below 1 s on 2 cores: its time and its ratio to
   refine_uvs at 1024^2 are printed.
2. Utilisation (texels covered by charts in the output, coverage_mask) on
   the bundled scenes' Smart UV and Lightmap Pack layouts at 256^2, 512^2
   and 1024^2, uniform repack (all scales 1), padding 2, against the input
   and the shelf packer.

    PYTHONPATH=python /usr/bin/python3 bench/bench_packer.py [--speed-only | --scenes-only]
"""

import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
sys.path.insert(0, HERE)
import lmrefine  # noqa: E402
from bench_refine import best_of  # noqa: E402
from layouts import grid_chart, merge  # noqa: E402

SAMPLES = os.path.join(HERE, "..", "blend_samples")


def many_charts(count=5000, seed=1):
    """`count` rectangular grid charts of 1-3 x 1-3 quads, sizes varying
    5x, scattered (overlapping) over [0, 1]^2."""
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(count):
        n = int(rng.integers(1, 4))
        s = rng.uniform(0.2, 1.0)
        uvs, tris = grid_chart(n, (0, 0), (s * rng.uniform(0.3, 1.0), s))
        parts.append((uvs * np.float32(0.01) + rng.uniform(0, 0.99, 2).astype(np.float32), tris))
    return merge(*parts)


def shelf_pack(uvs, tris, resolution, padding):
    """Bounding boxes (padding added, each laid wide side down) on shelves,
    tallest first; the largest global scale at which they fit, by bisection.
    Returns (uvs, global scale)."""
    charts = lmrefine.find_charts(uvs, tris, tolerance=lmrefine.CHART_TOLERANCE)
    count = charts.max() + 1
    corner_chart = np.empty(len(uvs), np.int64)
    corner_chart[tris.ravel()] = np.repeat(charts, 3)
    used = np.unique(tris)
    lo = np.full((count, 2), np.inf)
    hi = np.full((count, 2), -np.inf)
    np.minimum.at(lo, corner_chart[used], uvs[used])
    np.maximum.at(hi, corner_chart[used], uvs[used])
    size0 = (hi - lo) * resolution  # texels at scale 1
    turn = size0[:, 1] > size0[:, 0]
    size = np.where(turn[:, None], size0[:, ::-1], size0)
    order = np.argsort(-size[:, 1], kind="stable")
    gap = padding + 2e-3

    def place(scale):
        boxes = np.ceil(size[order] * scale + 2e-3) + gap
        x = y = shelf = 0.0
        at = np.zeros((count, 2))
        for k, (w, h) in zip(order, boxes):
            if x + w - gap > resolution:
                x, y, shelf = 0.0, y + shelf, 0.0
            if w - gap > resolution or y + h - gap > resolution:
                return None
            at[k] = (x, y)
            x += w
            shelf = max(shelf, h)
        return at

    low, high = 0.0, np.sqrt(resolution ** 2 / np.prod(size, axis=1).sum())
    for _ in range(30):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if place(middle) is not None else (low, middle)
    at = place(low)
    out = uvs.copy()
    c = corner_chart[used]
    rel = (uvs[used] - lo[c]) * low * resolution  # texels from the box corner, v up
    t = turn[c]
    rel[t] = np.stack([size0[c[t], 1] * low - rel[t][:, 1], rel[t][:, 0]], axis=1)  # a quarter turn
    out[used, 0] = (at[c, 0] + 1e-3 + rel[:, 0]) / resolution
    out[used, 1] = 1.0 - (at[c, 1] + 1e-3 + size[c, 1] * low - rel[:, 1]) / resolution
    return out, low


def speed():
    print(f"threads: {os.environ.get('LMREFINE_THREADS', os.cpu_count())}; load average: "
          f"{os.getloadavg()[0]:.1f} (a shared machine: compare ratios)")
    uvs, tris = many_charts()
    resolution, padding = 1024, 2.0
    packer_s, (out, report) = best_of(3, lambda: lmrefine.pack_charts(uvs, tris, None, None, resolution, padding))
    # Footprints only: the packer before boxes were tried too (its search is unchanged).
    grid_s, (_, grid_report) = best_of(3, lambda: lmrefine.pack_charts(uvs, tris, None, None, resolution, padding,
                                                                      boxes=False))
    check = lmrefine.check_layout(out, tris, resolution, padding)
    shelf_s, (shelf_uvs, shelf_scale) = best_of(1, lambda: shelf_pack(uvs, tris, resolution, padding))
    shelf_util = lmrefine.coverage_mask(shelf_uvs, tris, resolution).mean()

    from bench_refine import scene
    from layouts import finite_difference_gradient
    puvs, ptris, lightmap = scene(resolution)
    gradient = finite_difference_gradient(lightmap, lmrefine.coverage_mask(puvs, ptris, resolution))
    refine_s, _ = best_of(2, lambda: lmrefine.refine_uvs(None, puvs, ptris, resolution, gradient=gradient))

    print(f"{report['charts']} charts ({len(tris)} triangles) at {resolution}^2, padding {padding:g}")
    print(f"{'':16} {'seconds':>8} {'utilisation':>12} {'global scale':>13}")
    print(f"{'pack_charts':16} {packer_s:8.3f} {report['utilisation']:12.3f} {report['global_scale']:13.3f}"
          f"   trials {report['trials']}, check_layout valid: {check['valid']}")
    print(f"{'  boxes=False':16} {grid_s:8.3f} {grid_report['utilisation']:12.3f} {grid_report['global_scale']:13.3f}"
          f"   footprints only; pack_charts / boxes=False: {packer_s / grid_s:.2f} time; placement kept: "
          f"{report['placement']}")
    print(f"{'shelf packer':16} {shelf_s:8.3f} {shelf_util:12.3f} {shelf_scale:13.3f}   (bounding boxes)")
    print(f"{'refine_uvs 1024':16} {refine_s:8.3f}")
    print(f"pack_charts / refine_uvs at 1024^2: {packer_s / refine_s:.2f}; "
          f"pack_charts / shelf packer: {packer_s / shelf_s:.2f} time, "
          f"{report['utilisation'] / shelf_util:.2f}x utilisation; target: pack_charts < 1 s")


def scenes():
    print("texels covered (coverage_mask) / chart area (triangles), over the atlas; shelf: texels covered")
    print(f"{'scene':16} {'layout':8} {'size':>5} {'input':>13} {'packed':>13} {'shelf':>6} {'charts':>7} {'seconds':>8} "
          f"{'valid':>6} {'placement':>10} {'boxes=False':>13} {'seconds':>8}")
    for name in sorted(f[:-4] for f in os.listdir(SAMPLES) if f.endswith(".npz")):
        data = np.load(os.path.join(SAMPLES, name + ".npz"))
        if "uv_smart" not in data.files:
            continue
        for layout in ("uv_smart", "uv_lightmap"):
            uvs = data[layout]
            tris = np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)
            for resolution in (256, 512, 1024):
                seconds, (out, report) = best_of(1, lambda: lmrefine.pack_charts(uvs, tris, None, None, resolution, 2.0))
                grid_s, (_, grid) = best_of(1, lambda: lmrefine.pack_charts(uvs, tris, None, None, resolution, 2.0,
                                                                            boxes=False))
                valid = lmrefine.check_layout(out, tris, resolution, 2.0)["valid"]
                shelf = lmrefine.coverage_mask(shelf_pack(uvs, tris, resolution, 2.0)[0], tris, resolution).mean()
                print(f"{name:16} {layout[3:]:8} {resolution:5} "
                      f"{report['utilisation_input']:6.3f}/{report['area_utilisation_input']:.3f} "
                      f"{report['utilisation']:6.3f}/{report['area_utilisation']:.3f} {shelf:6.3f} {report['charts']:7} "
                      f"{seconds:8.3f} {str(valid):>6} {report['placement']:>10} "
                      f"{grid['utilisation']:6.3f}/{grid['area_utilisation']:.3f} {grid_s:8.3f}", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--speed-only", action="store_true")
    parser.add_argument("--scenes-only", action="store_true")
    args = parser.parse_args()
    if not args.scenes_only:
        speed()
    if not args.speed_only:
        scenes()
