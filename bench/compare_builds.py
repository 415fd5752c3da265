"""Compare two builds of lmrefine bit for bit.

Runs the same fixed inputs through two builds, each in its own subprocess
(PYTHONPATH = that build's python/ directory), and compares every output
array exactly (same dtype, shape and bytes; NaNs compare equal to NaNs):

* refine_uvs on random gradient maps (every border mode, scalar and
  directional, one and two passes) on a tessellated plane and a Lightmap
  Pack layout, and on the bundled scenes' layouts in blend_samples/;
* gradient_map, dwt2 and idwt2 on random images (every wavelet);
* check_layout on the same layouts and on the refined ones;
* find_charts at several tolerances on the bundled layouts and on crowded corners;
* bake of a small bundled scene with a fixed seed.

Timings (report["timings"], bake stats' seconds and rays per second) are
left out; everything else a call returns is compared.

    /usr/bin/python3 bench/compare_builds.py --base /work/base/python --new python
    /usr/bin/python3 bench/compare_builds.py --base ... --new ... --threads 1 --size 256

Prints one row per case and exits 1 if any output differs (or a case fails
in one build only), 0 otherwise.
"""

import argparse
import json
import inspect
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

# refine_uvs report keys redefined or added after eb486a1 (measured on the output layout, the
# repack, notes on what did not move): compared only between builds that share their meaning.
REDEFINED_REPORT_KEYS = ("transition_widening", "density_min", "density_max", "moved", "repack", "notes")

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SKIPPED_KEYS = ("timings", "seconds", "rays_per_second", "pass_seconds")


# ---------------------------------------------------------------- worker side

def flatten(value, prefix, out):
    """Every number and array in a (nested) result, keyed by its path."""
    if isinstance(value, dict):
        for key in sorted(value, key=str):
            if str(key) in SKIPPED_KEYS:
                continue
            flatten(value[key], f"{prefix}.{key}", out)
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            flatten(item, f"{prefix}[{index}]", out)
    elif isinstance(value, (str, type(None))):
        out[prefix] = np.frombuffer(json.dumps(value).encode(), np.uint8)
    else:
        out[prefix] = np.asarray(value)


def cases(size):
    """(name, function returning a result) for every compared call."""
    import lmrefine
    from lmrefine.sample_scenes import load_sample, sample_names

    sys.path.insert(0, os.path.join(ROOT, "tests"))
    from layouts import lightmap_pack, plane  # noqa: E402

    rng = np.random.default_rng(20261125)
    layouts = {"plane": plane(48, margin=0.02),
               "lightmap_pack": lightmap_pack(charts_across=8, resolution=size, seed=3)}
    gradient = rng.random((size, size, 4), dtype=np.float32) ** 4  # sparse strong changes
    gradient[size // 3:size // 3 + 3] += 2.0  # one hard edge across the map
    listed = []

    def refine(layout, **options):
        uvs, tris = layouts[layout]

        def run():
            # The in-chart refinement only: the chart repack (repack=True, the default since
            # the atlas issue) is new behaviour that a build before it cannot reproduce.
            extra = {"repack": False} if "repack" in inspect.signature(lmrefine.refine_uvs).parameters else {}
            result = lmrefine.refine_uvs(None, uvs, tris, size, gradient=gradient, **options, **extra)
            # Figures whose definition changed on purpose (now measured on the returned layout).
            report = {k: v for k, v in result.report.items() if k not in REDEFINED_REPORT_KEYS}
            return {"uvs": result.uvs, "grid": result.grid, "report": report}
        return run

    for layout in layouts:
        for border in ("same", "border_rule", "extra_ring"):
            for directional in (False, True):
                for passes in (1, 2):
                    name = f"refine {layout} {border} {'four-spring' if directional else 'scalar'} passes={passes}"
                    listed.append((name, refine(layout, border=border, directional=directional, passes=passes)))

    images = {"grey": rng.random((size, size), dtype=np.float32),
              "rgb": (rng.random((size // 2, size, 3), dtype=np.float32) * 4).astype(np.float32)}
    for wavelet in ("haar", "d4", "cdf53", "cdf97"):
        for kind, image in images.items():
            listed.append((f"gradient_map {kind} {wavelet}",
                           lambda image=image, wavelet=wavelet: lmrefine.gradient_map(image, wavelet=wavelet)))
        listed.append((f"dwt2/idwt2 {wavelet}", lambda wavelet=wavelet: (
            lambda bands: {"bands": bands, "inverse": lmrefine.idwt2(bands, wavelet=wavelet)})(
                lmrefine.dwt2(images["grey"], wavelet=wavelet))))

    # Corners in crowds (some within the tolerance, some bit-identical) and spread.
    centres = np.repeat(rng.random((300, 2)), 10, axis=0)
    crowds = centres + rng.normal(0, 1e-5, (3000, 2)) * (rng.random((3000, 1)) < 0.7)
    crowd_tris = rng.integers(0, 3000, (2000, 3)).astype(np.int32)
    listed.append(("find_charts crowds", lambda: {
        f"tolerance={tolerance:g}": lmrefine.find_charts(crowds.astype(np.float32), crowd_tris, tolerance)
        for tolerance in (0.0, 5e-6, 1e-5, 3e-5, 1e-3)}))

    for layout, (uvs, tris) in layouts.items():
        listed.append((f"check_layout {layout}",
                       lambda uvs=uvs, tris=tris: lmrefine.check_layout(uvs, tris, size, failing_charts=True)))

    samples = os.path.join(ROOT, "blend_samples")  # this checkout's scenes, for both builds
    for scene_name in sample_names(samples):
        scene = load_sample(os.path.join(samples, scene_name + ".npz"))
        for variant in scene.uvs:
            uvs, tris = scene.layout(variant)
            layouts[f"{scene_name}/{variant}"] = (uvs, tris)
            listed.append((f"check_layout {scene_name}/{variant}",
                           lambda uvs=uvs, tris=tris: lmrefine.check_layout(uvs, tris, size, failing_charts=True)))
            listed.append((f"refine {scene_name}/{variant} same scalar passes=1",
                           refine(f"{scene_name}/{variant}")))
            listed.append((f"find_charts {scene_name}/{variant}", lambda uvs=uvs, tris=tris: {
                f"tolerance={tolerance:g}": lmrefine.find_charts(uvs, tris, tolerance)
                for tolerance in (0.0, 1e-6, 1e-5, 1e-3)}))

    # The re-chart route (refine_uvs with the mesh, the repack on): the source refinement, the
    # re-charting, the carried map and the second refinement, on every scene whose layout folds
    # over creases or gives no room. A smooth light with one hard shadow edge stands in for a bake.
    rows, cols = np.mgrid[0:size, 0:size] / size
    light = (0.2 + 0.6 * rows * cols + 0.8 * (cols > 0.37 + 0.2 * rows))[..., None] * np.float32([1.0, 0.9, 0.8])
    light = np.ascontiguousarray(light, np.float32)
    for scene_name in sample_names(samples):
        scene = load_sample(os.path.join(samples, scene_name + ".npz"))
        for variant in scene.uvs:
            uvs, tris = scene.layout(variant)
            listed.append((f"route {scene_name}/{variant}",
                           lambda scene=scene, uvs=uvs, tris=tris: (lambda result: {
                               "uvs": result.uvs, "grid": result.grid,
                               "report": {k: v for k, v in result.report.items() if k != "notes"},
                               "notes": result.report["notes"]})(
                                   lmrefine.refine_uvs(light, uvs, tris, size, positions=scene.corner_positions))))
        listed.append((f"rechart {scene_name}", lambda scene=scene: lmrefine.rechart(
            scene.positions, scene.triangles, 20.0, size)))
    points = rng.uniform(-0.1, 1.1, (20000, 2))
    from lmrefine import metrics
    listed.append(("bilinear_lookup", lambda: metrics.bilinear_lookup(light, points)))

    def bake():
        scene = load_sample(os.path.join(samples, "room.npz"))
        uvs, _ = scene.layout("lightmap")
        result = lmrefine.bake(scene.to_scene(uvs), size // 2, samples=16, seed=7, passes=("direct", "ao"))
        return {"maps": dict(result), "stats": result.stats}
    if "room" in sample_names(samples):
        listed.append(("bake room direct+ao", bake))
    return listed


def worker(output, size, only):
    arrays, rows = {}, []
    for index, (name, run) in enumerate(cases(size)):
        if only and only not in name:
            continue
        start = time.perf_counter()
        try:
            flat = {}
            flatten(run(), "", flat)
            error = None
        except Exception as exc:  # noqa: BLE001 - reported, compared as a result
            flat, error = {}, f"{type(exc).__name__}: {exc}"
        rows.append({"name": name, "seconds": time.perf_counter() - start, "error": error, "keys": sorted(flat)})
        rows[-1]["index"] = index
        for key, value in flat.items():
            arrays[f"{index}{key}"] = value
    np.savez(output, __rows__=np.array(json.dumps(rows)), **arrays)


# ---------------------------------------------------------------- driver side

def run_build(python_dir, args, output):
    # Both builds read this repository's sample scenes, wherever their python/ lies.
    env = dict(os.environ, PYTHONPATH=os.path.abspath(python_dir),
               LMREFINE_SAMPLES=os.path.join(ROOT, "blend_samples"))
    if args.threads:
        env["LMREFINE_THREADS"] = str(args.threads)
    command = [sys.executable, os.path.abspath(__file__), "--worker", output, "--size", str(args.size)]
    if args.only:
        command += ["--only", args.only]
    start = time.perf_counter()
    subprocess.run(command, env=env, check=True, cwd=ROOT)
    with np.load(output) as data:
        rows = json.loads(str(data["__rows__"]))
        arrays = {key: data[key] for key in data.files if key != "__rows__"}
    return rows, arrays, time.perf_counter() - start


def same(a, b):
    """Bit for bit: dtype, shape and bytes (a NaN equals the same NaN)."""
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def describe(a, b):
    if a.dtype != b.dtype or a.shape != b.shape:
        return f"{a.dtype}{a.shape} vs {b.dtype}{b.shape}"
    flat_a, flat_b = a.reshape(a.size, -1).view(np.uint8), b.reshape(b.size, -1).view(np.uint8)
    changed = int(np.count_nonzero(np.any(flat_a != flat_b, axis=1)))
    text = f"{changed}/{a.size} elements differ"
    if a.dtype.kind in "fiub":
        diff = np.abs(a.astype(np.float64) - b.astype(np.float64))
        diff = diff[~np.isnan(diff)]
        text += f", max |diff| {diff.max() if diff.size else 0.0:.9g}"
    return text


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="python/ directory of the reference build")
    parser.add_argument("--new", help="python/ directory of the build under test")
    parser.add_argument("--size", type=int, default=256, help="lightmap side of every case (default 256)")
    parser.add_argument("--threads", type=int, default=0, help="LMREFINE_THREADS for both builds (default: all)")
    parser.add_argument("--only", default="", help="run only the cases whose name contains this text")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, args.size, args.only)
        return 0
    if not args.base or not args.new:
        parser.error("--base and --new are required")
    for path in (args.base, args.new):
        if not os.path.isdir(os.path.join(path, "lmrefine")):
            parser.error(f"{path} has no lmrefine package: give a build's python/ directory")

    with tempfile.TemporaryDirectory() as tmp:
        base_rows, base_arrays, base_seconds = run_build(args.base, args, os.path.join(tmp, "base.npz"))
        new_rows, new_arrays, new_seconds = run_build(args.new, args, os.path.join(tmp, "new.npz"))

    new_by_name = {row["name"]: row for row in new_rows}
    failures = 0
    width = max(len(row["name"]) for row in base_rows)
    print(f"{'case':<{width}}  {'arrays':>6}  {'base s':>7}  {'new s':>7}  result")
    base_names = {row["name"] for row in base_rows}
    missing = [{"name": row["name"], "keys": [], "seconds": float("nan"), "error": None, "index": -1}
               for row in new_rows if row["name"] not in base_names]
    for row in base_rows + missing:
        other = new_by_name.get(row["name"])
        if row["index"] < 0:
            print(f"{row['name']:<{width}}  {'':>6}  {'':>7}  {other['seconds']:>7.3f}  DIFFERENT: missing in the base build")
            failures += 1
            continue
        problems, added = [], {"new": set(), "base": set()}
        if other is None:
            problems.append("missing in the new build")
        elif row["error"] or other["error"]:
            if row["error"] != other["error"]:
                problems.append(f"base: {row['error']}; new: {other['error']}")
        else:
            keys = set(row["keys"]) | set(other["keys"])
            for key in sorted(keys):
                a = base_arrays.get(f"{row['index']}{key}")
                b = new_arrays.get(f"{other['index']}{key}")
                if a is None or b is None:
                    # A report field one build adds: listed apart, list indices folded ([*]).
                    added["new" if a is None else "base"].add(re.sub(r"\[\d+\]", "[*]", key or "result"))
                elif not same(a, b):
                    problems.append(f"{key or 'result'}: {describe(a, b)}")
        problems += [f"{', '.join(sorted(keys))} only in {build}" for build, keys in added.items() if keys]
        failures += bool(problems)
        result = "identical" if not problems else "DIFFERENT: " + "; ".join(problems[:4]) + \
            (f"; ... {len(problems) - 4} more" if len(problems) > 4 else "")
        if not problems and row["error"]:
            result = f"identical (both raise {row['error'][:60]})"
        print(f"{row['name']:<{width}}  {len(row['keys']):>6}  {row['seconds']:>7.3f}  "
              f"{(other or {}).get('seconds', float('nan')):>7.3f}  {result}")
    print(f"{len(base_rows)} cases, {failures} different; base {base_seconds:.1f} s, new {new_seconds:.1f} s "
          f"(wall, each subprocess)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
