"""Headless batch refinement: refine, re-bake, save the images and a .blend, write a JSON report.

    blender -b scene.blend --python batch.py -- --objects A,B --resolution 1024 --out DIR

Flags mirror the panel's settings; a flag left out keeps the setting saved in
the .blend (Scene > lmrefine), i.e. the add-on's default for a scene that
never used it. Exit status: 0 on success, 1 when the run failed (the message
goes to stderr and into the report), 2 for bad flags.
"""

import argparse
import json
import os
import sys
import time

# Runs as a plain script (`--python`), not as part of the package: make the
# package importable from an installed add-on folder or from a checkout.
_HERE = os.path.dirname(os.path.abspath(__file__))
for _path in (os.path.dirname(_HERE), os.path.join(_HERE, "..", "..", "python")):
    _path = os.path.normpath(_path)
    if os.path.isdir(_path) and _path not in sys.path:
        sys.path.insert(0, _path)

import bpy  # noqa: E402

import lmrefine_blender  # noqa: E402
from lmrefine_blender import bridge, errors, pipeline  # noqa: E402
from lmrefine_blender.journal import Journal  # noqa: E402

PASSES = ("direct", "indirect", "combined", "ao")
# Settings whose flag has another name.
FLAG_OF = {"tessellate_budget": "tessellate", "layouts": "per_effect", "per_effect_rule": "per_effect"}


def _csv(text):
    return [item.strip() for item in text.split(",") if item.strip()]


def _passes(text):
    names = [name.lower() for name in _csv(text)]
    unknown = sorted(set(names) - set(PASSES))
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown pass(es) {unknown or text!r}; choose from {', '.join(PASSES)}")
    return names


def build_parser():
    parser = argparse.ArgumentParser(
        prog="blender -b scene.blend --python batch.py --",
        description="Refine the lightmap UV maps of a .blend's objects, bake the lightmaps again with the "
                    "refined layout, and write the images (EXR), a copy of the .blend and report.json into "
                    "--out. Flags left out keep the scene's lmrefine settings.",
    )
    parser.add_argument("--objects", type=_csv, required=True,
                        help="what to refine: 'all' (every mesh object of the scene with a UV map), "
                             "'selected' (the objects selected when the .blend was saved), "
                             "'collection:NAME' (the mesh objects in that collection and its children), "
                             "or comma-separated object names")
    parser.add_argument("--out", required=True, help="output folder (created if missing)")
    parser.add_argument("--source-layer", help="lightmap UV map to refine (default: a map named like "
                        "'Lightmap'/'UVMap.001', else the second map)")
    parser.add_argument("--resolution", type=int, help="lightmap size in texels")
    parser.add_argument("--padding", type=int, help="gutter between charts in texels")
    parser.add_argument("--first-lightmap", choices=("image", "embree", "cycles"),
                        help="the lightmap that drives the refinement: an existing image, or bake it now")
    parser.add_argument("--lightmap-image", help="name of the image to use with --first-lightmap image "
                        "(default: found in each object's material)")
    parser.add_argument("--driving-pass", choices=PASSES, help="what the first bake measures")
    parser.add_argument("--strength", type=float,
                        help="texel growth at the strongest light change (0 = unchanged layout)")
    parser.add_argument("--max-magnification", type=float, help="largest growth of a texel's area")
    parser.add_argument("--min-shrink", type=float, help="smallest a texel's area may become (fraction)")
    parser.add_argument("--max-stretch", type=float, help="largest stretch of a chart across its light changes "
                        "(its texel area kept; 1 = none)")
    parser.add_argument("--triangle-stretch", type=float, help="largest stretch of a triangle across the light "
                        "changes that run one way inside it, after the charts are packed (1 = none; default 2)")
    parser.add_argument("--delta", type=float, help="automaton stop threshold")
    parser.add_argument("--passes", type=int, help="refinement passes")
    parser.add_argument("--border", choices=("same", "border_rule", "extra_ring"), help="grid border treatment")
    parser.add_argument("--directional", action=argparse.BooleanOptionalAction, default=None,
                        help="four energies per cell")
    parser.add_argument("--wavelet", choices=("d4", "haar", "d12", "d20", "cdf53", "cdf97"),
                        help="gradient-map filter")
    parser.add_argument("--stages", type=int, help="refinement stages: bake, refine, bake, refine...; an object "
                        "stops at the first stage that changes its layout by less than 5%% (default 1)")
    parser.add_argument("--tessellate", type=float, nargs="?", const=0.25, metavar="BUDGET",
                        help="before refining, split the triangles strong light transitions cross, in the mesh; "
                             "BUDGET: most vertices added, as a fraction of each object's (default 0.25)")
    parser.add_argument("--no-tessellate", action="store_true", help="turn tessellation off (when the .blend "
                        "has it on)")
    parser.add_argument("--per-effect", nargs="?", const="sqrt", choices=("sqrt", "energy", "equal"),
                        metavar="RULE", help="Layouts: Per Effect: direct and indirect light each get their own "
                        "refined UV map and image, RULE (sqrt, energy, equal; default sqrt) splitting the "
                        "resolution^2 texels between them")
    parser.add_argument("--rechart", action=argparse.BooleanOptionalAction, default=None,
                        help="re-chart an object from its mesh when its source map gives the refiner no room "
                             "(one chart per face, as Lightmap Pack makes) or its charts fold over sharp edges "
                             "whose light differs, and the error model predicts less error; --no-rechart refines the source map as it is")
    parser.add_argument("--backend", choices=("embree", "cycles"), help="baker of the final lightmaps")
    parser.add_argument("--bake-passes", type=_passes, help=f"comma-separated, of: {', '.join(PASSES)}")
    parser.add_argument("--samples", type=int, help="samples per texel")
    parser.add_argument("--float32", action=argparse.BooleanOptionalAction, default=None,
                        help="write 32-bit float EXRs (default: half float; both ZIP-compressed)")
    parser.add_argument("--shared-atlas", action=argparse.BooleanOptionalAction, default=None,
                        help="objects whose lightmap UV maps share one atlas are refined together and baked into "
                             "one image per pass, <first object>_atlas_lightmap_<pass>.exr (default: on); "
                             "--no-shared-atlas writes one image per object")
    parser.add_argument("--preview", action=argparse.BooleanOptionalAction, default=None,
                        help="hook the lightmap into the materials of the saved .blend")
    parser.add_argument("--report", help="JSON report path (default: OUT/report.json)")
    return parser


def apply_flags(settings, args):
    """Copy the given flags onto the scene's settings (unset flags keep the scene's values)."""
    mapping = {
        "source_layer": args.source_layer, "resolution": args.resolution, "padding": args.padding,
        "strength": args.strength, "max_magnification": args.max_magnification, "min_shrink": args.min_shrink,
        "max_stretch": args.max_stretch, "triangle_stretch": args.triangle_stretch,
        "delta": args.delta, "passes": args.passes, "directional": args.directional, "samples": args.samples,
        "preview": args.preview, "exr_float32": args.float32, "stages": args.stages,
        "shared_atlas": args.shared_atlas,
        "rechart": args.rechart,
    }
    if args.per_effect is not None:
        mapping.update(layouts='PER_EFFECT', per_effect_rule=args.per_effect.upper())
    upper = {"first_lightmap": args.first_lightmap, "driving_pass": args.driving_pass, "border": args.border,
             "wavelet": args.wavelet, "backend": args.backend}
    mapping.update({key: value.upper() for key, value in upper.items() if value is not None})
    if args.bake_passes is not None:
        mapping["bake_passes"] = {name.upper() for name in args.bake_passes}
    if args.tessellate is not None and args.no_tessellate:
        raise pipeline.UserError("--tessellate and --no-tessellate contradict each other: pass one of them")
    if args.tessellate is not None:
        mapping.update(tessellate=True, tessellate_budget=args.tessellate)
    elif args.no_tessellate:
        mapping["tessellate"] = False
    if args.lightmap_image is not None:
        image = bpy.data.images.get(args.lightmap_image)
        if image is None:
            raise pipeline.UserError(f"no image named '{args.lightmap_image}' in {bpy.data.filepath}")
        mapping["lightmap_image"] = image
    for key, value in mapping.items():
        if value is not None:
            _check_range(settings, key, value)
            try:
                setattr(settings, key, value)
            except (TypeError, ValueError) as error:
                raise pipeline.UserError(f"--{FLAG_OF.get(key, key).replace('_', '-')}: {error}") from error


def _check_range(settings, key, value):
    """Blender clamps a number set outside a property's hard range without a
    word; a command line must refuse it instead."""
    prop = settings.bl_rna.properties[key]
    if prop.type not in ('INT', 'FLOAT') or getattr(prop, "array_length", 0) or isinstance(value, bool):
        return
    low, high = prop.hard_min, prop.hard_max
    if not low <= value <= high:
        flag = f"--{FLAG_OF.get(key, key).replace('_', '-')} {value:g}"
        if high >= 1e30:  # no upper bound in practice (a float's 3.4e38): do not print it
            raise pipeline.UserError(f"{flag} is below {low:g}: pass {low:g} or more")
        raise pipeline.UserError(f"{flag} is outside {low:g} to {high:g}: pass a value in that range")


def _progress(fraction, label, state={"shown": None}):
    """One line per stage and per tenth of the run."""
    key = (label, int(fraction * 10))
    if key != state["shown"]:
        state["shown"] = key
        print(f"lmrefine: {100 * fraction:3.0f}% {label}", flush=True)


def _meshes_with_uvs(objects):
    return [obj.name for obj in objects if obj.type == 'MESH' and len(obj.data.uv_layers) > 0]


class Names(list):
    """Object names, plus the mesh objects with UV maps that `all` or a collection left out (`left_out`):
    those the bake does not see (hidden, disabled for render, an excluded collection's instance sources)."""

    def __init__(self, names=(), left_out=()):
        super().__init__(names)
        self.left_out = sorted(left_out)


def _baked_meshes(objects):
    """Names(the mesh objects with UV maps that take part in a bake, left_out=the others)."""
    candidates = [bpy.data.objects[name] for name in _meshes_with_uvs(objects)]
    seen = [bridge.renders(obj) for obj in candidates]
    return Names([o.name for o, s in zip(candidates, seen) if s], [o.name for o, s in zip(candidates, seen) if not s])


def object_names(spec, scene):
    """The object names an --objects value means in this scene, a Names (raises pipeline.UserError when it
    means none). `all` and `collection:NAME` take the mesh objects with UV maps the bake sees; named
    objects are taken as named (a hidden one is then skipped with its fix)."""
    if spec == ["all"]:
        names = _baked_meshes(scene.objects)
        what = "the scene"
    elif spec == ["selected"]:
        names = Names(obj.name for obj in scene.objects if obj.select_get())
        what = "the selection saved in the .blend"
    elif len(spec) == 1 and spec[0].startswith("collection:"):
        wanted = spec[0][len("collection:"):]
        collection = bpy.data.collections.get(wanted)
        if collection is None:
            known = ", ".join(sorted(c.name for c in bpy.data.collections)) or "none"
            raise pipeline.UserError(f"--objects collection:{wanted}: no such collection (collections: {known})")
        names = _baked_meshes(collection.all_objects)
        what = f"collection '{wanted}'"
    else:
        missing = [name for name in spec if name not in bpy.data.objects]
        if missing:
            meshes = ", ".join(sorted(_meshes_with_uvs(scene.objects))[:20]) or "none"
            raise pipeline.UserError(f"no object(s) named {', '.join(missing)} in {bpy.data.filepath} "
                                     f"(mesh objects with UV maps: {meshes}; or use --objects all)")
        return Names(spec)
    if not names:
        hidden = f" the bake sees ({len(names.left_out)} hidden or disabled for render)" if names.left_out else ""
        raise pipeline.UserError(f"--objects {','.join(spec)}: no mesh object with a UV map{hidden} in {what}")
    return Names(sorted(names), names.left_out)


def run(args):
    """The batch job; returns the report dict (raises pipeline.UserError and the job's errors)."""
    if not bpy.data.filepath:
        raise pipeline.UserError("no .blend opened: run `blender -b scene.blend --python batch.py -- ...`")
    scene = bpy.context.scene
    names = object_names(args.objects, scene)
    out = os.path.abspath(args.out)
    blend_copy = os.path.join(out, os.path.basename(bpy.data.filepath))
    if os.path.abspath(bpy.data.filepath) == blend_copy:
        raise pipeline.UserError(f"--out {args.out} is the folder of the input .blend, whose copy would "
                                 "overwrite it: choose another folder")
    objects = [bpy.data.objects[name] for name in names]
    not_meshes = [f"'{obj.name}' ({obj.type.lower()})" for obj in objects if obj.type != 'MESH']
    if not_meshes:
        raise pipeline.UserError(f"--objects names objects that are not meshes: {', '.join(not_meshes)}")
    apply_flags(scene.lmrefine, args)
    options = pipeline.settings_snapshot(scene.lmrefine)
    targets = pipeline.validate(bpy.context, objects, options)
    os.makedirs(out, exist_ok=True)
    journal = Journal()
    try:
        job = pipeline.run(bpy.context, targets, options, journal, image_dir=out)
        outcome = pipeline.run_blocking(job, progress=_progress)
    except BaseException:
        journal.rollback()
        raise
    journal.commit()
    if names.left_out:
        shown = ", ".join(names.left_out[:10]) + (", ..." if len(names.left_out) > 10 else "")
        outcome.warnings.append(f"Left out of --objects {','.join(args.objects)}: {len(names.left_out)} mesh "
                                f"object(s) the bake does not see ({shown}; hidden, disabled for render, or in an "
                                "excluded collection): show them and enable them for render to refine them")
    for warning in outcome.warnings:
        print(f"lmrefine: warning: {warning}", file=sys.stderr, flush=True)
    filepaths = bpy.context.preferences.filepaths
    save_version = filepaths.save_version
    filepaths.save_version = 0  # no copy.blend1 backup beside the copy
    try:
        bpy.ops.wm.save_as_mainfile(filepath=blend_copy)
        bpy.ops.file.make_paths_relative()  # the EXRs sit beside the copy: keep the folder relocatable
        bpy.ops.wm.save_mainfile()
    finally:
        filepaths.save_version = save_version
    return {
        "ok": True,
        "blend": blend_copy,
        "objects": {name: _object_entry(outcome, name, t) for name, t in ((t.obj.name, t) for t in targets)
                    if name in outcome.objects},
        "atlases": {group: {"objects": objects, "report": outcome.reports[group],
                            "images": {p: outcome.image_files[i] for p, i in outcome.images[group].items()}}
                    for group, objects in outcome.atlases.items()},
        "summary": outcome.summary(),
        "warnings": outcome.warnings,
        "timings": outcome.timings,
        "settings": {key: value for key, value in options.items() if key != "lightmap_image"},
    }


def _object_entry(outcome, name, target):
    """One object of the report: its maps, its atlas group and that group's images. The refinement
    report is the group's (atlases[group]["report"]); an object alone in its group carries it here too."""
    group = outcome.atlas_of(name)
    entry = {"source_layer": target.source, "refined_layer": target.refined, "atlas": group,
             "tessellation": outcome.tessellation.get(name),
             "images": {p: outcome.image_files[i] for p, i in outcome.images[group].items()}}
    if len(outcome.atlases[group]) == 1:
        entry["report"] = outcome.reports[group]
    if outcome.effects:  # Layouts: Per Effect: one refined map per effect instead of one
        del entry["refined_layer"]
        entry["refined_layers"] = {effect: f"{target.refined}_{effect}" for effect in outcome.effects[group]}
    return entry


def main(argv):
    parser = build_parser()
    args = parser.parse_args(argv)  # exits 2 with usage on bad flags, 0 on --help
    report_path = os.path.abspath(args.report or os.path.join(args.out, "report.json"))
    started = time.perf_counter()
    if not hasattr(bpy.types.Scene, "lmrefine"):
        lmrefine_blender.register()
    errors.BATCH = True  # messages name settings by their flags
    try:
        report = run(args)
        code = 0
    except Exception as error:
        from lmrefine.messages import user_message
        message = str(error) if isinstance(error, pipeline.UserError) else user_message(error)
        if message != str(error):  # the full text (native source location) stays in the log
            print(f"lmrefine: details: {type(error).__name__}: {error}", file=sys.stderr, flush=True)
        print(f"lmrefine: error: {message}", file=sys.stderr, flush=True)
        report = {"ok": False, "error": message}
        code = 1
    report["seconds"] = time.perf_counter() - started
    os.makedirs(os.path.dirname(report_path), exist_ok=True)
    with open(report_path, "w", encoding="utf-8") as stream:
        json.dump(report, stream, indent=2)
    return code


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    sys.exit(main(argv))
