"""Command line: ``python3 -m lmrefine <command> ...`` (see ``--help``)."""

import argparse
import os
import sys

import numpy as np

from . import _native
from .gradient_report import write_gradient_report
from .progressbar import ProgressBar

WAVELETS = ("haar", "d4", "d12", "d20", "cdf53", "cdf97")


class CliError(Exception):
    """A user-facing failure: printed without a traceback, exit code 2."""


def load_mask(args, shape):
    """Coverage from a layout (.npz with uvs and triangles), a mask image, or
    the whole image. Never from the lightmap's alpha."""
    if args.layout:
        try:
            layout = np.load(args.layout)
            uvs, triangles = layout["uvs"], layout["triangles"]
        except (OSError, KeyError, ValueError) as error:
            raise CliError(f"cannot read layout '{args.layout}': {error} "
                           "(expected an .npz with arrays 'uvs' (N, 2) and 'triangles' (T, 3))")
        return _native.coverage_mask(uvs, triangles, shape)
    if args.mask:
        mask_image = _native.read_image(args.mask)
        if mask_image.shape[:2] != shape:
            raise CliError(f"mask '{args.mask}' is {mask_image.shape[1]}x{mask_image.shape[0]}, "
                           f"the lightmap is {shape[1]}x{shape[0]}")
        return mask_image[..., 0] > 0.5
    return np.ones(shape, bool)


def run_gradient_map(args):
    lightmap = _native.read_image(args.lightmap)
    if lightmap.shape[2] == 2:  # gray + alpha: the gray is the light
        lightmap = lightmap[..., :1]
    image = np.ascontiguousarray(lightmap[..., 0] if lightmap.shape[2] == 1 else lightmap)
    mask = load_mask(args, image.shape[:2])
    bar = ProgressBar()
    summary = write_gradient_report(image, mask, args.out, source=args.lightmap, wavelet=args.wavelet, progress=bar)
    bar.close()
    print(open(os.path.join(args.out, "summary.md")).read())
    print(f"wrote {args.out}/")
    return summary


def parse_multipliers(text):
    try:
        return tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers like 1,1.5,2,3,4, got '{text}'")


def evaluation_options(args):
    from .evaluation import EvaluationOptions

    refine_options = {}
    if args.strength is not None:
        refine_options["strength"] = args.strength
    if args.refine_passes is not None:
        refine_options["passes"] = args.refine_passes
    if args.no_repack:
        refine_options["repack"] = False
    if getattr(args, "no_stretch", False):
        refine_options["max_stretch"] = 1.0
    if getattr(args, "triangle_stretch", None) is not None:
        refine_options["triangle_stretch"] = args.triangle_stretch
    if getattr(args, "no_triangle_stretch", False):
        refine_options["triangle_stretch"] = 1.0
    rechart = getattr(args, "rechart", None)
    compare = ()
    if rechart is not None and getattr(args, "compare", False):
        compare = ("smart", "lightmap") if args.variant == "both" else (args.variant,)
    return EvaluationOptions(resolution=args.resolution, samples=args.samples,
                             first_samples=getattr(args, "first_samples", None), truth_samples=args.truth_samples,
                             points=args.points, seed=args.seed, multipliers=args.multipliers,
                             padding=args.padding, denoise=args.denoise, bake_pass=args.bake_pass,
                             refine_options=refine_options, view_width=args.view_width,
                             tessellate=args.tessellate, rechart=rechart, compare_variants=compare,
                             stages=args.stages, per_effect=getattr(args, "per_effect", None),
                             auto_rechart=not getattr(args, "no_rechart", False))


def load_scenes(names, args=None):
    """Bundled samples by name, scene .npz files, and .blend files (exported
    through headless Blender into OUT/scenes/, again only when they changed)."""
    from .sample_scenes import load_sample, sample_names

    names = names or sample_names()
    if not names:
        raise CliError("no sample scenes found in blend_samples/ (run `make samples`), and none given")
    scenes = []
    for name in names:
        if name.lower().endswith(".blend"):
            from .scene_export import cached_export

            name = cached_export(name, os.path.join(args.out, "scenes"), objects=args.objects, uv_map=args.uv_map,
                                 blender=args.blender)
        scenes.append(load_sample(name))
    return scenes


def run_export_scene(args):
    from .sample_scenes import load_sample
    from .scene_export import export_blend

    out = args.out or os.path.splitext(os.path.basename(args.blend))[0] + ".npz"
    export_blend(args.blend, out, objects=args.objects, uv_map=args.uv_map, blender=args.blender)
    scene = load_sample(out)
    uvs = scene.uvs["own"]
    print(f"{out}: {len(scene.objects)} receivers, {len(scene.triangles)} triangles, UVs in "
          f"[{uvs.min():.3g}, {uvs.max():.3g}], {len(scene.occluder_triangles)} occluder triangles, "
          f"{len(scene.lights)} lights; evaluate it with: python3 -m lmrefine evaluate {out}")
    return out


def add_blend_arguments(parser):
    parser.add_argument("--objects", default="all",
                        help="the objects that get a lightmap (receivers): 'all' (every visible mesh object with a UV "
                             "map, default), 'selected', 'collection:NAME' or comma-separated names; every other "
                             "visible object casts shadows")
    parser.add_argument("--uv-map", help="the receivers' lightmap UV map (default: as the add-on picks it: a map "
                                         "named like 'Lightmap', else the second UV map, else the only one)")
    parser.add_argument("--blender", help="Blender executable (default: $BLENDER or `blender` on PATH)")


def run_evaluate(args):
    from .evaluation import evaluate_samples
    from .evaluation_report import summary_table

    options = evaluation_options(args)
    options.check()
    scenes = load_scenes(args.scenes, args)
    variants = ("smart", "lightmap") if args.variant == "both" else (args.variant,)
    if options.rechart is not None:
        variants = variants[:1]  # the re-charted layout replaces the scene's UVs: one run per scene
    bar = ProgressBar()
    try:
        summary = evaluate_samples(scenes, options, args.out, variants=variants, progress=bar)
    finally:
        bar.close()
    print(summary_table(summary))
    for scene in summary["scenes"]:
        if scene["notes"]:
            verdict = "gain, but" if scene["gain"] else "no gain"
            print(f"\n{scene['scene']} ({scene['variant']}): {verdict}: " + "; ".join(scene["notes"]))
    print(f"\nwrote {args.out}/report.md, report.json and one folder of pictures per scene")
    for scene in summary["scenes"]:
        if scene.get("surface"):
            folder = os.path.join(args.out, f"{scene['scene']}_{scene['variant']}")
            print(f"the lit surface ({scene['scene']}, plain / refined / ground truth): {folder}/surface.png, "
                  "surface_crops.png, surface_density.png")
    return summary


def run_demo(args):
    """The full pipeline on one bundled scene, plus the gradient-map pictures
    of its baseline bake (stage 1 of the method)."""
    summary = run_evaluate(args)
    scene = summary["scenes"][0]
    folder = os.path.join(args.out, f"{scene['scene']}_{scene['variant']}")
    # The layout the baseline was baked on (the scene's own, or re-charted).
    with np.load(os.path.join(folder, "refined_layout.npz")) as layout:
        uvs, triangles = layout["original_uvs"], layout["triangles"]
    baseline = _native.read_image(os.path.join(folder, "baseline.exr"))
    mask = _native.coverage_mask(uvs, triangles, baseline.shape[:2])
    write_gradient_report(np.ascontiguousarray(baseline[..., :3]), mask, os.path.join(args.out, "gradient"),
                          source=f"{scene['scene']} baseline bake", wavelet=args.wavelet)
    print(f"gradient map pictures of the baseline bake: {args.out}/gradient/")
    return summary


def add_evaluation_arguments(parser, resolution, points):
    parser.add_argument("--resolution", type=int, default=resolution,
                        help=f"lightmap resolution R (default: {resolution})")
    parser.add_argument("--samples", type=int, default=32, help="bake samples per texel (default: 32)")
    parser.add_argument("--first-samples", type=int, metavar="SAMPLES",
                        help="bake samples per texel of the first bake, the map the refinement reads (default: "
                             "--samples); every other map is baked with --samples")
    parser.add_argument("--truth-samples", type=int, default=256,
                        help="samples per point of the ground truth (default: 256)")
    parser.add_argument("--points", type=int, default=points,
                        help=f"surface points the error is measured at (default: {points})")
    parser.add_argument("--multipliers", type=parse_multipliers, default=(1.0, 1.5, 2.0, 3.0, 4.0),
                        help="baseline resolutions for the equal-error search, as multiples of R "
                             "(default: 1,1.5,2,3,4)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the points and the bakes (default: 0)")
    parser.add_argument("--padding", type=float, default=2.0,
                        help="gutter in texels the refined layout must keep (default: 2, or the original's if smaller)")
    parser.add_argument("--strength", type=float, help="refine_uvs strength (default: refine_uvs' own)")
    parser.add_argument("--refine-passes", type=int, help="refine_uvs passes (default: refine_uvs' own)")
    parser.add_argument("--no-repack", action="store_true",
                        help="refine inside charts only (refine_uvs repack=False): no chart scaling or packing")
    parser.add_argument("--no-stretch", action="store_true",
                        help="never stretch a chart across its light changes (refine_uvs max_stretch=1)")
    parser.add_argument("--triangle-stretch", type=float, metavar="STRETCH",
                        help="largest stretch of a triangle across the light changes that run one way inside it "
                             "(refine_uvs triangle_stretch; default: refine_uvs' own, 2)")
    parser.add_argument("--no-triangle-stretch", action="store_true",
                        help="never stretch a triangle across its light changes (refine_uvs triangle_stretch=1)")
    from .charting import DEFAULT_ANGLE

    parser.add_argument("--rechart", type=float, nargs="?", const=DEFAULT_ANGLE, metavar="ANGLE",
                        help="re-chart the scene's mesh (lmrefine.rechart: charts of faces whose normals are within "
                             f"ANGLE degrees, default {DEFAULT_ANGLE:g}, conformal unwrap, uniform texel density, "
                             "packed) and use that layout instead of the scene's own UVs; put scene names before it")
    parser.add_argument("--no-rechart", action="store_true",
                        help="refine the scene's own layout even when it gives the refiner no room (refine_uvs "
                             "rechart=False); by default a Lightmap Pack layout is re-charted from the mesh, as in "
                             "the add-on")
    parser.add_argument("--compare", action="store_true",
                        help="with --rechart: also bake the scene's own --variant layout(s) uniformly at every "
                             "multiplier and report the equal-error ratio of the re-charted maps against them")
    parser.add_argument("--denoise", action="store_true", help="denoise every bake (edge-aware)")
    parser.add_argument("--view-width", type=int, default=480,
                        help="width in pixels of the pictures of the lit surface, 16 to 2048 (default: 480; 0: none)")
    parser.add_argument("--stages", type=int, default=1,
                        help="bake-refine stages, each refining the previous stage's layout from its own bake "
                             "(default: 1); stops early when a stage hardly changes the layout, backs off "
                             "most of its deformation or gives the light changes no more texels")
    parser.add_argument("--tessellate", type=float, nargs="?", const=0.25, metavar="BUDGET",
                        help="split the triangles strong transitions cross before refining, at most BUDGET more "
                             "vertices as a fraction (default 0.25 = +25%%; docs/refiner.md, Tessellation)")
    parser.add_argument("--per-effect", nargs="?", const="sqrt", metavar="RULES",
                        help="also give direct and indirect light each its own refined layout and map, the texels "
                             "split by RULES (comma-separated, each one measured: equal, energy, sqrt; default "
                             "sqrt), and compare their sum with one combined map of R^2 texels (evaluates the "
                             "combined light; docs/refiner.md, Separate layouts for separate effects)")
    parser.add_argument("--pass", dest="bake_pass", choices=("direct", "ao", "indirect", "combined"),
                        help="light to bake and compare (default: the scene's own: direct, combined for the room)")


def _demo_scenes(args):
    if args.scene.lower().endswith(".blend"):
        raise CliError(f"demo runs on a bundled sample or a scene .npz; for '{args.scene}' run "
                       f"`python3 -m lmrefine evaluate {args.scene}`")
    args.scenes = [args.scene]
    return args


def build_parser():
    parser = argparse.ArgumentParser(
        prog="python3 -m lmrefine",
        description="lmrefine: sharper baked lightmaps from the same texels.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    gradient = commands.add_parser(
        "gradient-map", help="compute the wavelet gradient map of a lightmap and write pictures + a summary",
        description="Compute the four-channel wavelet gradient map of a lightmap (EXR, HDR, PNG, TIFF) "
                    "and write one picture per channel, the map as EXR, summary.json and summary.md.")
    gradient.add_argument("lightmap", help="lightmap image file")
    coverage = gradient.add_mutually_exclusive_group()
    coverage.add_argument("--layout", help=".npz with 'uvs' (N, 2) and 'triangles' (T, 3): coverage is rasterized from it")
    coverage.add_argument("--mask", help="coverage mask image (white = covered), same size as the lightmap")
    gradient.add_argument("--wavelet", choices=WAVELETS, default="d4", help="wavelet (default: d4, the thesis' choice)")
    gradient.add_argument("--out", default="gradient_out", help="output folder (default: gradient_out)")
    gradient.set_defaults(run=run_gradient_map)

    evaluate = commands.add_parser(
        "evaluate", help="measure the method on scenes: baseline vs refined lightmaps, report and pictures",
        description="Bake each scene with its uniform lightmap layout, refine the layout, bake again at the same "
                    "resolution, and measure both against a ground truth at surface points (RMSE, transition-point "
                    "error, transition widening, equal-error resolution). Writes report.md, report.json and "
                    "pictures per scene. Metrics: docs/evaluation.md.")
    evaluate.add_argument("scenes", nargs="*",
                          help="bundled sample names (courtyard, room, fence_and_tree, game_level, atrium, plaza, alley, village, cloister, depot, stairs, hillside), scene .npz "
                               "files or .blend files (exported with headless Blender into OUT/scenes/, as "
                               "export-scene does) (default: every bundled sample)")
    evaluate.add_argument("--variant", choices=("smart", "lightmap", "both"), default="smart",
                          help="bundled samples' lightmap UVs: Smart UV Project, Lightmap Pack, or both (default: "
                               "smart); a scene from a .blend has one, its lightmap UV map")
    add_blend_arguments(evaluate.add_argument_group(".blend files"))
    add_evaluation_arguments(evaluate, resolution=256, points=20000)
    evaluate.add_argument("--out", default="evaluate_out", help="output folder (default: evaluate_out)")
    evaluate.set_defaults(run=run_evaluate)

    demo = commands.add_parser(
        "demo", help="run the whole pipeline on a bundled sample and print the summary",
        description="Bake the bundled courtyard, refine its lightmap layout, bake again and compare "
                    "(python3 -m lmrefine evaluate courtyard), plus the gradient-map pictures of the first bake.")
    demo.add_argument("--scene", default="courtyard", help="bundled sample or scene .npz (default: courtyard)")
    demo.add_argument("--variant", choices=("smart", "lightmap"), default="smart",
                      help="lightmap UVs (default: smart)")
    add_evaluation_arguments(demo, resolution=256, points=20000)
    demo.add_argument("--wavelet", choices=WAVELETS, default="d4", help="wavelet of the gradient-map pictures")
    demo.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    demo.set_defaults(run=lambda args: run_demo(_demo_scenes(args)))

    export = commands.add_parser(
        "export-scene", help="export a .blend's scene (receivers, occluders, lights, camera) for evaluate",
        description="Export the scene of a .blend with headless Blender into the scene .npz that `evaluate` reads: "
                    "the receivers with their lightmap UV map, read as the add-on's bake reads them (modifiers "
                    "applied), every other visible object as an occluder, the lights, the world colour and the "
                    "active camera. Needs Blender (3.4 or later).")
    export.add_argument("blend", help="the .blend file")
    export.add_argument("-o", "--out", help="the scene .npz to write (default: <name of the .blend>.npz here)")
    add_blend_arguments(export)
    export.set_defaults(run=run_export_scene)

    from .batch.cli import add_batch_parser

    add_batch_parser(commands)
    return parser


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = []
    if argv[:1] == ["batch"] and "--" in argv:  # batch: flags after `--` go to the add-on as they are
        extra = argv[argv.index("--") + 1:]
        argv = argv[:argv.index("--")]
    args = build_parser().parse_args(argv)
    args.extra = extra
    try:
        result = args.run(args)
    except (CliError, ValueError, OSError, MemoryError) as error:
        print(f"lmrefine {args.command}: error: {error}", file=sys.stderr)
        return 2
    except _native.CancelledError:
        print(f"lmrefine {args.command}: cancelled", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"\nlmrefine {args.command}: interrupted", file=sys.stderr)
        return 130
    if args.command == "batch" and not result["ok"]:
        return 1  # a level failed: the summary says which and where its log is
    return 0
