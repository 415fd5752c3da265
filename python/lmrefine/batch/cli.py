"""`python3 -m lmrefine batch`: the command line of a batch (lmrefine/cli.py adds it)."""

import argparse
import sys

from .runner import BatchOptions, run_batch

# The add-on batch entry's flags (addon/lmrefine_blender/batch.py --help says
# what they do). They are passed to every level as given, unchecked here, so
# the add-on stays the one judge of its own flags; anything after `--` is
# passed too.
VALUE_FLAGS = ("--objects", "--source-layer", "--resolution", "--padding", "--first-lightmap", "--lightmap-image",
               "--driving-pass", "--strength", "--max-magnification", "--min-shrink", "--max-stretch",
               "--triangle-stretch", "--delta",
               "--passes",
               "--border", "--wavelet", "--backend", "--bake-passes", "--samples", "--stages")
SWITCH_FLAGS = ("--directional", "--no-directional", "--preview", "--no-preview", "--no-tessellate", "--rechart",
                "--no-rechart")
OPTIONAL_VALUE_FLAGS = ("--tessellate",)  # a value may follow


class PassThrough(argparse.Action):
    """Keeps the add-on flags in command-line order in args.flags."""

    def __call__(self, parser, namespace, values, option_string=None):
        flags = list(getattr(namespace, "flags", None) or [])
        flags.append(option_string)
        if isinstance(values, str):
            flags.append(values)
        namespace.flags = flags


def add_batch_parser(commands):
    parser = commands.add_parser(
        "batch", help="refine many levels (.blend files) on Dask distributed: resumable, with retries",
        description="Refine every level with headless Blender and the add-on's batch entry, one Dask task per "
                    "level, into OUT/<level>/ (refined .blend copy, lightmap EXRs, report.json, blender.log). "
                    "OUT/manifest.json makes a re-run skip finished levels whose input and options did not "
                    "change. Add-on flags (--objects, --resolution, --strength, ...) are passed to every level "
                    "as given; flags after `--` too. Guide: docs/batch.md.")
    parser.add_argument("levels", nargs="+", help=".blend files, or folders of them")
    parser.add_argument("--out", required=True, help="output folder (OUT/<level>/, manifest.json, summary.json)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="local worker processes (default: one per core); each Blender "
                                                   "gets cores / workers threads")
    where.add_argument("--scheduler", help="address of an existing Dask scheduler, e.g. tcp://host:8786")
    parser.add_argument("--force", action="store_true", help="redo every level, finished or not")
    parser.add_argument("--evaluate", action="store_true",
                        help="also measure every refined level with `python3 -m lmrefine evaluate` (same objects, "
                             "UV map and resolution; bakes it at up to 4x the resolution, so slow): its "
                             "equal-error resolution ratio goes into the summary, its report into "
                             "OUT/<level>/evaluation/")
    parser.add_argument("--retries", type=int, default=2,
                        help="times a level whose Blender crashed or whose worker died runs again (default: 2)")
    parser.add_argument("--blender", help="Blender executable on the workers (default: $BLENDER or `blender`)")
    parser.add_argument("--batch-script", help="the add-on's batch.py on the workers (default: found beside "
                                               "lmrefine or in Blender's add-ons)")
    addon = parser.add_argument_group("add-on flags, passed to every level as given")
    for flag in VALUE_FLAGS:
        addon.add_argument(flag, action=PassThrough, metavar="VALUE", dest=f"_{flag}")
    for flag in SWITCH_FLAGS:
        addon.add_argument(flag, action=PassThrough, nargs=0, dest=f"_{flag}")
    for flag in OPTIONAL_VALUE_FLAGS:
        addon.add_argument(flag, action=PassThrough, nargs="?", metavar="VALUE", dest=f"_{flag}")
    parser.set_defaults(run=run_batch_command, flags=[])
    return parser


def run_batch_command(args):
    if args.retries < 0:
        raise ValueError(f"--retries must be 0 or more, got {args.retries}")
    options = BatchOptions(flags=list(args.flags) + list(getattr(args, "extra", []) or []), workers=args.workers,
                           scheduler=args.scheduler, force=args.force, retries=args.retries,
                           blender=args.blender, batch_script=args.batch_script, evaluate=args.evaluate)
    summary = run_batch(args.levels, args.out, options, stream=sys.stderr)
    return summary
