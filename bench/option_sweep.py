"""The equal-error resolution ratio of refine_uvs option sets, fast: for
tuning the refiner's constants (docs/refiner.md, "Constants and how they
were chosen").

    PYTHONPATH=python /usr/bin/python3 bench/option_sweep.py '{"default": {}, "steps16": {"max_steps": 16}}'
    PYTHONPATH=python /usr/bin/python3 bench/option_sweep.py OPTIONS --scenes courtyard:lightmap --resolution 512

OPTIONS is a JSON object: a label per option set, each a dict of
refine_uvs keyword arguments. The last column, `shortfall`, sums how far
each row's ratio falls below its target (TARGETS: issue #11's 2.0 from
Smart UV, 1.8 from Lightmap Pack), the rule the defaults are chosen by
(docs/refiner.md, "Chosen for the weakest tuning row"). Every set is measured on the same scenes
(default: the tuning scenes, lmrefine.sample_scenes.TUNING_SCENES, in both
UV variants: the constants are chosen there, the holdouts only report) as
`lmrefine evaluate` measures them: the same bake, points, ground truth and
uniform bakes at R x {1, 1.5, 2, 3, 4}, with the re-chart route given the
mesh. What does not depend on the options (the plain bake, the truth, the
uniform sweep) is computed once per scene and kept in --cache, keyed by the
scene, variant, resolution and the extension's version, so a set costs one
refinement and one bake per scene. The figures equal `evaluate`'s to the
digit for the same options.
"""

import argparse
import hashlib
import json
import os
import pickle
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))

import lmrefine  # noqa: E402
from lmrefine import _native, metrics, sample_scenes  # noqa: E402
from lmrefine.baker import evaluate as evaluate_light  # noqa: E402
from lmrefine.evaluation import (EvaluationOptions, _bake_map, _route_mesh, _single_pass,  # noqa: E402
                                 _Stages, _uniform_sweep, surface_points)

# The equal-error resolution ratio each layout kind should reach (issue #11).
TARGETS = {"smart": 2.0, "lightmap": 1.8}


def plain_parts(sample, options):
    """What evaluate_sample measures every map against: the plain bake, the
    points and their stencil, the truth there (the mean of two estimates)
    and at the stencil, the transition mask and the uniform sweep (a
    lookup per multiplier)."""
    resolution = options.resolution
    uvs, triangles = sample.layout(options.variant)
    passes = _single_pass(sample, options)
    baseline = _bake_map(sample, uvs, resolution, options, None)
    density = metrics.texel_density(uvs, triangles, sample.triangle_areas(), resolution)
    points, stencil, stencil_normals, distances, _ = surface_points(sample, density, options)
    scene = sample.to_scene(uvs)
    first = evaluate_light(scene, np.concatenate([points.points, stencil]),
                           np.concatenate([points.normals, stencil_normals]), passes=passes,
                           samples=options.truth_samples, seed=options.seed + 1).astype(np.float64)
    second = evaluate_light(scene, points.points, points.normals, passes=passes, samples=options.truth_samples,
                            seed=options.seed + 2).astype(np.float64)
    truth = (first[:len(points)] + second) / 2
    neighbours = first[len(points):]
    transitions = metrics.transition_mask(metrics.surface_gradient(truth, neighbours, distances))
    uv_points = metrics.interpolate_corners(uvs, points.triangle, points.bary)
    sweep = _uniform_sweep(sample, uvs, uv_points, resolution, options, _Stages("sweep", None), "sweep",
                           first=metrics.bilinear_lookup(baseline, uv_points))
    return {"baseline": baseline, "density": density, "points": points, "stencil": stencil, "truth": truth,
            "neighbours": neighbours, "transitions": transitions, "sweep": sweep}


def _fixed_parts(sample, options):
    """What every option set shares: the plain bake, the points, the truth,
    the transition mask and the uniform sweep's RMSEs (as evaluate_sample)."""
    parts = plain_parts(sample, options)
    truth, transitions, points = parts["truth"], parts["transitions"], parts["points"]
    everywhere = np.ones(len(truth), bool)
    return {"baseline": parts["baseline"], "triangle": points.triangle, "bary": points.bary, "truth": truth,
            "transitions": transitions,
            "sweep": [metrics.error_stats(s["lookup"], truth, everywhere)["rmse"] for s in parts["sweep"]],
            "sweep_transitions": [metrics.error_stats(s["lookup"], truth, transitions)["rmse"]
                                  for s in parts["sweep"]]}


def fixed_parts(scene, variant, resolution, cache):
    sample = sample_scenes.load_sample(scene)
    options = EvaluationOptions(resolution=resolution, variant=variant)
    # The extension's build is part of the key: a baker change makes new truths and bakes.
    build = hashlib.sha1(open(_native.__file__, "rb").read()).hexdigest()[:12]
    path = os.path.join(cache, f"{scene}_{variant}_{resolution}_{build}.pkl")
    if os.path.exists(path):
        with open(path, "rb") as file:
            return sample, options, pickle.load(file)
    parts = _fixed_parts(sample, options)
    os.makedirs(cache, exist_ok=True)
    with open(path + ".tmp", "wb") as file:
        pickle.dump(parts, file)
    os.replace(path + ".tmp", path)
    return sample, options, parts


def measure(sample, options, parts, refine_options):
    """(equal-error ratio, transition ratio, refine report) of one option set."""
    uvs, triangles = sample.layout(options.variant)
    resolution = options.resolution
    result = lmrefine.refine_uvs(parts["baseline"], uvs, triangles, resolution, padding=options.padding,
                                 **_route_mesh(sample, options), **refine_options)
    refined = _bake_map(sample, result.uvs, resolution, options, None)
    lookup = metrics.bilinear_lookup(refined, metrics.interpolate_corners(result.uvs, parts["triangle"],
                                                                          parts["bary"]))
    everywhere = np.ones(len(parts["truth"]), bool)
    rmse = metrics.error_stats(lookup, parts["truth"], everywhere)["rmse"]
    rmse_t = metrics.error_stats(lookup, parts["truth"], parts["transitions"])["rmse"]
    ratio, _ = metrics.equal_error_resolution(options.multipliers, parts["sweep"], rmse)
    ratio_t, _ = metrics.equal_error_resolution(options.multipliers, parts["sweep_transitions"], rmse_t)
    return ratio, ratio_t, result.report


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("options", help="JSON: {label: {refine_uvs keyword: value}}")
    default_scenes = ",".join(f"{s}:{v}" for v in ("smart", "lightmap") for s in sample_scenes.TUNING_SCENES)
    parser.add_argument("--scenes", default=default_scenes, help=f"scene:variant,... (default: {default_scenes})")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--cache", default=os.path.join("evaluate_out", "option_sweep_cache"))
    args = parser.parse_args(argv)
    sets = json.loads(args.options)
    scenes = [tuple(item.split(":")) for item in args.scenes.split(",")]
    for scene, _ in scenes:
        if scene not in sample_scenes.TUNING_SCENES:
            print(f"note: {scene} is not a tuning scene: report on it, do not tune on it")
    print(f"{'options':>20} " + " ".join(f"{s[:10] + '/' + v[:5]:>17}" for s, v in scenes) + "   seconds  shortfall")
    for label, refine_options in sets.items():
        start = time.perf_counter()
        cells, shortfall = [], 0.0
        for scene, variant in scenes:
            sample, options, parts = fixed_parts(scene, variant, args.resolution, args.cache)
            ratio, ratio_t, _ = measure(sample, options, parts, refine_options)
            cells.append(f"{ratio:>8.2f} ({ratio_t:.2f})")
            shortfall += max(0.0, TARGETS.get(variant, 0.0) - round(ratio, 2))
        print(f"{label:>20} " + " ".join(f"{c:>17}" for c in cells)
              + f"   {time.perf_counter() - start:>7.0f}  {shortfall:9.2f}", flush=True)


if __name__ == "__main__":
    main()
