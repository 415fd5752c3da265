"""Is a change to the automaton as fast as before? The CPU time of
`run_automaton` on the bench plane's energy map (hard shadow edge, D4
gradient map, strength 24), scalar and four-spring; with `--case route`,
of `refine_uvs` on bench_refine's folded_smart_uv case (courtyard's Smart
UV atlas, its bake at a quarter of the size scaled up) without the mesh
(the source refinement) and with it (the re-chart route), and of the
re-chart routes of courtyard's and hillside's Lightmap Pack layouts (the
same bakes, with their faces, as bench_refine's route case); with `--case
first-call`, of one `refine_uvs` in a fresh process (what a click in the
add-on or a level of the batch costs: the memory the call needs is touched
for the first time), on the bench plane and on game_level's Smart UV atlas
with its repack (bench_refine's smart_uv_repack case), wall and CPU time;
with `--case tessellate`, of `tessellate` at the add-on's trial budget
(`TRIAL_BUDGET`, 64x) on a plane of 100,352 triangles under two crossing
shadow edges (about 7,000 splits at 1024^2, the split running to its end);
with `--case packing`, of the native atlas packer alone
(`_native.pack_charts`) on every packing one `refine_uvs` makes on the
routes of courtyard's and game_level's Lightmap Pack and Smart UV layouts
and of hillside's Lightmap Pack layout (each scene's bake at a quarter of
the size scaled up, with its faces, as bench_refine's route case), per
route and their sum: a process of the new build records the packings'
arguments (wrapping `_native.pack_charts` during the refinements) into a
temporary folder, so both builds replay the same packings; in two builds,
each in its own subprocess with PYTHONPATH set to that build's python/
directory, alternating base and new so both see the same machine load.
Prints the best time of each and the ratio new / base.

CPU time of the whole process, one worker thread by default: on a shared
machine that is steadier than wall time (other jobs take cores, not CPU
time); a ratio within about 3% is noise.

    /usr/bin/python3 bench/compare_speed.py --base /tmp/base/python --new python [--rounds 5] [--size 1024] [--threads 1]
    /usr/bin/python3 bench/compare_speed.py --base /tmp/base/python --new python --case route --rounds 3
    /usr/bin/python3 bench/compare_speed.py --base /tmp/base/python --new python --case first-call --threads 2
    /usr/bin/python3 bench/compare_speed.py --base /tmp/base/python --new python --case tessellate --rounds 3
    /usr/bin/python3 bench/compare_speed.py --base /tmp/base/python --new python --case packing --rounds 3
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))

CHILD = r"""
import json, sys, time
size, tests = int(sys.argv[1]), sys.argv[2]
sys.path.insert(0, tests)
import numpy as np
import lmrefine
from layouts import plane, shadow_edge_lightmap
uvs, tris = plane(128, margin=0.02)
lightmap = shadow_edge_lightmap(size, 0.5, 0.3)
mask = lmrefine.coverage_mask(uvs, tris, size)
gradient = lmrefine.gradient_map(lightmap, mask)
times = {}
for name, energy in (("scalar", gradient.sum(axis=2)), ("four-spring", gradient)):
    scale = max(float(np.percentile(energy[mask], 99)), 1e-9)
    energy = ((1 + 24 * np.clip(energy / scale, 0, 1)) / 25).astype(np.float32)
    energy[~mask] = 0
    best = float("inf")
    for _ in range(3):
        start = time.process_time()
        lmrefine.run_automaton(energy, mask)
        best = min(best, time.process_time() - start)
    times[name] = best
print(json.dumps(times))
"""

ROUTE_CHILD = r"""
import json, sys, time
size = int(sys.argv[1])
import numpy as np
import lmrefine
from lmrefine.sample_scenes import load_sample
sample = load_sample("courtyard")
uvs, tris = sample.layout("smart")
positions = sample.positions[sample.triangles].reshape(-1, 3)
small = lmrefine.bake(sample.to_scene(uvs), size // 4, passes="direct", samples=8, seed=0)[0][..., :3]
lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
times = {}


def best_of_two(name, lightmap, uvs, tris, **extra):
    best = float("inf")
    for _ in range(2):
        start = time.process_time()
        result = lmrefine.refine_uvs(lightmap, uvs, tris, size, **extra)
        best = min(best, time.process_time() - start)
    times[name] = best
    return result


best_of_two("source refinement", lightmap, uvs, tris)
assert best_of_two("re-chart route", lightmap, uvs, tris, positions=positions).report["rechart"]["used"]
# The Lightmap Pack routes: most of their time is packing.
for name in ("courtyard", "hillside"):
    sample = load_sample(name)
    uvs, tris = sample.layout("lightmap")
    small = lmrefine.bake(sample.to_scene(uvs), size // 4, passes="direct", samples=8, seed=0)[0][..., :3]
    lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
    best_of_two(name + " LP route", lightmap, uvs, tris, positions=sample.positions[sample.triangles].reshape(-1, 3),
                polygons=sample.polygons)
print(json.dumps(times))
"""


# Makes the game_level lightmap the first-call children read, so that no bake
# runs in a measured process before its call (the plane's map is cheap).
FIRST_CALL_INPUTS = r"""
import sys
import numpy as np
import lmrefine
from lmrefine.sample_scenes import load_sample
size, folder = int(sys.argv[1]), sys.argv[2]
sample = load_sample("game_level")
uvs, tris = sample.layout("smart")
small = lmrefine.bake(sample.to_scene(uvs), size // 4, passes="direct", samples=8, seed=0)[0][..., :3]
np.save(folder + "/game_level.npy", np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32))
"""

FIRST_CALL_CHILD = r"""
import json, sys, time
size, tests, case, folder = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
sys.path.insert(0, tests)
import numpy as np
import lmrefine
if case == "plane":
    from layouts import plane, shadow_edge_lightmap
    uvs, tris = plane(128, margin=0.02)
    lightmap = shadow_edge_lightmap(size, 0.5, 0.3)
else:
    from lmrefine.sample_scenes import load_sample
    uvs, tris = load_sample("game_level").layout("smart")
    lightmap = np.load(folder + "/game_level.npy")
wall, cpu = time.perf_counter(), time.process_time()
lmrefine.refine_uvs(lightmap, uvs, tris, size)
print(json.dumps({case + ", wall": time.perf_counter() - wall, case + ", CPU": time.process_time() - cpu}))
"""

TESSELLATE_CHILD = r"""
import json, sys, time
size = int(sys.argv[1])
import numpy as np
from lmrefine.tessellation import TRIAL_BUDGET, tessellate
n = 224  # 2 n^2 = 100,352 triangles
xs = np.linspace(0.0, 1.0, n + 1)
x, y = np.meshgrid(xs, xs, indexing="xy")
positions = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
v = (np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]).ravel()
triangles = np.concatenate([np.stack([v, v + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + n + 1], 1)])
uvs = (0.02 + 0.96 * positions[triangles.ravel()][:, :2]).astype(np.float32)
strength = np.zeros((size, size))
strength[:, int(0.437 * size) - 1:int(0.437 * size) + 1] = 1.0
strength[int(0.61 * size) - 1:int(0.61 * size) + 1, :] = 1.0
best = float("inf")
for _ in range(2):
    start = time.process_time()
    tessellate(positions, triangles, uvs, strength, budget=TRIAL_BUDGET)
    best = min(best, time.process_time() - start)
print(json.dumps({"tessellate": best}))
"""

# Records the native pack_charts calls of one refine_uvs per route into
# folder/packings.pkl: (route, args, keywords) without the progress callback.
PACKING_INPUTS = r"""
import pickle, sys
import numpy as np
import lmrefine
from lmrefine import _native
from lmrefine.sample_scenes import load_sample
size, folder = int(sys.argv[1]), sys.argv[2]
native, calls, route = _native.pack_charts, [], [None]


def recording(*args, **keywords):
    keywords.pop("progress", None)
    calls.append((route[0], args, keywords))
    return native(*args, **keywords)


_native.pack_charts = recording
for name, variant in (("courtyard", "lightmap"), ("courtyard", "smart"), ("game_level", "lightmap"),
                      ("game_level", "smart"), ("hillside", "lightmap")):
    sample = load_sample(name)
    uvs, tris = sample.layout(variant)
    small = lmrefine.bake(sample.to_scene(uvs), size // 4, passes="direct", samples=8, seed=0)[0][..., :3]
    lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
    route[0] = f"{name} {variant}"
    lmrefine.refine_uvs(lightmap, uvs, tris, size, positions=sample.positions[sample.triangles].reshape(-1, 3),
                        polygons=sample.polygons)
with open(folder + "/packings.pkl", "wb") as file:
    pickle.dump(calls, file)
"""

PACKING_CHILD = r"""
import json, pickle, sys, time
from lmrefine import _native
folder = sys.argv[1]
with open(folder + "/packings.pkl", "rb") as file:
    calls = pickle.load(file)
routes = {}
for route, args, keywords in calls:
    routes.setdefault(route, []).append((args, keywords))
times = {}
for route, packings in routes.items():
    best = float("inf")
    for _ in range(2):
        start = time.process_time()
        for args, keywords in packings:
            try:
                _native.pack_charts(*args, **keywords)
            except ValueError:  # a fixed scale that does not fit: the refinement asked, and it costs as much
                pass
        best = min(best, time.process_time() - start)
    times[f"{route} ({len(packings)})"] = best
times["all packings"] = sum(times.values())  # the routes' best times summed
print(json.dumps(times))
"""


def first_call(python_dir, size, threads, folder):
    """One refine_uvs per fresh process, on the plane and on game_level."""
    times = {}
    for case in ("plane", "game_level"):
        times.update(run_child(python_dir, threads, FIRST_CALL_CHILD, str(size), os.path.join(HERE, "..", "tests"),
                               case, folder))
    return times


def run_child(python_dir, threads, child, *args):
    # Both builds read this repository's sample scenes, wherever their python/ lies.
    env = dict(os.environ, PYTHONPATH=os.path.abspath(python_dir), LMREFINE_THREADS=str(threads),
               LMREFINE_SAMPLES=os.path.join(HERE, "..", "blend_samples"))
    out = subprocess.run([sys.executable, "-c", child, *args], env=env, capture_output=True, text=True,
                         check=True).stdout
    return json.loads(out) if out.strip() else {}


def measure(python_dir, size, threads, case="automaton", folder=None):
    if case == "packing":
        return run_child(python_dir, threads, PACKING_CHILD, folder)
    child = {"route": ROUTE_CHILD, "tessellate": TESSELLATE_CHILD}.get(case, CHILD)
    return run_child(python_dir, threads, child, str(size), os.path.join(HERE, "..", "tests"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the baseline build's python/ directory")
    parser.add_argument("--new", required=True, help="the new build's python/ directory")
    parser.add_argument("--rounds", type=int, default=5, help="subprocesses per build, alternating (default 5)")
    parser.add_argument("--size", type=int, default=1024, help="lightmap resolution (default 1024)")
    parser.add_argument("--threads", type=int, default=1, help="LMREFINE_THREADS (default 1)")
    parser.add_argument("--case", choices=("automaton", "route", "first-call", "tessellate", "packing"),
                        default="automaton",
                        help="run_automaton on the plane (default), refine_uvs' re-chart route, one refine_uvs "
                             "per fresh process, tessellate at the trial budget, or the packings of the routes")
    args = parser.parse_args()
    runs = {"base": [], "new": []}
    with tempfile.TemporaryDirectory() as folder:
        if args.case == "first-call":
            run_child(args.new, args.threads, FIRST_CALL_INPUTS, str(args.size), folder)
        if args.case == "packing":
            run_child(args.new, args.threads, PACKING_INPUTS, str(args.size), folder)
        for _ in range(args.rounds):
            for build, path in (("base", args.base), ("new", args.new)):
                runs[build].append(first_call(path, args.size, args.threads, folder) if args.case == "first-call"
                                   else measure(path, args.size, args.threads, args.case, folder))
    what, per_run, unit = {"route": ("refine_uvs' re-chart routes", 2, "CPU seconds"),
                           "first-call": ("the first refine_uvs of a process", 1, "seconds"),
                           "automaton": ("run_automaton", 3, "CPU seconds"),
                           "tessellate": ("tessellate on a plane of 100,352 triangles", 2, "CPU seconds"),
                           "packing": ("the native pack_charts on the routes' packings", 2, "CPU seconds")}[args.case]
    print(f"{what} at {args.size}^2, {args.threads} thread(s), {unit}, best of {per_run * args.rounds}:")
    width = max(18, *(len(name) for name in runs["base"][0]))
    for name in runs["base"][0]:
        base = min(r[name] for r in runs["base"])
        new = min(r[name] for r in runs["new"])
        print(f"  {name:<{width}} base {base:.3f}  new {new:.3f}  new/base {new / base:.3f}")
    if args.case == "route":
        for build in runs:
            route, source = (min(r[name] for r in runs[build]) for name in ("re-chart route", "source refinement"))
            print(f"  {build}: the route costs {route / source:.2f}x the source refinement")


if __name__ == "__main__":
    main()
