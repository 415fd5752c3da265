"""Benchmark of the UV refiner (docs/refiner.md).

1. The whole refinement (gradient map + automaton + warp + validity check)
   at 256^2, 512^2 and 1024^2 on a finely tessellated plane with a hard
   shadow edge; baseline: the 256^2 run's cost per texel.
2. The chart repack at 1024^2 on a Smart UV atlas (game_level), against
   the in-chart refinement alone, and its chart stretch against the
   repack without it; a Lightmap Pack layout at 1024^2, and two of
   thousands of one-face charts without the mesh against the plane; and
   the re-chart route on a Smart UV atlas with folds (courtyard), against
   the same refinement without the mesh; the chart stretch on the re-chart
   route of a Lightmap Pack layout (courtyard), where its turned fallback
   is packed too, against the same call with max_stretch=1; the route
   where a bound rules out the source layout's repack, against that
   repack always made; the triangle stretch on the Smart UV atlas, against
   the same call with triangle_stretch=1.
3. Coarse-to-fine against one level at 256^2: steps (and time) one level
   needs to give the shadow edge 90% of the texels the pyramid gives it.
4. The three border treatments, on an edge across the middle and one near
   the border (how the default was chosen).

    PYTHONPATH=python /usr/bin/python3 bench/bench_refine.py
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
import lmrefine  # noqa: E402
from layouts import plane, shadow_edge_lightmap  # noqa: E402
from timing import best_of  # noqa: E402


def scene(resolution, position=0.5, angle=0.3, quads=128):
    uvs, tris = plane(quads, margin=0.02)
    lightmap = shadow_edge_lightmap(resolution, position, angle)
    return uvs, tris, lightmap


def refine(lightmap, uvs, tris, resolution, **options):
    return lmrefine.refine_uvs(lightmap, uvs, tris, resolution, **options)


def whole_refinement():
    print(f"threads: {os.environ.get('LMREFINE_THREADS', os.cpu_count())}; load average: "
          f"{os.getloadavg()[0]:.1f} (a shared machine: compare ratios); gradient map: lmrefine.gradient_map (D4)")
    print(f"{'size':>6} {'seconds':>8} {'steps':>6} {'ns/texel':>9} {'vs 256^2':>9} {'widening':>9} {'valid':>6}"
          f"   setup / gradient / automaton / warp+check (s)")
    base = None
    for resolution in (256, 512, 1024):
        uvs, tris, lightmap = scene(resolution)
        seconds, result = best_of(3 if resolution < 1024 else 2, lambda: refine(lightmap, uvs, tris, resolution))
        per_texel = seconds / resolution ** 2 * 1e9
        base = base or per_texel
        report = result.report
        print(f"{resolution:>5}^2 {seconds:>8.3f} {report['steps']:>6} {per_texel:>9.1f} {per_texel / base:>8.2f}x "
              f"{report['transition_widening']:>9.2f} {str(report['check']['valid']):>6}   "
              + " / ".join(f"{report['timings'][k]:.3f}"
                           for k in ("setup", "gradient_map", "automaton", "warp_and_check")))


def lightmap_pack_layout(resolution=1024, runs=2):
    """The bundled Cycles sample (blend_samples/courtyard_layout.npz: 618
    Lightmap Pack charts, about 45% of the texels rigid gutter or chart
    edge) at 1024^2, its 256^2 lightmap scaled up: a harder case for the
    automaton's guards than the plane (many reverts, fit_to_bounds rounds)."""
    here = os.path.dirname(os.path.abspath(__file__))
    samples = os.path.join(here, "..", "blend_samples")
    layout = np.load(os.path.join(samples, "courtyard_layout.npz"))
    image = lmrefine.read_image(os.path.join(samples, "courtyard_lightmap.exr"))[..., :3]
    factor = resolution // image.shape[0]
    lightmap = np.ascontiguousarray(np.kron(image, np.ones((factor, factor, 1))), dtype=np.float32)
    seconds, result = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, layout["uvs"], layout["triangles"],
                                                                   lightmap.shape[:2]))
    report = result.report
    print(f"\nLightmap Pack layout (courtyard sample, 618 charts) at {resolution}^2: {seconds:.3f} s, "
          f"{report['steps']} steps, widening {report['transition_widening']:.2f}, valid {report['check']['valid']}")
    print("  " + " / ".join(f"{k} {v:.3f}" for k, v in report["timings"].items()))
    print("  automaton levels (block: seconds/steps): "
          + " ".join(f"{level['block']}: {level['seconds']:.3f}/{level['steps']}" for level in report["levels"]))


def one_face_charts_without_the_mesh(resolution=1024, runs=2):
    """Lightmap Pack layouts of thousands of one-face charts refined without
    the mesh (courtyard's 2,854 charts, hillside's 2,825: quads and
    triangles) at 1024^2, each scene's 256^2 direct-light bake scaled up,
    against the bench plane's whole refinement at 1024^2 in the same run.
    Every UV of such a layout is on its chart's border, so the automaton is
    not run (docs/refiner.md, "Layouts without room"): what is left is the
    repack."""
    from lmrefine.sample_scenes import load_sample

    uvs, tris, lightmap = scene(resolution)
    t_plane, _ = best_of(runs, lambda: refine(lightmap, uvs, tris, resolution))
    print(f"\nLightmap Pack layouts without the mesh at {resolution}^2 (baseline: the bench plane's whole refinement, "
          f"{t_plane:.3f} s; target 1 s):")
    for name in ("courtyard", "hillside"):
        sample = load_sample(name)
        uvs, tris = sample.layout("lightmap")
        small = lmrefine.bake(sample.to_scene(uvs), resolution // 4, passes="direct", samples=8, seed=0)[0][..., :3]
        lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
        seconds, result = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution))
        report = result.report
        print(f"  {name} ({(report['repack'] or {}).get('charts', 0)} charts): {seconds:.3f} s "
              f"({seconds / t_plane:.2f}x the plane), automaton steps {report['steps']}; "
              + " / ".join(f"{k} {v:.3f}" for k, v in report["timings"].items()))


def smart_uv_repack(resolution=1024, runs=2):
    """Refinement with the chart repack (refine_uvs' default) against the
    in-chart refinement alone (repack=False) on a Smart UV atlas of many
    charts at 1024^2: game_level's layout (19 objects), its 256^2 direct-light
    bake scaled up. The ratio is what scaling and packing the charts cost.
    Also the default against finest_block=1 (the automaton's one-texel
    level stepping, as before the finest level followed the triangles)."""
    from lmrefine.sample_scenes import load_sample

    sample = load_sample("game_level")
    uvs, tris = sample.layout("smart")
    small = lmrefine.bake(sample.to_scene(uvs), resolution // 4, passes="direct", samples=8, seed=0)[0][..., :3]
    lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
    t_plain, plain = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution, repack=False))
    t_unstretched, _ = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution, max_stretch=1.0,
                                                                 triangle_stretch=1.0))
    t_charts, _ = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution, triangle_stretch=1.0))
    t_repack, packed = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution))
    t_stepped, _ = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution, finest_block=1))
    repack = packed.report["repack"]
    stretch = repack.get("stretch") or {}
    before = lmrefine.check_layout(uvs, tris, resolution, 2.0)["overlapping"]
    print(f"\nSmart UV atlas (game_level, {repack.get('charts', 0)} charts) at {resolution}^2:")
    print(f"  in-chart only (repack=False): {t_plain:.3f} s; with the repack: {t_repack:.3f} s "
          f"({t_repack / t_plain:.2f}x; repack stage {packed.report['timings'].get('repack', 0.0):.3f} s)")
    print(f"  repack used: {repack.get('used')}; texels covered {repack.get('utilisation_before', 0):.1%} -> "
          f"{repack.get('utilisation_after', 0):.1%}; predicted error {repack.get('predicted_error', 1):.2f} "
          f"of the unpacked layout; overlapping triangles {packed.report['check']['overlapping']} "
          f"(input: {before}, a chart that overlaps itself)")
    print(f"  the chart stretch (a second packing at the same time as the first; a turned one after them where tried): "
          f"{t_charts:.3f} s against {t_unstretched:.3f} s with max_stretch=1 ({t_charts / t_unstretched:.2f}x; both "
          f"with triangle_stretch=1); "
          f"stretch kept: {stretch.get('used')} ({stretch.get('charts_stretched', 0)} charts, "
          f"{len(stretch.get('candidates', []))} candidates, {stretch.get('charts_turned', 0)} turned)")
    print(f"  the automaton's finest level from the triangles (finest_block={packed.report['finest_block']}, the "
          f"default) against one-texel cells that step (finest_block=1, the default before): {t_repack:.3f} s "
          f"against {t_stepped:.3f} s ({t_repack / t_stepped:.2f}x; automaton stage "
          f"{packed.report['timings']['automaton']:.3f} s)")
    triangles = packed.report["triangle_stretch"]
    print(f"  the triangle stretch (the default, triangle_stretch=2: a fit, a packing, backed-off charts packed again): "
          f"{t_repack:.3f} s against {t_charts:.3f} s with triangle_stretch=1 ({t_repack / t_charts:.2f}x); kept: "
          f"{triangles['used']} ({triangles['triangles_stretched']} triangles, predicted edge error "
          f"{triangles.get('predicted_edge_error', float('nan')):.3f}; stage "
          f"{packed.report['timings'].get('triangle_stretch', 0.0):.3f} s)")


def folded_smart_uv(resolution=1024, runs=2):
    """The re-chart route on a Smart UV atlas whose charts fold over lit
    creases (courtyard, lmrefine.folds) at 1024^2, its 256^2 direct-light bake
    scaled up: refine_uvs with the mesh (positions=, as the add-on calls it)
    against the same call without it (the source layout's refinement alone).
    The ratio is what the crease search, the re-charting and the second
    refinement cost."""
    from lmrefine.sample_scenes import load_sample

    sample = load_sample("courtyard")
    uvs, tris = sample.layout("smart")
    positions = sample.positions[sample.triangles].reshape(-1, 3)
    small = lmrefine.bake(sample.to_scene(uvs), resolution // 4, passes="direct", samples=8, seed=0)[0][..., :3]
    lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
    t_source, _ = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution))
    t_route, routed = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution,
                                                                  positions=positions))
    info = routed.report["rechart"]
    folds = info.get("folds") or {}
    print(f"\nSmart UV atlas with folds (courtyard) at {resolution}^2: without the mesh {t_source:.3f} s; "
          f"with it (re-chart route) {t_route:.3f} s ({t_route / t_source:.2f}x)")
    print(f"  folds: {folds.get('count', 0)} creases, {folds.get('energy_fraction', 0):.0%} of the light changes; "
          f"re-charted: {info['used']} ({info.get('charts', 0)} charts), valid {routed.report['check']['valid']}")

def stretch_on_lightmap_pack_route(resolution=1024, runs=2):
    """The chart stretch on the re-chart route of courtyard's Lightmap Pack
    layout at 1024^2 (its 256^2 direct-light bake scaled up; two repacks,
    the source layout's and the re-charted one's, each with its stretched
    packings) against the same call with max_stretch=1."""
    from lmrefine.sample_scenes import load_sample

    sample = load_sample("courtyard")
    uvs, tris = sample.layout("lightmap")
    positions = sample.positions[sample.triangles].reshape(-1, 3)
    small = lmrefine.bake(sample.to_scene(uvs), resolution // 4, passes="direct", samples=8, seed=0)[0][..., :3]
    lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
    t_off, _ = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution, positions=positions,
                                                         max_stretch=1.0))
    t_on, routed = best_of(runs, lambda: lmrefine.refine_uvs(lightmap, uvs, tris, resolution, positions=positions))
    stretch = (routed.report.get("repack") or {}).get("stretch") or {}
    print(f"\nthe chart stretch on the re-chart route of a Lightmap Pack layout (courtyard) at {resolution}^2: "
          f"{t_on:.3f} s against {t_off:.3f} s with max_stretch=1 ({t_on / t_off:.2f}x)")
    print(f"  re-charted: {routed.report['rechart']['used']}; stretch kept: {stretch.get('used')} "
          f"({stretch.get('charts_stretched', 0)} charts, {len(stretch.get('candidates', []))} packings tried, "
          f"{stretch.get('charts_turned', 0)} turned)")


def route_without_the_source_repack(resolution=1024, runs=3):
    """The re-chart route at 1024^2 of Lightmap Pack layouts and of a Smart
    UV atlas whose charts fold over creases (each scene's 256^2 direct bake
    scaled up, with its faces) as refine_uvs runs it, where a lower bound
    may rule out the source layout's repack (docs/refiner.md, "The source
    repack the route need not make"), against the same call with that
    repack always made (refine._source_lowest off), the two alternated in
    the same run."""
    from lmrefine import refine as refine_module
    from lmrefine.sample_scenes import load_sample

    always = lambda stage: None  # noqa: E731
    bounded = refine_module._source_lowest
    print(f"\nthe re-chart route at {resolution}^2 (target 1 s), against the source repack always made:")
    for name, variant in (("courtyard", "lightmap"), ("game_level", "lightmap"), ("hillside", "lightmap"),
                          ("courtyard", "smart")):
        sample = load_sample(name)
        uvs, tris = sample.layout(variant)
        positions = sample.positions[sample.triangles].reshape(-1, 3)
        small = lmrefine.bake(sample.to_scene(uvs), resolution // 4, passes="direct", samples=8, seed=0)[0][..., :3]
        lightmap = np.ascontiguousarray(np.kron(small, np.ones((4, 4, 1))), dtype=np.float32)
        times = {"bounded": [], "always": []}
        for _ in range(runs):
            for label, rule in (("always", always), ("bounded", bounded)):
                refine_module._source_lowest = rule
                try:
                    seconds, result = best_of(1, lambda: lmrefine.refine_uvs(
                        lightmap, uvs, tris, resolution, positions=positions, polygons=sample.polygons))
                finally:
                    refine_module._source_lowest = bounded
                times[label].append(seconds)
        info = result.report["rechart"]
        made = "made" if info["predicted_error_source_route"] is not None else "not made"
        print(f"  {name} ({variant}): {min(times['bounded']):.3f} s against {min(times['always']):.3f} s "
              f"({min(times['bounded']) / min(times['always']):.2f}x); re-charted {info['used']} predicting "
              f"{info['predicted_error']:.3f}, the bound {info['source_route_bound'] or float('nan'):.3f}: "
              f"source repack {made}")


def coarse_to_fine_against_one_level(resolution=256):
    energy = np.full((resolution, resolution), 1 / 7, np.float32)
    energy[:, resolution // 2 - 2:resolution // 2 + 2] = 1.0  # a 4-texel band, as strength 6 makes it
    band = slice(resolution // 2 - 2, resolution // 2 + 2)
    t_pyramid, pyramid = best_of(3, lambda: lmrefine.run_automaton(energy))
    target = 0.9 * pyramid["cell_area"][:, band].mean()
    reached, t_one, steps = 0.0, 0.0, 0
    for budget in (16, 64, 256, 1024, 4096, 8192):
        steps = budget
        t_one, one = best_of(1, lambda: lmrefine.run_automaton(energy, coarse_to_fine=False, max_steps=budget))
        reached = one["cell_area"][:, band].mean()
        if reached >= target:
            break
    print(f"\ncoarse-to-fine vs one level at {resolution}^2 (band magnification target {target:.2f}):")
    print(f"  pyramid : {pyramid['steps']:>5} steps ({len(pyramid['levels'])} levels) {t_pyramid:.3f} s")
    note = "" if reached >= target else f" (only reached {reached:.2f})"
    print(f"  one level: {steps:>5} steps{note} {t_one:.3f} s")
    print(f"  ratio: {t_one / t_pyramid:.1f}x time, {steps / pyramid['steps']:.1f}x steps")


def border_modes(resolution=256):
    print(f"\nborder treatments at {resolution}^2 (widening = texel-density ratio at the edge; "
          "unused = texels no original texel maps to):")
    print(f"{'scene':>14} {'border':>12} {'widening':>9} {'min':>6} {'max':>6} {'unused':>7} {'valid':>6}")
    for name, position, angle in (("edge middle", 0.5, 0.3), ("edge at border", 0.06, 0.0)):
        uvs, tris, lightmap = scene(resolution, position, angle)
        for border in ("same", "border_rule", "extra_ring"):
            result = refine(lightmap, uvs, tris, resolution, border=border)
            report = result.report
            unused = 1 - lmrefine.grid_cell_areas(result.grid).sum() / resolution ** 2
            print(f"{name:>14} {border:>12} {report['transition_widening']:>9.2f} {report['density_min']:>6.2f} "
                  f"{report['density_max']:>6.2f} {unused:>7.1%} {str(report['check']['valid']):>6}")


if __name__ == "__main__":
    whole_refinement()
    lightmap_pack_layout()
    one_face_charts_without_the_mesh()
    smart_uv_repack()
    folded_smart_uv()
    stretch_on_lightmap_pack_route()
    route_without_the_source_repack()
    coarse_to_fine_against_one_level()
    border_modes()
