"""Baker speed against two named baselines, measured in the same run:

1. rays per second of lmrefine.bake against a bare rtcOccluded1 loop
   (lmrefine._native._bench_occluded_loop) over the same Embree scene and the
   same ray distribution (target: >= 70%);
2. time to reach the same error against a high-sample reference as Cycles'
   bake (Debian's Blender, CPU, denoising off) of the same scene at the same
   resolution, each against its own converged bake (target: >= 3x faster);
3. lmrefine.dilate (the gutter fill the add-on runs on every map it merges
   or gets from Cycles) at 1024^2 on a bundled scene's Lightmap Pack layout,
   against a 1-sample bake of the same layout (which dilates its own map).

    PYTHONPATH=python /usr/bin/python3 bench/bench_baker.py [--no-cycles]
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

import lmrefine  # noqa: E402
from baker_scenes import floor, mesh_spec, scene_from_spec  # noqa: E402
from timing import best_of  # noqa: E402

RESOLUTION = 128
AO_DISTANCE = 2.0
REPEATS = 3  # every timing is the best of this many: the machine may be shared
POINT = dict(kind="point", energy=150.0, shadow_soft_size=0.2, position=[1.0, -1.5, 2.5])
AREA = dict(kind="area", energy=200.0, shape="RECTANGLE", size=1.0, size_y=0.5, position=[-1.5, 1.0, 2.0],
            direction=[0.3, -0.2, -1.0])
SUN = dict(kind="sun", energy=2.0, angle=0.1, direction=[0.4, 0.3, -1.0])
WORLD = [0.15, 0.17, 0.2]


def box(centre, half):
    """A closed box (outward fronts), 12 triangles."""
    c, h = np.asarray(centre, float), np.asarray(half, float)
    corners = c + h * np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)])
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    triangles = [[f[0], f[1], f[2]] for f in faces] + [[f[0], f[2], f[3]] for f in faces]
    return corners, np.array(triangles)


def sphere(centre, radius, rings=32, segments=64):
    v, u = np.meshgrid(np.linspace(0, np.pi, rings + 1), np.linspace(0, 2 * np.pi, segments + 1), indexing="ij")
    grid = np.stack([np.sin(v) * np.cos(u), np.sin(v) * np.sin(u), np.cos(v)], -1).reshape(-1, 3)
    index = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]
    triangles = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return np.asarray(centre) + radius * grid, triangles


def sample_scene():
    """A lightmapped floor (6 x 6 m, the receiver) in a room open to the front
    and the sky: three walls, boxes and dense spheres (~140k triangles, a
    typical furnished lightmap scene), lit by a point light, an area light, a
    sun and the sky."""
    positions, triangles, uvs = floor(half=3.0)
    meshes = [mesh_spec(positions, triangles, uvs)]
    for centre, half in [([0, 3.05, 1.5], [3.1, 0.05, 1.5]), ([-3.05, 0, 1.5], [0.05, 3.0, 1.5]),
                         ([3.05, 0, 1.5], [0.05, 3.0, 1.5]),  # walls
                         ([-1, -1, 0.5], [0.5, 0.5, 0.5]), ([1.2, 0.8, 0.3], [0.8, 0.3, 0.3]),
                         ([-0.5, 1.6, 1.0], [0.2, 0.2, 1.0])]:
        meshes.append(mesh_spec(*box(centre, half), receiver=False))
    for centre, radius, rings in [([0.6, -1.0, 0.7], 0.7, 128), ([-1.8, 0.8, 0.5], 0.5, 128),
                                  ([1.9, -2.0, 0.3], 0.3, 32), ([0.0, 2.2, 2.4], 0.4, 32)]:
        meshes.append(mesh_spec(*sphere(centre, radius, rings, 2 * rings), receiver=False))
    return dict(meshes=meshes, lights=[POINT, AREA, SUN], world=WORLD)


def cosine_directions(count, rng):
    r, phi = np.sqrt(rng.random(count)), 2 * np.pi * rng.random(count)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r * r)], 1)


def baseline_rays(kind, count, rng):
    """Rays distributed as the baker casts them from the floor: (count, 7)."""
    origins = np.concatenate([rng.uniform(-3, 3, (count, 2)), np.full((count, 1), 1e-4)], 1)
    if kind == "ao":
        return np.concatenate([origins, cosine_directions(count, rng), np.full((count, 1), AO_DISTANCE)], 1)
    # direct: one shadow ray per light per sample, plus one towards the sky.
    which = rng.integers(0, 4, count)
    targets = np.empty((count, 3))
    u = rng.random((count, 2))
    disk = np.sqrt(u[:, :1]) * np.stack([np.cos(2 * np.pi * u[:, 1]), np.sin(2 * np.pi * u[:, 1])], 1)
    targets[:] = np.asarray(POINT["position"]) + np.concatenate([disk * 0.2, np.zeros((count, 1))], 1)
    area = np.asarray(AREA["position"]) + np.concatenate([(u - 0.5) * [1.0, 0.5], np.zeros((count, 1))], 1)
    targets[which == 1] = area[which == 1]
    directions = targets - origins
    tfar = np.linalg.norm(directions, axis=1)
    directions /= tfar[:, None]
    tfar *= 1 - 1e-4
    sun = -np.asarray(SUN["direction"]) / np.linalg.norm(SUN["direction"])
    directions[which == 2] = sun
    directions[which == 3] = cosine_directions(int((which == 3).sum()), rng)
    tfar[which >= 2] = np.inf
    return np.concatenate([origins, directions, tfar[:, None]], 1).astype(np.float32)


def cpu_seconds(call):
    """CPU time of all of this process's threads over call() (less sensitive
    than wall time to other processes loading the machine), and its result."""
    started = time.process_time()
    result = call()
    return time.process_time() - started, result


def ray_throughput(scene):
    """Rays per second, wall (the stats) and per CPU second. CPU: the bake's
    CPU time minus that of building the same BVH (the bare loop over 1 ray),
    against the bare loop's CPU time per ray (the same subtraction)."""
    rows = []
    rng = np.random.default_rng(0)
    for name in ("direct", "ao"):
        # Best of REPEATS for both, interleaved.
        ours = bare = 0.0
        ours_cpu = bare_cpu = 0.0
        for _ in range(REPEATS):
            cpu, result = cpu_seconds(lambda: lmrefine.bake(scene, RESOLUTION, passes=name, samples=32,
                                                            ao_distance=AO_DISTANCE, dilation=0))
            ours = max(ours, result.stats["rays_per_second"])
            rays = baseline_rays(name, int(result.stats["rays"]), rng)
            build, _ = cpu_seconds(lambda: lmrefine._native._bench_occluded_loop(scene, rays[:1]))
            loop_cpu, (seconds, _) = cpu_seconds(lambda: lmrefine._native._bench_occluded_loop(scene, rays))
            bare = max(bare, len(rays) / seconds)
            ours_cpu = max(ours_cpu, len(rays) / max(cpu - build, 1e-9))
            bare_cpu = max(bare_cpu, len(rays) / max(loop_cpu - build, 1e-9))
        rows.append((name, ours, bare, ours_cpu, bare_cpu))
    print(f"rays per second at {RESOLUTION}^2, 32 samples per texel, best of {REPEATS} "
          "(target: baker >= 70% of the bare loop)")
    print(f"  {'pass':8} {'baker Mray/s':>13} {'bare rtcOccluded1 Mray/s':>25} {'ratio':>7}"
          f" {'per CPU s: baker':>17} {'bare':>6} {'ratio':>6}")
    for name, ours, bare, ours_cpu, bare_cpu in rows:
        print(f"  {name:8} {ours / 1e6:13.2f} {bare / 1e6:25.2f} {ours / bare:7.2f}"
              f" {ours_cpu / 1e6:17.2f} {bare_cpu / 1e6:6.2f} {ours_cpu / bare_cpu:6.2f}")


def relative_rmse(image, reference):
    return float(np.sqrt(np.mean((image[..., :3] - reference[..., :3]) ** 2)) / reference[..., :3].mean())


def our_curve(scene, name, samples):
    reference = lmrefine.bake(scene, RESOLUTION, passes=name, samples=1024, seed=99, ao_distance=AO_DISTANCE,
                              dilation=0)[0]
    curve, cpu_curve = [], []
    for n in samples:
        best = best_cpu = float("inf")
        for _ in range(REPEATS):
            started = time.perf_counter()
            cpu, result = cpu_seconds(lambda: lmrefine.bake(scene, RESOLUTION, passes=name, samples=n,
                                                            ao_distance=AO_DISTANCE, dilation=0))
            best = min(best, time.perf_counter() - started)
            best_cpu = min(best_cpu, cpu)
        error = relative_rmse(result[0], reference)
        curve.append((n, best, error))
        cpu_curve.append((n, best_cpu, error))
    return curve, cpu_curve


def cycles_curves(spec, samples):
    """Cycles' bakes at each sample count (best of REPEATS) and at 1024 (its
    reference): one Blender process; times are Cycles' bake calls (scene sync
    included)."""
    jobs = []
    for n in samples:
        for repeat in range(REPEATS):
            jobs.append(dict(spec, name=f"s{n}r{repeat}", resolution=RESOLUTION, samples=n, seed=0,
                             passes=["direct", "ao"], ao_distance=AO_DISTANCE))
    jobs.append(dict(spec, name="s1024r0", resolution=RESOLUTION, samples=1024, seed=99, passes=["direct", "ao"],
                     ao_distance=AO_DISTANCE))
    with tempfile.TemporaryDirectory() as folder:
        with open(os.path.join(folder, "jobs.json"), "w") as f:
            json.dump(jobs, f)
        script = os.path.join(HERE, "..", "tests", "blender", "cycles_bake.py")
        subprocess.run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python", script, "--",
                        os.path.join(folder, "jobs.json"), os.path.join(folder, "out.npz")],
                       check=True, capture_output=True)
        out = dict(np.load(os.path.join(folder, "out.npz")))
    curves = {}
    for name in ("direct", "ao"):
        reference = out[f"s1024r0/0/{name}"]
        curves[name] = [(n, min(float(out[f"s{n}r{r}/seconds/{name}"]) for r in range(REPEATS)),
                         min(float(out[f"s{n}r{r}/cpu_seconds/{name}"]) for r in range(REPEATS)),
                         relative_rmse(out[f"s{n}r0/0/{name}"], reference)) for n in samples]
    return curves


def time_to_error(curve, error):
    """Seconds our bake needs to reach `error`, interpolated in log-log, and
    whether it is only a bound (our fewest samples already beat `error`, so
    the time of that bake is reported)."""
    times = np.log([t for _, t, _ in curve])
    errors = np.log([e for _, _, e in curve])
    order = np.argsort(errors)  # np.interp needs increasing errors
    bound = np.log(error) >= errors.max()
    return float(np.exp(np.interp(np.log(error), errors[order], times[order]))), bound


def time_to_error_against_cycles(scene, spec):
    cycles_samples = (4, 16, 64)
    cycles = cycles_curves(spec, cycles_samples)
    print(f"\ntime to the same error against each one's 1024-sample reference, {RESOLUTION}^2, "
          f"whole bake calls (BVH build included for both), best of {REPEATS} (target: >= 3x)")
    print("  wall: seconds; CPU: CPU seconds of all threads (Cycles': Blender's process), less sensitive to load")
    print(f"  {'pass':8} {'Cycles spp':>10} {'error':>7} {'Cycles s':>9} {'lmrefine s':>11} {'speedup':>8}"
          f" {'Cycles CPU':>11} {'lmrefine CPU':>13} {'speedup':>8}")
    print("  (<=: lmrefine's fewest samples already beat that error; the speedup is then a lower bound)")
    for name in ("direct", "ao"):
        ours, ours_cpu = our_curve(scene, name, (1, 2, 4, 8, 16, 32, 64, 128))
        for n, seconds, cpu, error in cycles[name]:
            mine, bound = time_to_error(ours, error)
            mine_cpu, _ = time_to_error(ours_cpu, error)
            mark = "<=" if bound else "  "
            print(f"  {name:8} {n:10d} {error:7.3f} {seconds:9.3f} {mark}{mine:9.3f} {mark}{seconds / mine:6.1f}x"
                  f" {cpu:11.3f} {mark}{mine_cpu:11.3f} {mark}{cpu / mine_cpu:6.1f}x")
        print(f"  ({name}: lmrefine samples, seconds, CPU seconds, error: "
              + ", ".join(f"{n}: {t:.3f} s {c:.3f} {e:.3f}" for (n, t, e), (_, c, _) in zip(ours, ours_cpu)) + ")")


def dilation_against_a_bake(resolution=1024):
    from lmrefine.sample_scenes import load_sample

    sample = load_sample("courtyard")
    uvs, triangles = sample.layout("lightmap")
    scene = sample.to_scene(uvs)

    bake, maps = best_of(REPEATS, lambda: lmrefine.bake(scene, resolution, samples=1, seed=0))
    dilate, _ = best_of(REPEATS, lambda: lmrefine.dilate(maps[0], uvs, triangles, 16))
    print(f"\nlmrefine.dilate at {resolution}^2 (courtyard, Lightmap Pack, {len(triangles)} triangles): "
          f"{dilate:.3f} s against {bake:.3f} s for a 1-sample bake of the same layout ({dilate / bake:.2f}x)")


def main():
    spec = sample_scene()
    scene = scene_from_spec(spec)
    triangles = sum(len(m["triangles"]) for m in spec["meshes"])
    print(f"sample scene: {triangles} triangles, 3 lights + sky, {lmrefine._native.__name__}, "
          f"threads={os.environ.get('LMREFINE_THREADS', os.cpu_count())}")
    ray_throughput(scene)
    dilation_against_a_bake()
    if "--no-cycles" in sys.argv or shutil.which("blender") is None:
        print("\n(Cycles comparison skipped)")
        return
    time_to_error_against_cycles(scene, spec)


if __name__ == "__main__":
    main()
