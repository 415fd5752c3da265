"""Layouts: Per Effect (issue 14 item 3): each light effect its own refined UV map and its own image.

The effects are lmrefine.per_effect.EFFECTS, direct and indirect light: the
combined light is their sum, so the preview adds them. Per atlas group:

1. both effects baked on the source layout at Resolution R; each effect's
   gradient energy, summed over the groups, splits the R^2 texels by the
   rule (lmrefine.per_effect.split_fractions / split_resolutions): each
   effect gets one side r for the whole run, its maps together hold at most
   the texels of one R map;
2. per effect: its first bake on the source layout at r (the R bake when r
   is R), refine_uvs from it at r, checked, written to
   `<source>_refined_<effect>`;
3. per effect: the second bake with its own map, one image
   `<group>_lightmap_<effect>_effect` at r x r; the first bake at r is kept
   as `<group>_lightmap_before_<effect>` (the preview's Before);
4. the preview adds the effects' images, each through its own UV map.

AO multiplies the light rather than adding to it, and is not an effect here:
with AO among the bake passes the run says so and leaves it out (bake it with
Layouts: One). The job is a generator driven like pipeline.run.
"""

import time
from dataclasses import replace

import bpy
import numpy as np

from . import atlas, bridge, materials
from .errors import UserError

IMAGE_SUFFIX = "_effect"  # <group>_lightmap_direct_effect: not the One layout's <group>_lightmap_direct


def run(context, targets, options, journal, image_dir=None):
    from . import pipeline
    lmrefine = pipeline.import_core()
    from lmrefine.per_effect import EFFECTS, gradient_energy, split_fractions, split_resolutions

    rule = options["per_effect"]
    if options["first_lightmap"] == 'IMAGE':
        raise UserError("Layouts: Per Effect bakes each effect's first map itself, and an existing image holds "
                        "one light, not its effects: set First Map to Embree or Cycles, or Layouts to One")
    if options.get("stages", 1) > 1 or options.get("tessellate") is not None:
        raise UserError("Layouts: Per Effect refines each effect's layout once, without tessellation: set Stages "
                        "to 1 and turn Tessellate off, or set Layouts to One")
    outcome = pipeline.new_outcome(targets, options)
    if "ao" in options["bake_passes"]:
        outcome.warnings.append("AO was not baked: with Layouts: Per Effect the run bakes the effects that add "
                                "up to the light (direct, indirect); AO multiplies it, bake it with Layouts: One")
    resolution, padding = options["resolution"], options["padding"]
    groups = atlas.group_targets(list(targets), resolution, options.get("shared_atlas", True))
    for group in groups:
        group.join()
    source_of = {t.obj.name: t.source for t in targets}
    # Progress in units of one map's work: the split bake, then per effect a first bake, a refinement
    # and a second bake of every map.
    span = 1.0 / (len(groups) * (1 + 3 * len(EFFECTS)))
    done = 0

    def bake(backend, uv_name_of, passes, side, label):
        """One unit of progress per map; the first bakes with First Map's baker, the second with Baker's."""
        settings = dict(options, resolution=side)
        if backend == 'EMBREE':
            return (yield from pipeline._bake_embree(context, lmrefine, targets, uv_name_of, passes, settings, label,
                                                     done * span, len(groups) * span, outcome.warnings))
        return (yield from pipeline._bake_cycles(context, targets, uv_name_of, passes, settings, label, done * span,
                                                 len(groups) * span))

    # 1. The split: both effects at R on the source layout.
    clock = time.perf_counter()
    baked = yield from bake(options["first_lightmap"], source_of, EFFECTS, resolution,
                            "First bake (effects at full resolution)")
    done += len(groups)
    at_full = {name: pipeline._group_maps(groups, baked[name], resolution) for name in EFFECTS}
    energies = {name: sum(gradient_energy(image) for image in at_full[name].values()) for name in EFFECTS}
    fractions = split_fractions(rule, energies)
    sides = split_resolutions(resolution, fractions)
    outcome.timings["first bake"] = time.perf_counter() - clock

    # 2. Per effect: its first bake at its side, its refinement, its UV map.
    clock = time.perf_counter()
    firsts, refined_uvs, reports = {}, {}, {group.name: {} for group in groups}
    for name in EFFECTS:
        side = sides[name]
        if side == resolution:
            firsts[name] = at_full[name]
        else:
            baked = yield from bake(options["first_lightmap"], source_of, (name,), side,
                                    f"First bake ({name} at {side})")
            firsts[name] = pipeline._group_maps(groups, baked[name], side)
        done += len(groups)
        refined_uvs[name] = {}
        for group in groups:
            label = f"{group.label()} ({name})"
            # The user's padding, as a One run passes it: where the source is tighter at this side,
            # refine_uvs keeps those pairs at their own distance and packs no closer than a texel.
            source_at_padding = lmrefine.check_layout(group.uvs, group.triangles, side, padding=padding)
            try:
                result = yield pipeline.NativeWork(
                    f"Refining {group.name} ({name})",
                    lambda progress, lightmap=firsts[name][group.name], group=group, side=side:
                        lmrefine.refine_uvs(lightmap, group.uvs, group.triangles, side, padding=padding,
                                            progress=progress, positions=group.positions, normals=group.normals,
                                            **options["refine_options"]),
                    done * span, span, parts=pipeline.refine_parts(group, options))
            except (ValueError, TypeError, MemoryError) as error:
                raise UserError(f"{label} could not be refined at {side} x {side} texels: "
                                f"{pipeline.error_text(error)}") from error
            done += 1
            check, source_check = pipeline._check_refined(lmrefine, label, result.uvs,
                                                          bridge.Layout(group.uvs, group.triangles), group.uvs, side,
                                                          padding)
            warning = pipeline.source_warning(label, group, source_at_padding, padding, side)
            if warning is not None:
                outcome.warnings.append(warning)
            if not result.report["moved"]:  # say why, as a One run does
                why = next((n for n in result.report["notes"] if n.startswith("nothing moved")), "nothing moved")
                outcome.warnings.append(f"{label}: {why}")
            own = group.split(result.uvs)
            for target in group.targets:
                pipeline._write_refined_layer(_effect_target(target, name), own[target.obj.name], journal)
            report = {key: value for key, value in result.report.items() if key != "triangle_density"}
            report.update(check_layout=dict(check), source_check_layout=dict(source_check), resolution=side,
                          fraction=fractions[name], energy=energies[name],
                          uv_maps=[_effect_target(t, name).refined for t in group.targets])
            reports[group.name][name] = pipeline._plain(report)
            refined_uvs[name][group.name] = result.uvs
    outcome.timings["refine"] = time.perf_counter() - clock

    # 3. Per effect: the second bake with its own UV map, its image.
    clock = time.perf_counter()
    for name in EFFECTS:
        side = sides[name]
        refined_of = {t.obj.name: _effect_target(t, name).refined for t in targets}
        pipeline.modifier_warnings(context, targets, refined_of, side, outcome.warnings)
        baked = yield from bake(options["backend"], refined_of, (name,), side, f"Second bake ({name} at {side})")
        done += len(groups)
        merged = pipeline._group_maps(groups, baked[name], side, refined_uvs[name])
        for group in groups:
            images = outcome.images.setdefault(group.name, {})
            images[name] = pipeline._store_image(group, name + IMAGE_SUFFIX, merged[group.name], journal).name
            if options["preview"]:
                images[f"before_{name}"] = pipeline._store_image(group, f"before_{name}", firsts[name][group.name],
                                                                journal).name
    outcome.timings["second bake"] = time.perf_counter() - clock

    outcome.atlases = {group.name: group.objects for group in groups}
    for group in groups:
        effects = reports[group.name]
        outcome.effects[group.name] = {name: {"resolution": sides[name], "image": outcome.images[group.name][name],
                                              "report": effects[name]} for name in EFFECTS}
        outcome.reports[group.name] = _combined_report(effects, rule)

    # 4. The preview adds the effects, each through its own UV map; then the files (last: no rollback).
    if options["preview"]:
        for group in groups:
            images = outcome.images[group.name]
            after = [bpy.data.images[images[name]] for name in EFFECTS]
            before = [bpy.data.images[images[f"before_{name}"]] for name in EFFECTS]
            for target in group.targets:
                materials.add_terms_preview(target.obj, after, [_effect_target(target, n).refined for n in EFFECTS],
                                            before, [target.source] * len(EFFECTS), journal)
    for names in outcome.images.values():
        for image_name in names.values():
            outcome.image_files[image_name] = pipeline._save_image(
                lmrefine, bpy.data.images[image_name], image_dir, "float" if options["exr_float32"] else "half")
    return outcome


def _effect_target(target, effect):
    """`target` writing its effect's UV map, `<source>_refined_<effect>`."""
    return replace(target, refined=f"{target.refined}_{effect}")


def _combined_report(effects, rule):
    """The group's report for Outcome.summary: the effects' figures together (widening their mean,
    density their extremes), each effect's own report under "effects"."""
    values = list(effects.values())
    limits = set()
    for report in values:
        limited_by = report.get("limited_by") or []
        limits.update([limited_by] if isinstance(limited_by, str) else limited_by)
    return {"moved": any(report["moved"] for report in values),
            "transition_widening": float(np.mean([report["transition_widening"] for report in values])),
            "density_min": min(report["density_min"] for report in values),
            "density_max": max(report["density_max"] for report in values),
            "limited_by": sorted(limits), "split_rule": rule, "effects": effects,
            # Re-charted (the source gave no room) for any effect: the operator counts these maps and
            # reports their first note (an effect whose map was re-charted first).
            "rechart": {"used": any(_recharted(report) for report in values)},
            "notes": [f"{name}: {note}" for name, report in sorted(effects.items(), key=lambda e: not _recharted(e[1]))
                      for note in report.get("notes", [])]}


def _recharted(report):
    return bool((report.get("rechart") or {}).get("used"))
