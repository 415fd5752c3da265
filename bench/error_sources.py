"""Where a refined map's error sits: transition points or not, chart borders,
bake noise, and how the chart model's prediction compares with the measured
error (docs/evaluation.md, "Smart UV on scenes not tuned on").

    PYTHONPATH=python /usr/bin/python3 bench/error_sources.py courtyard [--resolution 256] [--variant smart]

Bakes, on the scene's layout at R: the plain map, a second plain map with
another seed (its difference to the first is the bake's noise), the refined
map (refine_uvs' defaults), the in-chart refinement alone (repack=False),
the charts repacked at one scale, and a plain map at 2R; reads each at
the evaluation's surface points against the same ground truth (as
`lmrefine evaluate` does: 20000 points, truth 2 x 256 samples, transitions
the top decile of the truth's gradient). A border point is one whose
bilinear lookup reads an uncovered texel of its layout (a dilated gutter
value). Prints the summed squared error per class and layout, and the
repack's predicted error beside the measured ratios (MAE, squared error,
RMSE) of the refined map against the in-chart refinement.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))

import lmrefine  # noqa: E402
from lmrefine import metrics, sample_scenes  # noqa: E402
from lmrefine.evaluation import EvaluationOptions, _bake_map, _single_pass  # noqa: E402


def border_points(uvs, triangles, uv_points, resolution):
    """(P,) bool: the point's four bilinear texels are not all covered."""
    mask = lmrefine.coverage_mask(uvs, triangles, resolution)
    x = np.clip(uv_points[:, 0] * resolution - 0.5, 0, resolution - 1)
    y = np.clip((1 - uv_points[:, 1]) * resolution - 0.5, 0, resolution - 1)
    j = np.minimum(np.floor(x).astype(np.int64), resolution - 2)
    i = np.minimum(np.floor(y).astype(np.int64), resolution - 2)
    return ~(mask[i, j] & mask[i, j + 1] & mask[i + 1, j] & mask[i + 1, j + 1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--variant", default="smart")
    args = parser.parse_args(argv)
    resolution = args.resolution
    sample = sample_scenes.load_sample(args.scene)
    options = EvaluationOptions(resolution=resolution, variant=args.variant)
    uvs, triangles = sample.layout(args.variant)
    padding = min(2.0, lmrefine.check_layout(uvs, triangles, resolution, 2.0)["min_gutter_texels"])
    areas = sample.triangle_areas()

    plain = _bake_map(sample, uvs, resolution, options, None)
    refined = lmrefine.refine_uvs(plain, uvs, triangles, resolution, padding=padding)
    in_chart = lmrefine.refine_uvs(plain, uvs, triangles, resolution, padding=padding, repack=False)
    uniform, _ = lmrefine.pack_charts(uvs, triangles, None, None, resolution, padding)
    layouts = {"plain": (uvs, resolution), "in-chart only": (in_chart.uvs, resolution),
               "uniform repack": (uniform, resolution), "refined": (refined.uvs, resolution),
               "plain at 2R": (uvs, 2 * resolution)}

    # The evaluation's points, transitions and truth (lmrefine.evaluation.evaluate_sample).
    points = metrics.sample_surface(sample.positions, sample.triangles, options.points, normals=sample.normals,
                                    seed=options.seed)
    texel = 1.0 / np.sqrt(np.maximum(metrics.texel_density(uvs, triangles, areas, resolution), 1e-30))
    order = np.argsort(texel)
    cumulative = np.cumsum(areas[order])
    step = 0.5 * float(texel[order][np.searchsorted(cumulative, cumulative[-1] / 2)])
    stencil, stencil_normals, distances = metrics.gradient_stencil(sample.positions, sample.triangles, points, step,
                                                                   normals=sample.normals)
    scene = sample.to_scene(uvs)
    passes = (_single_pass(sample, options),)
    first = lmrefine.evaluate(scene, np.concatenate([points.points, stencil]),
                              np.concatenate([points.normals, stencil_normals]), passes=passes,
                              samples=options.truth_samples, seed=options.seed + 1).astype(np.float64)
    second = lmrefine.evaluate(scene, points.points, points.normals, passes=passes, samples=options.truth_samples,
                               seed=options.seed + 2).astype(np.float64)
    count = len(points)
    truth = (first[:count] + second) / 2
    transitions = metrics.transition_mask(metrics.surface_gradient(truth, first[count:], distances))

    def read(image, layout_uvs):
        return metrics.bilinear_lookup(image, metrics.interpolate_corners(layout_uvs, points.triangle, points.bary))

    again = _bake_map(sample, uvs, resolution, EvaluationOptions(resolution=resolution, variant=args.variant,
                                                                  seed=options.seed + 7), None)
    noise = ((read(plain, uvs) - read(again, uvs)) ** 2).mean(axis=1) / 2  # one bake's noise variance
    print(f"{args.scene} ({args.variant}, {resolution}^2): summed squared error over {count} points")
    print("| layout | total | at transition points | elsewhere | at border points (share of points) |")
    print("|---|---|---|---|---|")
    errors = {}
    for name, (layout_uvs, size) in layouts.items():
        image = plain if name == "plain" else _bake_map(sample, layout_uvs, size, options, None)
        difference = read(image, layout_uvs) - truth
        errors[name] = difference
        squared = (difference ** 2).mean(axis=1)
        border = border_points(layout_uvs, triangles, metrics.interpolate_corners(layout_uvs, points.triangle,
                                                                                   points.bary), size)
        print(f"| {name} | {squared.sum():.1f} | {squared[transitions].sum():.1f} | {squared[~transitions].sum():.1f} "
              f"| {squared[border].sum():.1f} ({border.mean():.1%}) |")
    print(f"bake noise (one plain bake): {noise.sum():.2f}")
    repack = refined.report["repack"] or {}
    ratio = {kind: float(f(errors["refined"]) / f(errors["in-chart only"])) for kind, f in
             (("MAE", lambda e: np.abs(e).mean()), ("squared", lambda e: (e ** 2).mean()))}
    print(f"repack: predicted error {repack.get('predicted_error', float('nan')):.3f} (L1, used: "
          f"{repack.get('used')}); measured refined / in-chart only: MAE {ratio['MAE']:.3f}, squared "
          f"{ratio['squared']:.3f}, RMSE {np.sqrt(ratio['squared']):.3f}")


if __name__ == "__main__":
    main()
