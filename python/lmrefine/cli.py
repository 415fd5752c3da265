"""Command line: ``python3 -m lmrefine <command> ...`` (see ``--help``)."""

import argparse
import os
import sys

import numpy as np

from . import _native
from .gradient_report import write_gradient_report
from .progressbar import ProgressBar

WAVELETS = ("haar", "d4", "d12", "d20", "cdf53", "cdf97")
SAMPLES_DIR = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", "..", "blend_samples"))


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


def run_demo(args):
    args.lightmap = args.lightmap or os.path.join(SAMPLES_DIR, "courtyard_lightmap.exr")
    args.layout = args.layout or os.path.join(SAMPLES_DIR, "courtyard_layout.npz")
    args.mask = None
    for path in (args.lightmap, args.layout):
        if not os.path.exists(path):
            raise CliError(f"sample '{path}' not found; run from the lmrefine checkout or pass "
                           "--lightmap and --layout")
    return run_gradient_map(args)


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

    demo = commands.add_parser(
        "demo", help="run the pipeline on the bundled sample and write its report",
        description="Run lmrefine on the bundled courtyard sample (blend_samples/) and write the report.")
    demo.add_argument("--lightmap", help="lightmap to use instead of the bundled sample")
    demo.add_argument("--layout", help="layout .npz to use instead of the bundled sample's")
    demo.add_argument("--wavelet", choices=WAVELETS, default="d4", help="wavelet (default: d4)")
    demo.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    demo.set_defaults(run=run_demo)
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        args.run(args)
    except (CliError, ValueError, OSError) as error:
        print(f"lmrefine {args.command}: error: {error}", file=sys.stderr)
        return 2
    except _native.CancelledError:
        print(f"lmrefine {args.command}: cancelled", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"\nlmrefine {args.command}: interrupted", file=sys.stderr)
        return 130
    return 0
