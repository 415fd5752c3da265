"""The re-chart route's choice, measured: for each scene row, the layout
refine_uvs returns with the route left to its error model and with each
of its two choices forced (re-charted: the bound on the source layout's
refinement made infinite, so the route never makes that refinement; the
source layout's own refinement: rechart=False), each before and after its
triangle stretch, baked and measured as `lmrefine evaluate` measures
them, beside the model's prediction (rechart_route.ErrorModel, relative
to the source layout's plain error) for each layout. The route compares
the layouts before their triangle stretch; a row where the better
measured layout is not the one the model predicts lower is a wrong choice
(docs/evaluation.md, "The route the model refused").

    PYTHONPATH=python /usr/bin/python3 bench/route_choice.py [--scenes courtyard:lightmap,...] [--resolution 512]

The plain bake, truth and uniform sweep come from bench/option_sweep.py's
cache (computed once per scene, variant, resolution and build). Default:
the tuning scenes from Lightmap Pack, whose layouts have no room, so the
route is always tried: the choice is for the tuning scenes (docs/refiner.md,
"Constants and how they were chosen"); a holdout row only reports.
"""

import argparse
import contextlib
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import option_sweep  # noqa: E402  (puts ../python on the path)

import lmrefine  # noqa: E402
from lmrefine import _native, metrics, rechart_route, refine, sample_scenes  # noqa: E402
from lmrefine.evaluation import _bake_map, _route_mesh  # noqa: E402
from lmrefine.folds import find_folds  # noqa: E402

CHOICES = ("re-charted", "source layout")


@contextlib.contextmanager
def forced(choice):
    """refine_uvs with the route's choice forced to `choice`: its keyword
    arguments (the re-charted layout through refine._source_lowest, whose
    bound then rules the source layout's refinement out)."""
    if choice == "source layout":
        yield {"rechart": False}
        return
    bound = refine._source_lowest
    refine._source_lowest = lambda stage: (lambda model: math.inf)
    try:
        yield {}
    finally:
        refine._source_lowest = bound


def source_model(lightmap, uvs, triangles, resolution, padding, mesh):
    """The ErrorModel the route builds for this source layout and first bake
    (refine_uvs' gradient energy, read within charts, and its folds)."""
    shape = (resolution, resolution)
    checker = _native.LayoutChecker(uvs, triangles, shape, padding)
    mask = checker.coverage_mask()
    gradient = refine._gradient(lightmap, None, refine.chart_separated(mask, checker.texel_owners()), shape, "d4",
                                None)
    energy = gradient.sum(axis=2)
    positions = rechart_route.positions_array(mesh["positions"], len(uvs))
    folds = None
    if not rechart_route.layout_room(uvs, triangles)["no_room"]:
        normals = mesh.get("normals")
        folds = find_folds(uvs, triangles, positions, rechart_route.ANGLE, energy, mask,
                           None if normals is None else rechart_route.normals_array(normals, len(uvs)))
    return rechart_route.ErrorModel(uvs, triangles, energy, positions, lightmap, folds=folds)


def row(scene, variant, resolution, cache):
    sample, options, parts = option_sweep.fixed_parts(scene, variant, resolution, cache)
    uvs, triangles = sample.layout(variant)
    padding = min(float(options.padding),
                  float(lmrefine.check_layout(uvs, triangles, resolution, options.padding)["min_gutter_texels"]))
    mesh = _route_mesh(sample, options)
    model = source_model(parts["baseline"], uvs, triangles, resolution, padding, mesh)
    everywhere = np.ones(len(parts["truth"]), bool)

    def measured(**refine_options):
        result = lmrefine.refine_uvs(parts["baseline"], uvs, triangles, resolution, padding=padding, **mesh,
                                     **refine_options)
        refined = _bake_map(sample, result.uvs, resolution, options, None)
        lookup = metrics.bilinear_lookup(refined, metrics.interpolate_corners(result.uvs, parts["triangle"],
                                                                              parts["bary"]))
        rmse = metrics.error_stats(lookup, parts["truth"], everywhere)["rmse"]
        ratio, _ = metrics.equal_error_resolution(options.multipliers, parts["sweep"], rmse)
        return rmse, ratio, model.relative(result.uvs), result.report

    chosen = measured()
    label = f"{scene}/{variant} {resolution}^2"
    rechart = chosen[3]["rechart"]
    print(f"{label}: the route returns {chosen[1]:.2f}x (RMSE {chosen[0]:.5f}), "
          f"re-charted: {rechart['used']}" + ("" if rechart["used"] else f" ({rechart.get('reason')})"), flush=True)
    compared = {}
    for name in CHOICES:
        for stretch_label, stretch in (("before its triangle stretch", {"triangle_stretch": 1.0}), ("finished", {})):
            with forced(name) as choice:
                rmse, ratio, predicted, report = measured(**choice, **stretch)
            if name == "re-charted" and not report["rechart"]["used"]:
                print(f"    {name:>13}: not possible ({report['rechart'].get('reason')})", flush=True)
                break
            if stretch:  # the route compares the layouts before their triangle stretch
                compared[name] = (rmse, predicted)
            print(f"    {name:>13}, {stretch_label:>27}: {ratio:.2f}x, RMSE {rmse:.5f}, model {predicted:.3f}",
                  flush=True)
    if len(compared) < 2:
        return True  # one choice only: nothing the model could get wrong
    (a, (rmse_a, model_a)), (b, (rmse_b, model_b)) = compared.items()
    right = (rmse_a <= rmse_b) == (model_a <= model_b)
    print(f"    compared layouts: measured better {a if rmse_a <= rmse_b else b}, model prefers "
          f"{a if model_a <= model_b else b}: {'right' if right else 'WRONG'}", flush=True)
    return right


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    default = ",".join(f"{s}:lightmap" for s in sample_scenes.TUNING_SCENES)
    parser.add_argument("--scenes", default=default, help=f"scene:variant,... (default: {default})")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--cache", default=os.path.join("evaluate_out", "option_sweep_cache"))
    args = parser.parse_args(argv)
    rows = [tuple(item.split(":")) for item in args.scenes.split(",")]
    wrong = 0
    for scene, variant in rows:
        if scene not in sample_scenes.TUNING_SCENES:
            print(f"note: {scene} is not a tuning scene: report on it, do not tune on it")
        wrong += not row(scene, variant, args.resolution, args.cache)
    print(f"{wrong} of {len(rows)} rows chosen wrongly by the model")


if __name__ == "__main__":
    main()
