"""The refinement job: validate, first bake, refine, write the layer, second bake.

The job is a generator so one implementation serves both drivers: it runs
bpy work itself (on Blender's main thread) and *yields* each long native call
as a NativeWork; the driver runs it, inline (operator `execute`, batch) or
on a worker thread while a modal operator keeps Blender responsive and
listens for Esc, and sends the result back. Native calls touch numpy only,
never bpy, so running them off the main thread is safe.

No algorithm here: the layout comes from lmrefine.refine_uvs and is checked
with lmrefine.check_layout; lightmaps come from lmrefine.bake or Cycles.
"""

import itertools
import os
import re
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import atlas, bridge, cycles_bake, effects, materials, tessellation
from .errors import Cancelled, UserError, setting  # noqa: F401  (re-exported for the drivers)

REFINED_SUFFIX = "_refined"
# The stages refine_uvs reports, each from 0 to 1: gradient map, automaton, pack.
REFINE_STAGES = 3
# The further stages of refine_uvs' re-chart route (a source map with no room, the mesh given): the
# re-charting's unwrap and pack, then the re-charted layout's gradient map, automaton and pack.
RECHART_STAGES = 5
# The light transports the baker runs per map for each pass, each a stage of its progress.
TRANSPORTS = {"direct": {"direct"}, "indirect": {"indirect"}, "combined": {"direct", "indirect"}, "ao": {"ao"}}
# Texels both bakers fill into the gutter around each chart (Blender's default
# bake margin): bilinear and mipmapped lookups near a chart border stay on it.
BAKE_MARGIN = 16
# The baker's own count in its progress stages, "(map 3/5)".
_BAKER_MAP = re.compile(r"\(map (\d+/\d+)\)")


def error_text(error):
    """`error` as a user reads it: without the native core's C++ source locations ("[coverage.cpp:127]").
    When one was dropped, the full text goes to the console (the system console, a batch's stderr)
    as `lmrefine: details: ...`, for a bug report."""
    from lmrefine.messages import without_source_location
    text = without_source_location(error)
    if text != str(error):
        print(f"lmrefine: details: {type(error).__name__}: {error}", file=sys.stderr, flush=True)
    return text


def refine_parts(group, options, refine_options=None):
    """The stages refine_uvs(..., positions=group.positions) will report for `group`'s joined layout:
    REFINE_STAGES, and RECHART_STAGES more when it may take the re-chart route (the rule of refine_uvs:
    re-charting on, strength above 0, the mesh given, and a layout with no room or charts folded over
    creases; whether the folds hold enough light to be cut is known only from the bake, and a route
    not taken ends its share at once), so the progress fills the refinement's share over all of them
    rather than standing still through the re-chart. A layout whose every UV lies on its chart's border (one
    chart per face) reports no automaton: refine_uvs does not run it there. `refine_options`: the group's own
    (default the run's)."""
    from lmrefine import folds, rechart_route
    refine_options = options["refine_options"] if refine_options is None else refine_options
    room = rechart_route.layout_room(group.uvs, group.triangles)
    source = REFINE_STAGES - 1 if room["room_fraction"] == 0 else REFINE_STAGES
    if group.positions is None or not refine_options.get("rechart", True) or refine_options.get("strength") == 0:
        return source
    if refine_options.get("rechart") == "always":
        return source + RECHART_STAGES
    route = room["no_room"] or len(folds.fold_faces(group.uvs, group.triangles, group.positions,
                                                     rechart_route.ANGLE)[0]) > 0
    return source + (RECHART_STAGES if route else 0)


@dataclass
class NativeWork:
    """A long native call the driver must run: `call(progress)` -> value.

    With `call` None it is only a progress mark before blocking bpy work (a
    Cycles bake): the driver shows the label, checks for a cancel and resumes.
    """

    label: str
    call: object
    start: float  # overall progress at the start of this work, in [0, 1]
    span: float  # share of the overall progress it covers
    parts: int = 1  # stages the call reports one after another, each from 0 to 1 (the baker: one per map and transport)


@dataclass
class Target:
    """One object to refine, with everything validated up front."""

    obj: object
    source: str
    refined: str
    layout: bridge.Layout
    image: object = None  # first lightmap, when it comes from an existing image
    zero_area: int = 0  # triangles of zero area in 3-D: they need no texels, the baker skips them
    unsplit: tuple = None  # with Tessellate on: why its mesh is refined without splitting (tessellation.problem)


def grown_charts(report):
    """The charts of a refine_uvs report's output grown into the space a
    packing left, by the kept repack's fill or by the fill of the kept
    triangle stretch's own packing: a set of lowest triangle indices, one per
    chart (both fills name a chart so), so a chart grown by both is one."""
    grown = set()
    for part in (report.get("repack") or {}, report.get("triangle_stretch") or {}):
        fill = part.get("fill") or {}
        if part.get("used") and fill.get("used", True):
            grown.update(fill.get("grown_chart_triangles", ()))
    return grown


@dataclass
class Outcome:
    objects: list
    reports: dict = field(default_factory=dict)  # atlas group name -> refine_uvs report (+ check_layout)
    images: dict = field(default_factory=dict)  # atlas group name -> {pass: image name}
    atlases: dict = field(default_factory=dict)  # atlas group name -> its object names (one image per pass each)
    image_files: dict = field(default_factory=dict)  # image name -> file path ('' when packed)
    timings: dict = field(default_factory=dict)  # stage -> seconds
    warnings: list = field(default_factory=list)  # things the user should know, though the run succeeded
    tessellation: dict = field(default_factory=dict)  # object name -> lmrefine.tessellate report
    stages: dict = field(default_factory=dict)  # atlas group name -> {"stages": [...], "stopped": why}
    stages_asked: int = 1
    effects: dict = field(default_factory=dict)  # Layouts: Per Effect: group -> effect -> resolution, image, report

    def summary(self):
        reports = list(self.reports.values())
        # Measured on the refined layouts (refine_uvs's report); objects that did not move count as 1x.
        widening = float(np.mean([r["transition_widening"] for r in reports]))
        # Texels across the light changes there (a stretch raises it while it keeps the area).
        across = [r["transition_widening_across"] for r in reports if r.get("transition_widening_across") is not None]
        low = min(r["density_min"] for r in reports)
        high = max(r["density_max"] for r in reports)
        moved = sum(len(self.atlases.get(name, [name])) for name, report in self.reports.items()
                    if report.get("moved", True))  # objects, counted by their atlas group's map
        limits = set()
        for report in reports:
            limited_by = report.get("limited_by") or []
            limits.update([limited_by] if isinstance(limited_by, str) else limited_by)
        kept = [len([s for s in entry["stages"] if s["kept"]]) for entry in self.stages.values()]
        # Charts the output layouts stretched across their light changes (refine_uvs' chart stretch).
        stretches = [(report.get("repack") or {}).get("stretch") or {} for report in reports]
        stretches = [s for s in stretches if s.get("used")]
        # Triangles the output layouts stretched (refine_uvs' triangle stretch).
        triangles = [report.get("triangle_stretch") or {} for report in reports]
        triangles = [t for t in triangles if t.get("used")]
        # Charts grown into the space a packing left: by the kept repack's fill or the fill of the kept
        # triangle stretch's own packing, each chart once (named by its lowest triangle in both).
        grown = sum(len(grown_charts(report)) for report in reports)
        return {
            "moved": moved,
            "transition_widening": widening,
            "transition_widening_across": float(np.mean(across)) if across else None,
            "density_min": float(low),
            "density_max": float(high),
            "limited_by": ", ".join(sorted(limits)),
            "vertices_added": sum(report["vertices_added"] for report in self.tessellation.values()),
            "stages_kept": max(kept, default=1),
            "stretched_charts": sum(int(s["charts_stretched"]) for s in stretches),
            "largest_stretch": max((float(s["largest_stretch"]) for s in stretches), default=1.0),
            "stretched_triangles": sum(int(t["triangles_stretched"]) for t in triangles),
            "grown_charts": grown,
            "objects": len(self.objects),
            "images_per_pass": len(self.images),
            "shared_images": {name: objects for name, objects in self.atlases.items() if len(objects) > 1},
            "effects": self.effects_summary(),
        }

    def effects_summary(self):
        """Layouts: Per Effect: {effect: its resolution and its figures over the maps} ({} otherwise),
        measured on each effect's own refined layout."""
        by_effect = {}
        for entries in self.effects.values():
            for name, entry in entries.items():
                by_effect.setdefault(name, []).append(entry)
        return {name: {"resolution": entries[0]["resolution"],
                       "transition_widening": float(np.mean([e["report"]["transition_widening"] for e in entries])),
                       "density_min": float(min(e["report"]["density_min"] for e in entries)),
                       "density_max": float(max(e["report"]["density_max"] for e in entries)),
                       "images": [e["image"] for e in entries]}
                for name, entries in by_effect.items()}

    def atlas_of(self, obj_name):
        """The name of the atlas group (and of its images) that `obj_name` belongs to."""
        return next(name for name, objects in self.atlases.items() if obj_name in objects)


def settings_snapshot(settings):
    """The settings as plain values: a running job must not see later UI edits."""
    return {
        "source_layer": settings.source_layer.strip(),
        "resolution": settings.resolution,
        "padding": settings.padding,
        "first_lightmap": settings.first_lightmap,
        "lightmap_image": settings.lightmap_image,
        "driving_pass": settings.driving_pass.lower(),
        "refine_options": {
            "strength": settings.strength,
            "max_magnification": settings.max_magnification,
            "min_shrink": settings.min_shrink,
            "max_stretch": settings.max_stretch,
            "triangle_stretch": settings.triangle_stretch,
            "delta": settings.delta,
            "passes": settings.passes,
            "border": settings.border.lower(),
            "directional": settings.directional,
            "wavelet": settings.wavelet.lower(),
            "rechart": settings.rechart,
        },
        "backend": settings.backend,
        "bake_passes": [name.lower() for name in ("DIRECT", "INDIRECT", "COMBINED", "AO")
                        if name in settings.bake_passes],
        "samples": settings.samples,
        "preview": settings.preview,
        "exr_float32": settings.exr_float32,
        "shared_atlas": settings.shared_atlas,
        "tessellate": settings.tessellate_budget if settings.tessellate else None,
        "tessellate_budget": settings.tessellate_budget,
        "stages": settings.stages,
        "per_effect": settings.per_effect_rule.lower() if settings.layouts == 'PER_EFFECT' else None,
    }


def import_core():
    """lmrefine, or a UserError that says how to get it."""
    try:
        import lmrefine
    except ImportError as error:
        raise UserError(f"lmrefine's native core could not be loaded ({error}); reinstall the add-on from "
                        "the lmrefine_blender.zip built for this Blender") from error
    return lmrefine


# --------------------------------------------------------------- validation

def validate(context, objects, options):
    """Targets for `objects`, or a UserError naming the first problem and its fix."""
    import_core()  # the layout rules below are lmrefine's
    if context.mode != 'OBJECT':
        mode = context.mode.replace("_", " ").title()
        raise UserError(f"Refine Lightmap UVs works in Object Mode, not {mode}: switch to Object Mode (Tab, or "
                        "the mode menu of the 3D View), then run again")
    meshes = [obj for obj in objects if obj.type == 'MESH']
    if not meshes:
        raise UserError("No mesh selected: select the mesh objects whose lightmap UVs to refine")
    if not options["bake_passes"]:
        raise UserError("No bake pass chosen: enable at least one of Direct, Indirect, Combined, AO")
    resolution = options["resolution"]
    owners = {}
    targets = Targets()
    # Both bakes see the evaluated meshes. A script that set UVs or positions with foreach_set and no
    # update() leaves them stale, and the bake would use other UVs than the ones refined.
    for obj in meshes:
        if obj.data.library is None:
            obj.data.update()
    depsgraph = context.evaluated_depsgraph_get()
    # Bad geometry in one object skips it (reported, with its fix); the
    # others are refined. Only when every object is skipped does the run stop.
    for obj in meshes:
        try:
            targets.append(_validate_object(obj, options, owners, resolution, depsgraph))
        except UserError as error:
            targets.skipped.append(str(error))
    if not targets:
        raise UserError(one_per_line(targets.skipped))
    return targets


def one_per_line(messages):
    """Several refusals as one message: one a line, each a sentence of its own (Blender's report popup and
    its Info log show each line as a row of its own); a single one as it is."""
    if len(messages) == 1:
        return messages[0]
    return "\n".join(text if text.endswith(".") else text + "." for text in messages)


class Targets(list):
    """The objects to refine, plus why the others were skipped (one message each)."""

    def __init__(self):
        super().__init__()
        self.skipped = []


def _validate_object(obj, options, owners, resolution, depsgraph):
    """The Target for one mesh object, or a UserError naming its problem and fix."""
    mesh = obj.data
    if obj.library is not None or mesh.library is not None:
        library = (obj.library or mesh.library).filepath
        raise UserError(f"'{obj.name}' is linked from {library}: make it local (Object > Relations > "
                        "Make Local > Selected Objects and Data) to change its UV maps")
    if not obj.visible_get():
        raise UserError(f"'{obj.name}' is hidden: show it (Object > Show/Hide, or its collection), since "
                        "both bakers only see visible objects")
    if mesh.name in owners:
        raise UserError(f"'{owners[mesh.name]}' and '{obj.name}' share mesh '{mesh.name}': UV maps belong "
                        f"to the mesh, so only '{owners[mesh.name]}' is refined; to give each its own lightmap, "
                        "make the mesh single-user (Object > Relations > Make Single User > Object & Data)")
    owners[mesh.name] = obj.name
    if len(mesh.uv_layers) == 0:
        raise UserError(f"'{obj.name}' has no UV map: add one for the lightmap (Object Data > UV Maps > +, "
                        "then UV > Lightmap Pack)")
    source = options["source_layer"] or bridge.default_source_layer(mesh)
    if source is None:
        raise UserError(f"'{obj.name}' has only refined UV maps: "
                        + setting("set Source (top of the panel) to the one to refine",
                                  "pass the one to refine with --source-layer"))
    if source not in mesh.uv_layers:
        available = ", ".join(layer.name for layer in mesh.uv_layers)
        raise UserError(f"'{obj.name}' has no UV map '{source}' (it has: {available}): "
                        + setting("pick the lightmap UV map as Source (top of the panel)",
                                  "pass the lightmap UV map with --source-layer"))
    refined = source + REFINED_SUFFIX
    if refined not in mesh.uv_layers and len(mesh.uv_layers) >= 8:
        raise UserError(f"'{obj.name}' already has 8 UV maps, Blender's limit: remove one to make room "
                        f"for '{refined}'")
    layout = bridge.read_layout(mesh, source, obj.matrix_world)
    if len(layout.triangles) == 0:
        raise UserError(bridge.faceless_problem(obj, obj.evaluated_get(depsgraph)))
    not_finite = int(np.count_nonzero(~np.isfinite(layout.uvs).all(axis=1)))
    if not_finite:
        raise UserError(f"UV map '{source}' of '{obj.name}' has {not_finite} UVs that are NaN or Inf: re-unwrap it "
                        "(UV > Lightmap Pack)")
    outside = int(np.count_nonzero(((layout.uvs < 0.0) | (layout.uvs > 1.0)).any(axis=1)))
    if outside:
        # Tiling UVs are a texture map's: repacking it would break the textures, so a map of its own comes first.
        raise UserError(f"UV map '{source}' of '{obj.name}' has {outside} UVs outside [0, 1], so it looks like a "
                        "texture map (tiling), not a lightmap layout, which must lie inside the unit square: add a "
                        "UV map for the lightmap (Object Data > UV Maps > +, then UV > Lightmap Pack) and pick it "
                        "as Source, or repack this one if it is the lightmap's (UV > Pack Islands)")
    zero_3d, zero_uv, bad_vertices = bridge.geometry_problems(obj, layout, resolution)
    if bad_vertices:
        raise UserError(f"'{obj.name}' has {bad_vertices} vertices at NaN, Inf or beyond 1e9 units in world "
                        "space: fix or delete them (Edit Mode > Select > Select All by Trait), or check the "
                        "object's transform, then run again")
    if zero_3d == len(layout.triangles):
        raise UserError(f"'{obj.name}' has no area in 3-D (zero scale, or only degenerate faces): give it a "
                        "non-zero scale or real faces")
    if zero_uv:
        raise UserError(f"'{obj.name}' has {zero_uv} triangles of zero area in UV map '{source}': "
                        "re-unwrap it (UV > Lightmap Pack) so every face has its own texels")
    corners = layout.uvs[layout.triangles].astype(np.float64)
    covered = 0.5 * np.abs(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])).sum()
    if covered > 1.0 + 1e-6:
        # More UV area than the unit square holds: faces lie on top of each other (UV > Reset, a
        # texture map). No refinement or bake can give them texels of their own.
        raise UserError(f"UV map '{source}' of '{obj.name}' has faces stacked on each other (together they "
                        f"cover {covered:.1f} times the unit square), so it looks like a texture map, not a "
                        "lightmap layout: add a UV map for the lightmap (Object Data > UV Maps > +, then UV > "
                        "Lightmap Pack) and pick it as Source")
    problem = bridge.evaluated_problem(depsgraph, obj, source, layout, resolution)
    if problem:
        raise UserError(problem)
    target = Target(obj, source, refined, layout, zero_area=zero_3d)
    if options.get("tessellate") is not None:
        target.unsplit = tessellation.problem(obj)
    if options["first_lightmap"] == 'IMAGE':
        target.image = _first_image(obj, source, options)
    return target


def _first_image(obj, source, options):
    image = options["lightmap_image"] or materials.find_lightmap_image(obj, source)
    if image is None:
        raise UserError(f"No lightmap image found for '{obj.name}': give its material an Image Texture node "
                        f"fed by a UV Map node set to '{source}', pick the image in the panel, or set First Map "
                        "to Embree or Cycles")
    if image.get("lmrefine_object") is not None and image.get("lmrefine_pass") != "before":
        raise UserError(f"'{image.name}' was baked with a refined UV map, not with '{source}': pick a lightmap "
                        "baked with the source map, or set First Map to Embree or Cycles")
    problem = materials.image_problem(image)
    if problem:
        raise UserError(problem)
    resolution = options["resolution"]
    if tuple(image.size) != (resolution, resolution):
        width, height = image.size
        raise UserError(f"Lightmap '{image.name}' is {width}x{height} but Resolution is {resolution}: set "
                        f"Resolution to {width} (the layout is refined at the lightmap's own resolution)")
    return image


# ---------------------------------------------------------------------- run

def run(context, targets, options, journal, image_dir=None):
    """The job (a generator; see the module doc). Returns an Outcome.

    Targets that share one atlas (atlas.group_targets) are refined and baked
    as one map: one refinement of their joined layout, one image per pass.
    Every scene change registers its revert in `journal`; the driver rolls
    back on any exception. `image_dir`: where to write the EXR lightmaps
    (default: next to the .blend, or packed into it when it was never saved).
    """
    if options.get("per_effect"):  # Layouts: Per Effect, its own job
        return (yield from effects.run(context, targets, options, journal, image_dir))
    lmrefine = import_core()
    outcome = new_outcome(targets, options)
    resolution = options["resolution"]
    padding = options["padding"]
    backend_first = options["first_lightmap"]
    groups = atlas.group_targets(list(targets), resolution, options.get("shared_atlas", True))
    for group in groups:
        group.join()
    group_of = {target.obj.name: group for group in groups for target in group.targets}
    # Progress in units of one map's work (a map = an atlas group): every bake one unit per map, every
    # refinement one, the tessellation one per object.
    maps = len(groups)
    further = options.get("stages", 1) - 1  # each: a bake of all targets and a refinement of each map
    span = 1.0 / ((0 if backend_first == 'IMAGE' else maps) + maps + maps + further * 2 * maps
                  + (len(targets) if options.get("tessellate") is not None else 0))
    done = 0

    # 1. The first lightmap, on the source layout: one per atlas group.
    clock = time.perf_counter()
    if backend_first == 'IMAGE':
        lightmaps = {}
        for group in groups:
            images = {target.image.name: target.image for target in group.targets}
            if len(images) == 1:  # the members' material shows one atlas image: it is the group's map
                lightmaps[group.name] = bridge.image_to_array(next(iter(images.values())))
            else:
                lightmaps[group.name] = group.merge([bridge.image_to_array(t.image) for t in group.targets],
                                                    resolution, BAKE_MARGIN)
    else:
        source_of = {t.obj.name: t.source for t in targets}
        passes = (options["driving_pass"],)
        if backend_first == 'EMBREE':
            baked = yield from _bake_embree(context, lmrefine, targets, source_of, passes, options, "First bake",
                                            done * span, maps * span, outcome.warnings)
        else:
            baked = yield from _bake_cycles(context, targets, source_of, passes, options, "First bake",
                                            done * span, maps * span)
        lightmaps = _group_maps(groups, baked[options["driving_pass"]], resolution)
        done += maps
        outcome.timings["first bake"] = time.perf_counter() - clock

    for group in groups:
        _black_warnings(group, lightmaps[group.name], resolution, outcome.warnings)
        _noise_warning(lmrefine, group.label(), group, lightmaps[group.name], options, outcome.warnings)

    # 1b. Opt-in: split the triangles that strong transitions of the first lightmap cross, in the mesh.
    refine_options = {group.name: options["refine_options"] for group in groups}
    if options.get("tessellate") is not None:
        clock = time.perf_counter()
        for group in groups:  # from the layouts before the split: a one-face-per-chart map keeps its route
            refine_options[group.name] = lmrefine.tessellated_refine_options(options["refine_options"],
                                                                             group.uvs, group.triangles)
        unsplit = [(target.obj.name, target.unsplit) for target in targets if target.unsplit]
        outcome.warnings.extend(tessellation.unsplit_warnings(unsplit))
        for target in targets:
            if target.unsplit:  # a split would change more than this object: it is refined as it is
                outcome.tessellation[target.obj.name] = {"vertices_added": 0, "not_split": target.unsplit[0]}
            else:
                yield from _tessellate(lmrefine, target, lightmaps[group_of[target.obj.name].name],
                                       options["tessellate"], journal, outcome, done * span, span)
            done += 1
        for group in groups:
            group.join()  # the tessellated meshes' layouts (the same charts, more triangles)
        outcome.timings["tessellate"] = time.perf_counter() - clock

    # 2. Refine every map's layout (native, off the main thread), check it, write it.
    clock = time.perf_counter()
    refined_uvs = {}  # group name -> the joined refined UVs
    light_changes = {}  # group name -> where its first refinement found the light changes
    for group in list(groups):
        name, label = group.name, group.label()
        try:
            result = yield NativeWork(
                f"Refining {name}",
                lambda progress, lightmap=lightmaps[name], group=group: lmrefine.refine_uvs(
                    lightmap, group.uvs, group.triangles, resolution, padding=padding, progress=progress,
                    positions=group.positions, normals=group.normals, **refine_options[group.name]),
                done * span, span, parts=refine_parts(group, options, refine_options[name]))
        except (ValueError, TypeError, MemoryError) as error:
            # The core refused this map's input: skip its objects, refine the others
            # (nothing of them was written yet).
            outcome.warnings.append(f"Skipped: {label} could not be refined: {error_text(error)}")
            groups.remove(group)
            for obj_name in group.objects:
                outcome.objects.remove(obj_name)
            done += 1
            continue
        done += 1
        joined = bridge.Layout(group.uvs, group.triangles)
        check, source_check = _check_refined(lmrefine, label, result.uvs, joined, group.uvs, resolution, padding)
        warning = source_warning(label, group, source_check, padding, resolution, check)
        if warning is not None:
            outcome.warnings.append(warning)
        black = f"{label}: the first lightmap is black"  # already said, with its advice
        if not result.report["moved"] and not any(w.startswith(black) for w in outcome.warnings):
            why = next((n for n in result.report["notes"] if n.startswith("nothing moved")), "nothing moved")
            outcome.warnings.append(f"{label}: {why}")
        # Strength 0 moves nothing whatever the triangles, nor does a layout held for its light steps on
        # texel boundaries: the nothing-moved warning says why, Tessellate is no fix.
        # A texture map's layout got its warning: Tessellate is no fix. A few overlapping faces are no
        # reason to keep quiet about the triangles a split would serve.
        if (options.get("tessellate") is None and options["refine_options"]["strength"] > 0
                and not texture_like(source_check, len(group.triangles))
                and "aligned_steps" not in result.report["limited_by"]
                and lmrefine.tessellation.coarse_refinement(result.report)):
            _coarse_warning(lmrefine, label, lightmaps[name], group, result.report, outcome,
                            options.get("tessellate_budget", 0.25))
        report = {key: value for key, value in result.report.items() if key != "triangle_density"}
        report["check_layout"] = dict(check)
        report["source_check_layout"] = dict(source_check)
        outcome.reports[name] = _plain(report)
        refined_uvs[name] = result.uvs
        light_changes[name] = result.light_changes
    if not groups:
        raise UserError(one_per_line([w for w in outcome.warnings if w.startswith("Skipped: ")]))
    outcome.atlases = {group.name: group.objects for group in groups}
    for group in groups:
        _write_group_layers(group, refined_uvs[group.name], journal)
    outcome.timings["refine"] = time.perf_counter() - clock

    # 2b. Opt-in: further stages, each refining from a bake with the previous stage's layout.
    if further:
        clock = time.perf_counter()
        done = yield from _further_stages(context, lmrefine, groups, refined_uvs, options, journal, outcome,
                                          done, span)
        for group in groups:
            name = group.name
            if sum(entry["kept"] for entry in outcome.stages[name]["stages"]) > 1:
                # The figures of the layout the user gets, against the source map, at the first bake's edges.
                figures = lmrefine.refine.layout_figures(lightmaps[name], group.uvs, refined_uvs[name],
                                                         group.triangles,
                                                         wavelet=options["refine_options"]["wavelet"],
                                                         light_changes=light_changes[name])
                figures.pop("triangle_density")
                outcome.reports[name].update(_plain(figures))
            outcome.reports[name]["stages"] = _plain(outcome.stages[name])
        outcome.timings["stages"] = time.perf_counter() - clock

    # 3. The second bake with the refined layout, one image per map and pass.
    clock = time.perf_counter()
    targets = [target for group in groups for target in group.targets]
    refined_of = {t.obj.name: t.refined for t in targets}
    modifier_warnings(context, targets, refined_of, resolution, outcome.warnings)
    passes = tuple(options["bake_passes"])
    if options["backend"] == 'EMBREE':
        baked = yield from _bake_embree(context, lmrefine, targets, refined_of, passes, options, "Second bake",
                                        done * span, 1.0 - done * span, outcome.warnings)
    else:
        baked = yield from _bake_cycles(context, targets, refined_of, passes, options, "Second bake",
                                        done * span, 1.0 - done * span)
    for pass_name in passes:
        merged = _group_maps(groups, baked[pass_name], resolution, refined_uvs)
        for group in groups:
            image = _store_image(group, pass_name, merged[group.name], journal)
            outcome.images.setdefault(group.name, {})[pass_name] = image.name
    outcome.timings["second bake"] = time.perf_counter() - clock

    # 4. Preview in the materials, then write the images (the one step a rollback cannot undo, so last).
    if options["preview"]:
        # Before and after show the same light: the driving pass when it was baked again, else the first pass.
        shown_pass = options["driving_pass"] if options["driving_pass"] in passes else passes[0]
        for group in groups:
            image = bpy.data.images[outcome.images[group.name][shown_pass]]
            stored_before = None
            for target in group.targets:
                if target.image is not None:  # the user's own first lightmap is the "before"
                    before = target.image
                else:
                    if stored_before is None:
                        stored_before = _store_image(group, "before", lightmaps[group.name], journal)
                        outcome.images[group.name]["before"] = stored_before.name
                    before = stored_before
                materials.add_preview(target.obj, image, target.refined, before, target.source, journal)
    for names in outcome.images.values():
        for image_name in names.values():
            image = bpy.data.images[image_name]
            outcome.image_files[image_name] = _save_image(lmrefine, image, image_dir,
                                                          "float" if options["exr_float32"] else "half")
    return outcome


def modifier_warnings(context, targets, uv_name_of, resolution, warnings):
    """A warning for each target whose modifiers fold its UV map `uv_name_of[name]` where the bake reads
    it (bridge.modifier_folds_problem), once per object."""
    depsgraph = context.evaluated_depsgraph_get()
    for target in targets:
        problem = bridge.modifier_folds_problem(depsgraph, target.obj, uv_name_of[target.obj.name], resolution)
        if problem is not None and not any(
                w.startswith(f"'{target.obj.name}': its ") and "where the bake reads" in w for w in warnings):
            warnings.append(problem)


def _noise_warning(lmrefine, label, group, lightmap, options, warnings):
    """A warning (naming `label`) when the first `lightmap` of `group` is noisy (lmrefine.metrics.noise_level above
    NOISY_FIRST_MAP): the refiner takes noise for light changes and spreads texels over it. Noise falls
    as 1/sqrt(samples), so a baked map's warning gives the Samples that bring it under the bound."""
    from lmrefine.metrics import NOISY_FIRST_MAP, noise_level
    mask = lmrefine.coverage_mask(group.uvs, group.triangles, lightmap.shape[:2]).astype(bool)
    noise = noise_level(lightmap, mask)
    if not noise > NOISY_FIRST_MAP:
        return
    what = (f"the first lightmap is noisy (noise {noise:.1%} of its median light; above "
            f"{NOISY_FIRST_MAP:.0%} the refiner takes much of it for light changes and gives its texels less "
            "of their gain)")
    if options["first_lightmap"] == 'IMAGE':
        fix = "bake that image with more samples or denoise it, or " + setting(
            "set First Map to Embree or Cycles", "pass --first-lightmap embree or cycles")
    else:
        samples = options["samples"]
        needed = 2 ** int(np.ceil(np.log2(samples * (noise / NOISY_FIRST_MAP) ** 2)))
        fix = setting(f"raise Samples to {needed} or more", f"pass --samples {needed} or more")
        if options["first_lightmap"] == 'CYCLES':
            fix += setting(", or set First Map to Embree (its direct light is less noisy per sample)",
                           ", or pass --first-lightmap embree (its direct light is less noisy per sample)")
    warnings.append(f"{label}: {what}: {fix}")


def _black_warnings(group, lightmap, resolution, warnings):
    """Warnings for the objects of `group` whose texels are all black in the first `lightmap`: an
    inside-out mesh is named as the cause (looked for only there: it costs a pass over the mesh), and
    a black map says so, with the fix."""
    lit = lightmap[..., :3] > 0.0
    black = not np.any(lit)
    masks = group.masks(resolution) if len(group.targets) > 1 and not black else [None] * len(group.targets)
    inside_out = []
    for target, mask in zip(group.targets, masks):
        if black or (mask is not None and not np.any(lit[mask])):
            inward, closed = bridge.inside_out_shells(target.obj.data)
            if inward:
                parts, bake = (("it is", "it bakes") if closed == 1
                               else (f"{inward} of its {closed} closed parts are", "they bake"))
                warnings.append(f"'{target.obj.name}': {parts} inside out (the normals point inward), and both "
                                f"bakers light the side a face's normal points to, so {bake} black: recalculate "
                                "its normals (Edit Mode > Mesh > Normals > Recalculate Outside)")
                inside_out.append(inward == closed)
    if black:
        if len(inside_out) == len(group.targets) and all(inside_out):
            cause, fix = "its faces point inward", "recalculate its normals (above)"
        else:
            cause, fix = "no light reaches it", "add lights or a world colour"
        warnings.append(f"{group.label()}: the first lightmap is black ({cause}), so there is nothing to "
                        f"refine for: {fix}")


# A source map is a texture map's layout (mirrored or stacked islands) when more than this share of
# its triangles overlap others; fewer are a lightmap layout with a flaw (Smart UV Project leaves a few
# where an island folds over itself, as on Suzanne).
TEXTURE_OVERLAP_SHARE = 0.01


def texture_like(source_check, triangles):
    """Whether a source map's check_layout report (of a map of `triangles` triangles) reads as a
    texture map's layout: more than TEXTURE_OVERLAP_SHARE of its triangles overlap."""
    return source_check["overlapping"] > TEXTURE_OVERLAP_SHARE * max(int(triangles), 1)


def source_warning(label, group, source_check, padding, resolution, refined_check=None):
    """What the user should know about a group's source map that fails check_layout at `resolution`
    (`source_check`), or None when it passes; `refined_check`, the refined map's check at `padding`,
    says whether what the user gets still has the problem."""
    from lmrefine.layout_input import describe_problems
    if source_check["valid"]:
        return None
    source = "', '".join(sorted({target.source for target in group.targets}))
    if texture_like(source_check, len(group.triangles)):
        # Charts that overlap widely share texels: the layout of a texture, not of a lightmap.
        return (f"{label}: UV map '{source}' looks like a texture map, not a lightmap layout "
                f"({describe_problems(source_check, padding)}): faces share texels, so light bleeds between "
                "them whatever the refinement does; add a UV map for the lightmap (Object Data > UV Maps > +, "
                "then UV > Lightmap Pack) and pick it as Source")
    if source_check["overlapping"] and refined_check is not None and refined_check["valid"]:
        # Re-charted from the mesh: the refined map has faces of its own.
        return (f"{label}: UV map '{source}' has faces that share texels "
                f"({describe_problems(source_check, padding)}); the refined map, re-charted from the mesh, has "
                "none, so only the first lightmap, baked with the source map, may show bleeding")
    if source_check["overlapping"]:
        # A few faces overlap: the refined map keeps them where they were (it never makes a map worse).
        return (f"{label}: UV map '{source}' has faces that share texels "
                f"({describe_problems(source_check, padding)}): light bleeds between them whatever the "
                "refinement does; in the UV Editor, Select > Select Overlap finds them: move them apart, or "
                "unwrap the map again")
    if refined_check is not None and refined_check["valid"]:
        # Repacked or re-charted at the padding: only the source map's own bake (Before) bleeds.
        gutter = refined_check["min_gutter_texels"]
        apart = "one chart" if not np.isfinite(gutter) else f"charts {gutter:.2f} texels apart or more"
        return (f"{label}: UV map '{source}' was invalid at {resolution} texels "
                f"({describe_problems(source_check, padding)}); the refined map is valid ({apart}), so only "
                "the first lightmap, baked with the source map, may show bleeding")
    # Charts closer than the padding: the packer's Margin is what keeps them apart.
    margin = (f" with a larger Margin (in the operator's Adjust Last Operation panel), so that its charts lie "
              f"at least Padding ({padding:g} texels) apart" if source_check["min_gutter_texels"] < padding else "")
    return (f"{label}: UV map '{source}' was already invalid at {resolution} texels "
            f"({describe_problems(source_check, padding)}); the refined map is no worse, but lightmap "
            f"bleeding may show: repack the source map (UV > Lightmap Pack){margin}")


def new_outcome(targets, options):
    """An Outcome for `targets`, with the warnings validation left: skipped objects, zero-area triangles."""
    outcome = Outcome(objects=[t.obj.name for t in targets], stages_asked=options.get("stages", 1))
    outcome.warnings += [f"Skipped: {message}" for message in getattr(targets, "skipped", [])]
    for target in targets:
        if target.zero_area:
            outcome.warnings.append(f"'{target.obj.name}': {target.zero_area} triangles of zero area in 3-D "
                                    "were skipped (they need no texels); Mesh > Clean Up > Degenerate "
                                    "Dissolve removes them")
    return outcome


def _group_maps(groups, per_object, resolution, joined_uvs=None):
    """{group name: its one map} from each object's own bake: the members' maps merged by their
    rasterized coverage of the layout they were baked with (`joined_uvs[group name]`, default the
    group's source layout) and the gutter filled from the joined layout's charts (atlas.merge_maps;
    for a group of one, what the Embree baker did already, and what Cycles' margin does otherwise)."""
    maps = {}
    for group in groups:
        members = [per_object[name] for name in group.objects]
        uvs = joined_uvs[group.name] if joined_uvs is not None else None
        maps[group.name] = group.merge(members, resolution, BAKE_MARGIN, uvs)
    return maps


def _write_group_layers(group, joined_uvs, journal):
    """Each object's rows of the group's refined layout into its `<source>_refined` UV map."""
    own = group.split(joined_uvs)
    for target in group.targets:
        _write_refined_layer(target, own[target.obj.name], journal)


def _check_refined(lmrefine, label, uvs, layout, reference_uvs, resolution, padding):
    """An independent check of the promise refine_uvs makes: never worse than the layout it started
    from (the joined layout of an atlas group, `label` naming it). Returns (check of `uvs`, check of
    `reference_uvs`); a worse layout is a bug, raised."""
    from lmrefine.backoff import without_chart_lists, worse_than_source
    # With its chart lists, which worse_than_source's overlap rule reads (without them it checks the map again).
    reference_check = lmrefine.check_layout(reference_uvs, layout.triangles, resolution, padding=padding,
                                            failing_charts=True)
    worse, check = worse_than_source(uvs, reference_uvs, layout.triangles, resolution, padding,
                                     source=reference_check)
    without_chart_lists(reference_check)
    if worse:
        raise RuntimeError(f"refine_uvs returned a layout for {label} that is worse than the one it started from "
                           f"({', '.join(worse)}: {dict(check)}); this is a bug in lmrefine, please report "
                           "it with the .blend")
    return check, reference_check


def _coarse_warning(lmrefine, label, lightmap, group, report, outcome, budget):
    """Edges hardly gained, or the triangles at light changes are large (tessellation.coarse_refinement),
    and light changes that are no mere falloff (tessellation.light_contrast) cross triangles tessellate
    would split: say that tessellation is the fix (a warp moves vertices; inside a triangle the mapping
    stays affine), and the Vertex Budget its split needs to run to its own end (_split_needs)."""
    from lmrefine.tessellation import (COARSE_CONTRAST, COARSE_MIN_TEXELS, TRIAL_BUDGET, budget_to_end,
                                       coarse_transitions, light_contrast)
    # The map's transition strength: each object's share below is counted with it too, so the shares
    # are parts of this count (an object's own strength is scaled to its own strongest light change).
    strength = lmrefine.transition_strength_of(lightmap, group.uvs, group.triangles)
    coarse = coarse_transitions(lightmap, group.uvs, group.triangles, strength=strength)
    # Nearly flat light (a point light's falloff, bake noise) has a top decile too: no reason to split.
    hard = light_contrast(lightmap, lmrefine.coverage_mask(group.uvs, group.triangles, lightmap.shape[:2]))
    if not (coarse["triangles"] and hard >= COARSE_CONTRAST):
        return
    needs = _split_needs(lmrefine, lightmap, group, strength)
    if needs is not None and not any(added for _, added, _, _ in needs):
        return  # the split would add nothing (its thresholds are its own): Tessellate is no fix here
    raise_budget = where = ""
    if needs is not None and len(needs) > 1:
        # The budget below names the object whose split needs the most per vertex, which need not be the one
        # holding most of these triangles (a one-quad floor beside cubes): name that one too.
        holder, _, _, held = max(needs, key=lambda need: need[3])
        if held:
            where = f", {held} of them on '{holder}'"
    if needs is None:
        # Too large to try the split here. The default budget is a fraction of the vertices: on a mesh of
        # few it adds next to nothing.
        vertices = sum(len(target.obj.data.vertices) for target in group.targets)
        allowed = sum(int(budget * len(target.obj.data.vertices)) for target in group.targets)
        if allowed < coarse["triangles"]:
            raise_budget = (f" with a Vertex Budget well above {budget:g} (at {budget:g} it adds at most {allowed} "
                            f"to its {vertices} vertices)")
    else:
        name, added, vertices, _ = max(needs, key=lambda need: need[1] / max(need[2], 1))
        needed = budget_to_end(added, vertices)
        if needed >= TRIAL_BUDGET:
            raise_budget = (f" with a Vertex Budget of {TRIAL_BUDGET:g} or more ('{name}' takes +{added} "
                            f"to its {vertices} vertices and still has triangles to split)")
        elif needed > budget:
            raise_budget = (f" with a Vertex Budget of {needed:g} or more (the split of '{name}' "
                            f"ends by itself at +{added} to its {vertices} vertices; at {budget:g} it stops short)")
    outcome.warnings.append(
        f"{label}: light changes cross {coarse['triangles']} triangle(s) of more than "
        f"{COARSE_MIN_TEXELS:g} texels{where}, and moving UVs cannot put more texels inside a triangle "
        f"(edges {report['transition_widening']:.2f}x; those triangles cover "
        f"{coarse['texels'] / coarse['triangles']:.0f} texels each on average): turn on Tessellate (Stages and "
        "Tessellation)"
        f"{raise_budget} to split them in the mesh, as one undo step")


# The largest map whose split _coarse_warning tries, to tell the Vertex Budget it needs: triangles summed
# over its objects (a plane of 20,000 or 100,000 triangles under a shadow edge at 1024^2: about a second),
# and objects (each reads the whole lightmap's gradient map first, as Tessellate's split does).
SPLIT_TRIAL_TRIANGLES = 100_000
SPLIT_TRIAL_OBJECTS = 16


def _split_needs(lmrefine, lightmap, group, strength):
    """[(object name, vertices its split adds when it runs to its own end, its vertices, its triangles
    that _coarse_warning counts)] for the objects of `group`, from a trial of the split Tessellate makes
    (_tessellate's, at a budget of lmrefine.tessellation.TRIAL_BUDGET; nothing is written; a split that
    needs more counts as needing that budget), or None for a map too large to try
    (SPLIT_TRIAL_TRIANGLES, SPLIT_TRIAL_OBJECTS). The triangles are counted with `strength`, the
    group's map's (transition_strength_of of its joined layout), as _coarse_warning counts them."""
    from lmrefine.tessellation import TRIAL_BUDGET, coarse_transitions
    if (len(group.targets) > SPLIT_TRIAL_OBJECTS
            or sum(len(target.layout.triangles) for target in group.targets) > SPLIT_TRIAL_TRIANGLES):
        return None
    needs = []
    for target in group.targets:
        positions, triangles, corner_uvs = tessellation.mesh_arrays(target.obj.data, target.layout)
        own = lmrefine.transition_strength_of(lightmap, target.layout.uvs, target.layout.triangles)
        trial = lmrefine.tessellate(positions, triangles, corner_uvs, own, budget=TRIAL_BUDGET)
        counted = coarse_transitions(lightmap, target.layout.uvs, target.layout.triangles, strength=strength)
        needs.append((target.obj.name, int(trial.report["vertices_added"]), len(positions), counted["triangles"]))
    return needs


def _tessellate(lmrefine, target, lightmap, budget, journal, outcome, start, span):
    """Split the triangles of `target` that the transitions of `lightmap` (baked on its source map)
    cross, in its mesh (journalled); its layout becomes the tessellated mesh's."""
    obj = target.obj
    layout = target.layout
    from lmrefine.alignment import layout_held
    mask = lmrefine.coverage_mask(layout.uvs, layout.triangles, lightmap.shape[:2])
    aligned, held = layout_held(lightmap, layout.uvs, layout.triangles, mask)
    if held:
        # Its refinement will leave the layout as it is (refine_uvs' aligned_steps): splitting would gain nothing.
        outcome.tessellation[obj.name] = {"vertices_added": 0, "aligned_steps": aligned}
        outcome.warnings.append(
            f"'{obj.name}': not tessellated: {aligned:.0%} of its first lightmap's light steps lie on texel "
            "boundaries its map's edges run along, so its layout stays as it is and a split would gain nothing")
        return
    positions, triangles, corner_uvs = tessellation.mesh_arrays(obj.data, layout)

    def split(progress):
        strength = lmrefine.transition_strength_of(lightmap, layout.uvs, layout.triangles)
        return lmrefine.tessellate(positions, triangles, corner_uvs, strength, budget=budget, progress=progress)

    result = yield NativeWork(f"Tessellating {obj.name}", split, start, span)
    added = tessellation.write(obj, result, journal)
    report = _plain(result.report)
    report["vertices_added"] = added
    outcome.tessellation[obj.name] = report
    if report["stopped"] == "the vertex budget is spent" and report["candidates_left"]:
        # Triangles the split would still halve down to a texel are no reason to warn; ones a warp cannot
        # serve are (the coarse advice's rule; the split keeps the lightmap's mapping, so its map holds).
        from lmrefine.tessellation import COARSE_MIN_TEXELS, coarse_transitions
        coarse = coarse_transitions(lightmap, result.uvs, np.arange(len(result.uvs)).reshape(-1, 3))
        report["coarse_left"] = coarse["triangles"]
        if coarse["triangles"]:
            outcome.warnings.append(
                f"'{obj.name}': Tessellate spent its Vertex Budget ({budget:g}x its "
                f"{report['vertices_before']} vertices: {added} added) with {coarse['triangles']} triangle(s) "
                f"of more than {COARSE_MIN_TEXELS:g} texels still crossed by light changes: raise Vertex Budget "
                "(Stages and Tessellation; a mesh of few vertices needs many times its count)")
    if added:
        target.layout = bridge.read_layout(obj.data, target.source, obj.matrix_world)


def _further_stages(context, lmrefine, groups, refined_uvs, options, journal, outcome, done, span):
    """Stages 2..options["stages"]: bake the driving pass with each map's refined layout, refine that
    layout from it, write it. A map stops at the first stage that moves its layout by less than
    lmrefine.metrics.STAGE_MIN_CHANGE, backs off below STAGE_MIN_BACKOFF or gives its light changes no
    more texels (the rule of `evaluate --stages`, metrics.stage_stop_reason); its last kept layout stays.
    Updates `refined_uvs` (group name -> joined UVs) and outcome.stages; returns the progress steps done."""
    from lmrefine import metrics
    resolution, padding = options["resolution"], options["padding"]
    driving = options["driving_pass"]
    further = {}  # group name -> its refine options for stages 2, 3, ... (the rule of `evaluate --stages`)
    for group in groups:
        first = outcome.reports[group.name]
        further[group.name] = {**options["refine_options"], **metrics.further_stage_options(first)}
        outcome.stages[group.name] = {
            "stages": [{**metrics.stage_entry(1, first), "kept": True}],
            "stopped": f"{options['stages']} stages done",
            "repack": bool(further[group.name].get("repack", True))}
    active = list(groups)
    # Progress: each stage one unit per map for its bake and one per refinement, as run() counts them.
    end = done + (options["stages"] - 1) * 2 * len(groups)
    for stage in range(2, options["stages"] + 1):
        if not active:
            break
        targets = [target for group in active for target in group.targets]
        refined_of = {t.obj.name: t.refined for t in targets}
        label = f"Stage {stage} bake"
        if options["backend"] == 'EMBREE':
            baked = yield from _bake_embree(context, lmrefine, targets, refined_of, (driving,), options, label,
                                            done * span, len(active) * span, outcome.warnings)
        else:
            baked = yield from _bake_cycles(context, targets, refined_of, (driving,), options, label, done * span,
                                            len(active) * span)
        done += len(active)
        lightmaps = _group_maps(active, baked[driving], resolution, refined_uvs)
        for group in list(active):
            name = group.name
            previous = refined_uvs[name]
            result = yield NativeWork(
                f"Stage {stage}: refining {name}",
                lambda progress, lightmap=lightmaps[name], previous=previous, group=group:
                    lmrefine.refine_uvs(lightmap, previous, group.triangles, resolution, padding=padding,
                                        progress=progress, **further[group.name]),
                done * span, span, parts=REFINE_STAGES)
            done += 1
            change = metrics.layout_change(previous, result.uvs, group.triangles)
            entry = metrics.stage_entry(stage, result.report, change)
            history = outcome.stages[name]
            reason = metrics.stage_stop_reason(stage, entry["moved"], change, entry["backoff"], entry["widening"])
            history["stages"].append({**entry, "kept": reason is None})
            if reason is not None:
                history["stopped"] = reason
                active.remove(group)
                continue
            _check_refined(lmrefine, group.label(), result.uvs, bridge.Layout(group.uvs, group.triangles),
                           previous, resolution, padding)
            refined_uvs[name] = result.uvs
            outcome.reports[name]["repack"] = _plain(result.report["repack"])  # the kept stage's packing
            _write_group_layers(group, result.uvs, journal)
    # Maps that stopped early left their share of the progress undone: catch up.
    return end


def _plain(value):
    """numpy scalars/arrays -> JSON-able Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _bake_embree(context, lmrefine, targets, uv_name_of, passes, options, label, start, span, warnings):
    """Bake `passes` with lmrefine's baker; returns {pass: {object name: (R, R, 4) float32}}.
    Occluders left out of the bake are named in `warnings` (once)."""
    left_out = []
    with materials.previews_hidden(context.scene.objects):  # the materials as the user made them
        receivers, occluders = bridge.export_scene(context, [t.obj for t in targets], uv_name_of, left_out)
    for name in left_out:
        warning = (f"'{name}' casts no shadow in the bake: it has vertices at NaN, Inf or beyond 1e9 units; "
                   "fix or delete them (Edit Mode > Select > Select All by Trait), or check its transform")
        if warning not in warnings:
            warnings.append(warning)
    scene = lmrefine.Scene()
    ids = {}
    for export in receivers:
        # The baker takes UVs per triangle corner (row 3t + k), the layout's loops in triangle order.
        corner_uvs = export.uvs[export.triangles.ravel()]
        ids[export.name] = scene.add_mesh(export.positions, export.triangles, uvs=corner_uvs,
                                          normals=export.normals, base_color=_base_color(export), receiver=True)
    for export in occluders:
        scene.add_mesh(export.positions, export.triangles, normals=export.normals,
                       base_color=_base_color(export), receiver=False)
    for kind, params in bridge.scene_lights(context):
        scene.add_light(kind, **params)
    scene.set_world(bridge.world_color(context.scene))
    baked = yield NativeWork(
        label,
        lambda progress: lmrefine.bake(scene, options["resolution"], passes=passes, samples=options["samples"],
                                       seed=0, progress=progress, dilation=BAKE_MARGIN),
        start, span, parts=len(ids) * len(set().union(*(TRANSPORTS[name] for name in passes))))
    by_pass = {passes[0]: baked} if len(passes) == 1 else baked
    return {name: {obj: np.asarray(by_pass[name][mesh_id], dtype=np.float32) for obj, mesh_id in ids.items()}
            for name in passes}


def _bake_cycles(context, targets, uv_name_of, passes, options, label, start, span):
    """Bake `passes` with Cycles, object by object; returns {pass: {object name: (R, R, 4) float32}}."""
    baked = {name: {} for name in passes}
    steps = len(passes) * len(targets)
    with cycles_bake.render_settings(context, options["samples"]):
        for index, (name, target) in enumerate((n, t) for n in passes for t in targets):
            obj = target.obj
            yield NativeWork(f"{label}: {name} of {obj.name} (Cycles)", None, start + span * index / steps, 0.0)
            with materials.previews_hidden(context.scene.objects):  # the materials as the user made them
                baked[name][obj.name] = cycles_bake.bake_object(context, obj, uv_name_of[obj.name], name,
                                                                options["resolution"], BAKE_MARGIN)
    return baked


def _base_color(export):
    """One colour when the mesh is uniform (the common case), else one per triangle."""
    colors = export.base_color
    if len(colors) and np.all(colors == colors[0]):
        return tuple(float(c) for c in colors[0])
    return colors


def _write_refined_layer(target, uvs, journal):
    mesh = target.obj.data
    active_index = mesh.uv_layers.active_index
    render_name = next((layer.name for layer in mesh.uv_layers if layer.active_render), None)
    existing = mesh.uv_layers.get(target.refined)
    if existing is not None:
        previous = bridge.read_uv_layer(mesh, target.refined)
        journal.on_rollback(lambda: bridge.write_uv_layer(mesh, target.refined, previous))
    else:
        def remove_layer():
            layer = mesh.uv_layers.get(target.refined)
            if layer is not None:
                mesh.uv_layers.remove(layer)
            mesh.uv_layers.active_index = active_index
            if render_name is not None:
                mesh.uv_layers[render_name].active_render = True
        journal.on_rollback(remove_layer)
    bridge.write_uv_layer(mesh, target.refined, uvs)
    # A new UV map must not steal the active or render slot from the user's maps.
    mesh.uv_layers.active_index = active_index
    if render_name is not None:
        mesh.uv_layers[render_name].active_render = True


def _store_image(group, pass_name, pixels, journal):
    """The lightmap image of an atlas group for `pass_name`, a new one holding `pixels`:
    `<group name>_lightmap_<pass>` (atlas.AtlasGroup.name: the object's name, or "<first>_atlas").

    Alpha is written as 1 everywhere, like Cycles' bake output: Blender stores
    EXR premultiplied, so an alpha-0 gutter would lose its dilated colour on
    the next load and seams would show. Coverage comes from the UV layout.
    The image keeps a fake user so it survives saving even without a material.

    An earlier run's image of that name is left as it was (pixels and file): it
    gives the name and every use (a user's own material's too) to the new one
    and loses its fake user, so it is not saved with the .blend unless Ctrl+Z
    brings it back (Blender's undo does not keep pixels written from Python,
    so writing into it could not be undone).
    """
    pixels = np.array(pixels, dtype=np.float32)  # a copy: never modify the baker's array
    pixels[..., 3] = 1.0
    name = f"{group.name}_lightmap_{pass_name}"
    earlier = bpy.data.images.get(name)
    if earlier is not None and not (earlier.get("lmrefine_object") == group.name and earlier.library is None):
        earlier = None  # not the add-on's: the new image gets Blender's next free name
    if earlier is not None:
        earlier.name = f"{name} (earlier run)"
        earlier.use_fake_user = False
    image = bridge.new_float_image(name, pixels.shape[0])
    image["lmrefine_object"] = group.name
    image["lmrefine_pass"] = pass_name
    image.use_fake_user = True
    if earlier is not None:
        earlier.user_remap(image)

    def remove():
        if earlier is not None:
            image.user_remap(earlier)
        bpy.data.images.remove(image)
        if earlier is not None:
            earlier.name = name
            earlier.use_fake_user = True
    journal.on_rollback(remove)
    image["lmrefine_objects"] = ", ".join(group.objects)  # who shares it (one object, or an atlas group)
    bridge.array_to_image(image, pixels)
    return image


def _save_image(lmrefine, image, image_dir, precision):
    """Write `image` as an EXR (ZIP-compressed, `precision` "half" or "float") into image_dir or next to
    the .blend, and point the image at the file; pack it when the .blend was never saved.

    The file is written by lmrefine (OpenImageIO), so its format is exactly the
    one asked for, and the image is reloaded from it: what Blender shows is what
    was written. Runs last: a file on disk is the one change a rollback cannot take back.
    """
    pixels = bridge.image_to_array(image)
    if image_dir is not None:
        filename = _free_filename(os.path.abspath(image_dir), image)
        path = os.path.join(os.path.abspath(image_dir), filename)
        stored = path
    elif bpy.data.filepath:
        filename = _free_filename(os.path.dirname(bpy.data.filepath), image)
        path = os.path.join(os.path.dirname(bpy.data.filepath), filename)
        stored = "//" + filename
    else:
        filename = bpy.path.clean_name(image.name) + ".exr"
        with tempfile.TemporaryDirectory(prefix="lmrefine") as folder:
            temporary = os.path.join(folder, filename)
            lmrefine.write_image(temporary, pixels, format=precision)
            _load_from(image, temporary)
            image.pack()
        image.filepath_raw = "//" + filename
        return ""
    try:
        lmrefine.write_image(path, pixels, format=precision)
    except OSError as error:
        raise RuntimeError(f"could not write lightmap '{path}': {error}") from error
    _load_from(image, stored)
    return path


def _free_filename(folder, image):
    """`<image name>.exr`, or `<image name>_2.exr`, ... where another image (an earlier run's, which
    Ctrl+Z may bring back) reads that file: its file is never written over."""
    used = {os.path.normpath(bpy.path.abspath(other.filepath_raw)) for other in bpy.data.images
            if other != image and other.source == 'FILE' and other.filepath_raw}
    stem = bpy.path.clean_name(image.name)
    for number in itertools.count(1):
        filename = f"{stem}.exr" if number == 1 else f"{stem}_{number}.exr"
        if os.path.normpath(os.path.join(folder, filename)) not in used:
            return filename


def _load_from(image, filepath):
    image.filepath_raw = filepath
    image.source = 'FILE'
    image.reload()


# ------------------------------------------------------------------ drivers

def run_blocking(job, progress=None, should_stop=None):
    """Drive `job` on this thread (operator execute, batch).

    `progress(fraction, label)` is told the overall progress; `should_stop()`
    returning True cancels the running native call (lmrefine.CancelledError).
    """
    value, error = None, None
    while True:
        try:
            # A failed native call goes back into the job, which may skip the
            # object it was for; whatever the job does not handle comes out here.
            work = job.throw(error) if error is not None else job.send(value)
        except StopIteration as stop:
            return stop.value
        error = None
        if progress is not None:
            progress(work.start, work.label)
        if work.call is None:
            if should_stop is not None and should_stop():
                job.close()
                raise Cancelled()
            value = None
        else:
            callback = _progress_callback(work, progress, should_stop or (lambda: False))
            try:
                value = work.call(callback)
                callback.finish()
            except Exception as failure:  # noqa: BLE001  (handed to the job, re-raised if it does not handle it)
                value, error = None, failure


def _progress_callback(work, report, should_stop):
    """The callable lmrefine's native calls take: progress(fraction, stage) -> False cancels.

    A native call restarts its fraction at every stage (the baker per map and
    transport, refine_uvs per step): each new stage name counts as the next
    of the work's `parts`, so the fraction moves across all of them. It only
    moves forward, and a call with more stages than expected stops at the end
    of its span rather than running past it.
    """
    state = {"stage": None, "done": 0, "furthest": 0.0}

    def shown(stage):
        # The baker counts the meshes it bakes as maps ("baking direct (map 3/5)"); the add-on gives it one
        # mesh per object, and a "map" of the add-on is an atlas group (five objects of one atlas: one map).
        return _BAKER_MAP.sub(r"(object \1)", stage)

    def callback(fraction, stage=""):
        if state["stage"] is not None and stage != state["stage"]:
            state["done"] += 1
        state["stage"] = stage
        within = (state["done"] + min(max(float(fraction), 0.0), 1.0)) / max(work.parts, 1)
        state["furthest"] = max(state["furthest"], min(within, 1.0))
        if report is not None:
            report(work.start + work.span * state["furthest"],
                   f"{work.label} ({shown(stage)})" if stage else work.label)
        return not should_stop()

    def finish():
        """The call returned: its whole span is done, even when its last stages did not report
        (a pack with nothing to do, a re-chart route that stopped early)."""
        state["furthest"] = 1.0
        if report is not None:
            stage = state["stage"]
            report(work.start + work.span, f"{work.label} ({shown(stage)})" if stage else work.label)

    callback.finish = finish
    return callback


class ThreadedDriver:
    """Drive `job` without blocking: native work on a worker thread, bpy work in poll().

    The modal operator calls poll() from a timer on Blender's main thread;
    cancel() (Esc) makes the running native call stop at its next progress
    report and the job stop before its next step. poll() returns None while
    the job runs, then ("done", outcome) or ("error", exception) once.
    """

    def __init__(self, job):
        self._job = job
        self._stop = threading.Event()
        self._thread = None
        self._send = ("value", None)
        self.fraction = 0.0
        self.label = "Starting"

    def cancel(self):
        self._stop.set()
        self.label = "Cancelling"

    def poll(self):
        if self._thread is not None:
            if self._thread.is_alive():
                return None
            self._thread = None
        if self._stop.is_set():
            self._job.close()
            return ("error", Cancelled())
        kind, payload = self._send
        try:
            work = self._job.throw(payload) if kind == "error" else self._job.send(payload)
        except StopIteration as stop:
            return ("done", stop.value)
        except BaseException as error:
            return ("error", error)
        self.label = work.label
        self.fraction = work.start
        if work.call is None:  # a progress mark: show it now, do the bpy work on the next poll
            self._send = ("value", None)
        else:
            self._start(work)
        return None

    def _start(self, work):
        def report(fraction, label):
            # Runs on the worker thread: plain Python state only, never bpy.
            self.fraction = fraction

        progress = _progress_callback(work, report, self._stop.is_set)

        def target():
            try:
                value = work.call(progress)
                progress.finish()
                self._send = ("value", value)
            except BaseException as error:
                self._send = ("error", error)

        self._thread = threading.Thread(target=target, name="lmrefine", daemon=True)
        self._thread.start()
