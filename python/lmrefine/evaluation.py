"""Evaluation of the whole method on a scene: is the refined lightmap better?

    baseline bake at R -> refine_uvs -> re-bake at R with the refined UVs ->
    ground truth at surface points -> baseline bakes at R x multipliers ->
    metrics (lmrefine.metrics) -> report.md, report.json, pictures

Used by ``python3 -m lmrefine evaluate`` and ``demo``; the metrics are defined
in :mod:`lmrefine.metrics` and docs/evaluation.md.
"""

import functools
import math
import os
import time
from dataclasses import dataclass, field, replace

import numpy as np

from . import bake, check_layout, coverage_mask, find_charts, metrics, pack_charts, refine_uvs, write_image
from . import evaluate as evaluate_light
from .charting import rechart
from .per_effect import EFFECTS, gradient_energy, parse_rules, split_fractions, split_resolutions
from .refine import pack_padding
from .tessellation import (COARSE_CONTRAST, COARSE_TRIANGLE_TEXELS, MAX_BUDGET, TRIAL_BUDGET, budget_to_end,
                           light_contrast, tessellated_refine_options)

DEFAULT_MULTIPLIERS = (1.0, 1.5, 2.0, 3.0, 4.0)
# A transition-point RMSE at least this much lower counts as a gain.
GAIN_THRESHOLD = 0.05
# An object whose RMSE the refined map raises by this factor (and by more than
# twice the truth's noise), measured at this many points or more, is named in
# a note: the figure over all points can hide it.
OBJECT_WORSE = 1.25
OBJECT_MIN_POINTS = 200


@dataclass
class EvaluationOptions:
    resolution: int = 256
    variant: str = "smart"            # UV variant of the sample scene
    samples: int = 32                 # bake samples per texel
    # Samples per texel of the first bake, the map the refinement reads;
    # None: `samples`. Every other bake (the plain map the refined one is
    # compared with, the refined map, the uniform sweep) uses `samples`.
    first_samples: int = None
    truth_samples: int = 256          # lmrefine.evaluate samples per point (ground truth)
    points: int = 20000               # surface points
    seed: int = 0
    multipliers: tuple = DEFAULT_MULTIPLIERS
    padding: float = 2.0              # gutter the refined layout must keep, texels
    denoise: bool = False
    bake_pass: str = None             # None: the scene's own pass (direct, or combined for the room)
    refine_options: dict = field(default_factory=dict)   # passed to refine_uvs (strength, passes, ...)
    # Re-chart the scene's mesh (lmrefine.rechart with this angle in degrees)
    # and use that layout instead of the scene's own UVs; None: the scene's.
    rechart: float = None
    # With rechart: the scene's own UV variants whose uniform bakes the
    # re-charted maps are also compared with (a resolution sweep each).
    compare_variants: tuple = ()
    # refine_uvs' re-chart route (positions=): a source layout with no room
    # (Lightmap Pack) is re-charted from the mesh inside refine_uvs, as the
    # add-on and the batch do; False: refine the source layout (--no-rechart).
    auto_rechart: bool = True
    view_width: int = 480             # pixels across the pictures of the lit surface (0: none)
    tessellate: float = None          # vertex budget (fraction) of a tessellation along transitions; None: off
    stages: int = 1                   # refine + bake stages, each refining from the previous stage's bake
    # Separate layouts for separate effects (lmrefine.per_effect): the split
    # rules to measure, e.g. ("sqrt",) or "equal,energy,sqrt"; None: off.
    per_effect: tuple = None

    def check(self):
        if self.resolution < 8:
            raise ValueError(f"resolution must be at least 8, got {self.resolution}")
        if self.points < 100:
            raise ValueError(f"points must be at least 100 (for a top decile of transitions), got {self.points}")
        if self.view_width != 0 and not 16 <= self.view_width <= 2048:
            raise ValueError(f"view width must be 0 (no surface pictures) or 16 to 2048 pixels, got {self.view_width}")
        if self.samples < 1 or self.truth_samples < 1:
            raise ValueError("samples and truth_samples must be at least 1")
        if self.first_samples is not None and self.first_samples < 1:
            raise ValueError(f"first_samples must be at least 1, or None for samples, got {self.first_samples}")
        m = tuple(float(x) for x in self.multipliers)
        if len(m) < 2 or m[0] != 1.0 or any(b <= a for a, b in zip(m, m[1:])):
            raise ValueError(f"multipliers must start at 1 and increase, e.g. 1,1.5,2,3,4; got {self.multipliers}")
        self.multipliers = m
        if self.rechart is not None and not 0.0 < float(self.rechart) < 90.0:
            raise ValueError(f"rechart must be an angle in (0, 90) degrees, got {self.rechart}")
        if not (isinstance(self.stages, int) and 1 <= self.stages <= 16):
            raise ValueError(f"stages must be an integer from 1 to 16, got {self.stages}")
        if self.tessellate is not None and not (0.0 <= self.tessellate <= MAX_BUDGET):
            raise ValueError(f"the tessellation budget is a fraction of the vertex count in [0, {MAX_BUDGET:g}] "
                             f"(0.25 = at most 25% more vertices), got {self.tessellate}")
        if self.per_effect is not None:
            self.per_effect = parse_rules(self.per_effect)
            if self.bake_pass not in (None, "combined"):
                raise ValueError(f"per_effect (--per-effect) compares the effects' maps, added up, with the "
                                 f"combined light: leave the pass (--pass) unset or use 'combined', not "
                                 f"{self.bake_pass!r}")
            if self.stages != 1:
                raise ValueError(f"per_effect (--per-effect) refines each effect's layout once: use it with "
                                 f"stages=1 (--stages 1), not {self.stages}")
            if self.first_samples is not None:
                raise ValueError("per_effect (--per-effect) bakes each effect's first map with the combined one: "
                                 "leave first_samples (--first-samples) unset")

    @property
    def layout_name(self):
        """The layout's name in reports and folder names: the UV variant, or rechart<angle>."""
        return self.variant if self.rechart is None else f"rechart{float(self.rechart):g}"


class _Stages:
    """Wall-clock seconds per named stage, and a progress callback that
    labels every stage with the scene's name."""

    def __init__(self, label, progress):
        self.label, self.progress, self.seconds = label, progress, {}

    def callback(self, stage):
        if self.progress is None:
            return None
        return lambda fraction, inner=None: self.progress(fraction, f"{self.label}: {stage}")

    def run(self, stage, work):
        start = time.perf_counter()
        result = work(self.callback(stage))
        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - start
        return result


def _bake_map(sample, uvs, resolution, options, progress, passes=None):
    """The RGB map of the evaluation's pass (or of `passes`, one name) at
    `resolution` on the layout `uvs`."""
    return np.ascontiguousarray(_bake_passes(sample, uvs, resolution, options, progress,
                                             (passes or _single_pass(sample, options),))[0][..., :3])


def _bake_passes(sample, uvs, resolution, options, progress, passes):
    """Several passes in one bake (each transport traced once): a list of
    (H, W, 4) maps, alpha = coverage, in the order of `passes`."""
    result = bake(sample.to_scene(uvs), resolution, passes=passes, samples=options.samples, seed=options.seed,
                  progress=progress, denoise=options.denoise)
    return [result[0]] if len(passes) == 1 else [result[name][0] for name in passes]


def _tessellated(sample, variant, baseline, budget):
    """The scene with its triangles split along the transitions of `baseline`
    (baked on `variant`): the same surface, every UV variant keeping its
    mapping (lmrefine.tessellation). The budget holds per object, as in the
    add-on: each object gets at most `budget` x its own vertices (objects
    that share vertices are one mesh here: split together, on their joint
    budget, so a split edge they share stays conforming).
    Returns (scene, tessellation report, (parent triangle per output
    triangle, (3T', 3) barycentric coordinates of every output corner in its
    parent))."""
    from .tessellation import tessellate, transition_strength_of

    uvs, corner_triangles = sample.layout(variant)
    strength = transition_strength_of(baseline, uvs, corner_triangles)
    # A split edge stays conforming only where its two faces share its vertices.
    sample = replace(sample, **dict(zip(("positions", "triangles"), welded(sample.positions, sample.triangles,
                                                                          sample.object_id))))
    others = {name: values for name, values in sample.uvs.items() if name != variant}
    # Each output corner's barycentric coordinates in its input triangle: a
    # point of the split mesh is then a point of the input mesh too.
    attributes = {"normals": sample.normals, "parent_bary": np.tile(np.eye(3), (len(sample.triangles), 1)),
                  **{f"uv:{k}": v for k, v in others.items()}}
    pieces, reports, new_positions = [], [], [sample.positions]
    vertex_count = len(sample.positions)
    groups = _connected_objects(sample.triangles, sample.object_id)
    for members in groups:
        rows = np.nonzero(np.isin(sample.object_id, members))[0]
        corners = (3 * rows[:, None] + np.arange(3)).ravel()
        used, local = np.unique(sample.triangles[rows], return_inverse=True)
        result = tessellate(sample.positions[used], local.reshape(-1, 3), uvs[corners], strength, budget=budget,
                            corner_attributes={name: values[corners] for name, values in attributes.items()})
        # The objects' own vertices keep their scene index; new ones follow.
        to_scene = np.concatenate([used, vertex_count + np.arange(len(result.positions) - len(used))])
        vertex_count += len(result.positions) - len(used)
        new_positions.append(result.positions[len(used):])
        pieces.append((result, rows, to_scene[result.triangles]))
        reports.append({"objects": [sample.objects[i] for i in members], **result.report})
    corner = {name: np.concatenate([r.corner_attributes[name] for r, _, _ in pieces]) for name in attributes}
    parent = np.concatenate([rows[r.parent] for r, rows, _ in pieces])
    normals = corner["normals"].astype(np.float64)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    layouts = {variant: np.concatenate([r.uvs for r, _, _ in pieces])}
    layouts.update({name: corner[f"uv:{name}"].astype(np.float32) for name in others})
    scene = replace(sample, positions=np.concatenate(new_positions).astype(np.float32),
                    triangles=np.concatenate([t for _, _, t in pieces]).astype(np.int32),
                    normals=normals.astype(np.float32), uvs={name: layouts[name] for name in sample.uvs},
                    base_color=sample.base_color[parent], object_id=sample.object_id[parent],
                    polygons=None if sample.polygons is None else sample.polygons[parent])
    report = {key: sum(r[key] for r in reports) for key in ("vertices_added", "vertex_budget", "triangles_before",
                                                           "triangles_after", "candidates_left")}
    report.update(vertices_before=len(sample.positions), vertices_after=vertex_count)
    report.update(rounds=max(r["rounds"] for r in reports), stopped="; ".join(sorted({r["stopped"] for r in reports})),
                  min_texels=reports[0]["min_texels"], threshold=reports[0]["threshold"], objects=reports)
    return scene, report, (parent, corner["parent_bary"])


def welded(positions, triangles, object_id):
    """(positions, triangles) with the vertices of one object at the same
    position joined: a scene file exported from Blender (export-scene) has a
    vertex per face corner, so its faces share no vertex. A vertex that
    triangles of several objects use, or none, keeps its own index; the
    vertices keep their order (first index of each position), so a scene
    without such vertices comes back as it was."""
    positions = np.asarray(positions)
    triangles = np.asarray(triangles)
    count = len(positions)
    lowest = np.full(count, np.iinfo(np.int64).max, np.int64)
    highest = np.full(count, -1, np.int64)
    corner_object = np.repeat(np.asarray(object_id, np.int64), 3)
    np.minimum.at(lowest, triangles.ravel(), corner_object)
    np.maximum.at(highest, triangles.ravel(), corner_object)
    # One owner per vertex: its object, or a key of its own when several objects (or none) use it.
    owner = np.where(lowest == highest, lowest, -1 - np.arange(count)).astype(np.float64)
    _, first, inverse = np.unique(np.column_stack([owner, positions.astype(np.float64)]), axis=0,
                                  return_index=True, return_inverse=True)
    if len(first) == count:
        return positions, triangles
    order = np.argsort(first, kind="stable")
    renumber = np.empty(len(first), np.int64)
    renumber[order] = np.arange(len(first))
    return positions[first[order]], renumber[inverse.ravel()][triangles].astype(triangles.dtype)


def _connected_objects(triangles, object_id):
    """Lists of object ids whose triangles share vertices (transitively), in
    order of their first object."""
    objects = np.unique(object_id)
    root = {int(o): int(o) for o in objects}

    def find(o):
        while root[o] != o:
            root[o] = root[root[o]]
            o = root[o]
        return o

    owner = np.full(int(triangles.max()) + 1 if triangles.size else 0, -1, np.int64)
    for vertex, obj in zip(triangles.ravel().tolist(), np.repeat(object_id, 3).tolist()):
        if owner[vertex] < 0:
            owner[vertex] = obj
        elif find(int(owner[vertex])) != find(obj):
            root[find(obj)] = find(int(owner[vertex]))
    groups = {}
    for o in objects.tolist():
        groups.setdefault(find(o), []).append(o)
    return sorted(groups.values())


def _route_mesh(sample, options):
    """refine_uvs' keyword arguments for its re-chart route: the mesh, one
    row per corner UV (positions, shading normals), and the face each
    triangle was cut from (polygons: None for a scene file without them);
    {} when the route is off."""
    if not (options.auto_rechart and options.rechart is None):
        return {}
    return {"positions": sample.positions[sample.triangles].reshape(-1, 3), "normals": sample.normals,
            "polygons": sample.polygons}


def _plain_refinement(unsplit, variant, baseline, to_unsplit, points, truth, transitions, sweep, resolution,
                      padding, options, stages, result):
    """The plain refinement (the same scene without the tessellation, refined
    from the same bake at the same resolution) measured at the same points
    against the same truth and uniform bakes as the tessellated one: the
    tessellation's own gain, free of the points' sampling noise."""
    uvs, triangles = unsplit.layout(variant)
    # refine_uvs' re-chart route as for the tessellated mesh (evaluate_sample).
    route = _route_mesh(unsplit, options)
    refined = stages.run("refine unsplit", lambda p: refine_uvs(baseline, uvs, triangles, resolution,
                                                                padding=padding, progress=p, **route,
                                                                **options.refine_options))
    refined_map = stages.run("bake unsplit", lambda p: _bake_map(unsplit, refined.uvs, resolution, options, p))
    parent, parent_bary = to_unsplit
    bary = metrics.interpolate_corners(parent_bary, points.triangle, points.bary)
    lookup = metrics.bilinear_lookup(refined_map, metrics.interpolate_corners(refined.uvs, parent[points.triangle],
                                                                              bary))
    out = {"plain_refine": {k: refined.report[k] for k in ("backoff", "backoff_area", "limited_by")
                            if k in refined.report}}
    for where, prefix in ((np.ones(len(truth), bool), ""), (transitions, "transition_")):
        errors = [metrics.error_stats(s["lookup"], truth, where)["rmse"] for s in sweep]
        rmse = metrics.error_stats(lookup, truth, where)["rmse"]
        ratio, status = metrics.equal_error_resolution(options.multipliers, errors, rmse)
        split_ratio = result[f"{prefix}equal_error_resolution_ratio"]
        out[f"plain_{prefix}rmse"] = rmse
        out[f"plain_{prefix}equal_error_resolution_ratio"] = ratio
        out[f"plain_{prefix}equal_error_status"] = status
        out[f"{prefix}gain_over_plain"] = (split_ratio / ratio if ratio and split_ratio and ratio > 0 else None)
    return out


def _ill_determined_note(result):
    """A note when the equal-error ratio is ill-determined: within
    metrics.INTERVAL_TOLERANCE of the refined map's error, the uniform
    baseline's curve gives ratios more than ILL_DETERMINED_SPREAD apart
    (its error hardly falls there: bake noise, most often); else None."""
    low, high = result["equal_error_interval"]
    if not (np.isfinite(low) and np.isfinite(high)) or high < metrics.ILL_DETERMINED_SPREAD * low:
        return None
    sweep = result["resolution_sweep"]
    # The stretch to name: the flattest of those the interval spans.
    spanned = [k for k in range(1, len(sweep)) if sweep[k - 1]["multiplier"] < high and sweep[k]["multiplier"] > low]
    flattest = min(spanned or range(1, len(sweep)),
                   key=lambda k: (sweep[k - 1]["rmse"] - sweep[k]["rmse"]) / sweep[k - 1]["rmse"])
    a, b = sweep[flattest - 1], sweep[flattest]
    return (f"ill-determined ratio: the refined map's error {result['rmse_refined']:.4g} +-"
            f"{metrics.INTERVAL_TOLERANCE:.0%} matches the uniform baseline anywhere from {low:.2f}x to {high:.2f}x, "
            f"as the baseline's error hardly falls there ({a['rmse']:.4g} at {a['resolution']}, {b['rmse']:.4g} at "
            f"{b['resolution']}); bake with more --samples (now {result['bake_samples']}) to resolve it, and compare "
            "runs by their errors rather than this ratio")


# The stop rule of further stages is shared with the add-on (lmrefine.metrics).
STAGE_MIN_CHANGE = metrics.STAGE_MIN_CHANGE


def _further_stages(sample, triangles, resolution, padding, options, stages, points, truth, transitions, refined,
                    refined_map, lookup):
    """Stages 2..options.stages: refine the previous stage's layout from its
    own bake, bake again. Stops when a stage's layout hardly differs from the
    previous one (STAGE_MIN_CHANGE), its refinement backed off below
    STAGE_MIN_BACKOFF or it gave the light changes no more texels
    (metrics.stage_stop_reason); the world-space error of every stage is
    measured at the evaluation's points for the report, never used to choose.
    Returns the last kept stage's (refine result, map, lookup) and the history."""
    everywhere = np.ones(len(truth), bool)

    def errors(stage, result, lookup, change=None):
        return {"stage": stage, "rmse": metrics.error_stats(lookup, truth, everywhere)["rmse"],
                "transition_rmse": metrics.error_stats(lookup, truth, transitions)["rmse"],
                **metrics.stage_entry(stage, result.report, change)}

    history = [errors(1, refined, lookup)]
    stopped = f"{options.stages} stages done"
    further = {**options.refine_options, **metrics.further_stage_options(refined.report)}
    for stage in range(2, options.stages + 1):
        previous, previous_map = refined, refined_map
        candidate = stages.run("refine", lambda p: refine_uvs(previous_map, previous.uvs, triangles, resolution,
                                                              padding=padding, progress=p, **further))
        change = metrics.layout_change(previous.uvs, candidate.uvs, triangles)
        entry = metrics.stage_entry(stage, candidate.report, change)
        reason = metrics.stage_stop_reason(stage, entry["moved"], change, entry["backoff"], entry["widening"])
        if reason is not None:
            history.append({**entry, "kept": False})
            stopped = reason
            break
        candidate_map = stages.run("bake refined", lambda p: _bake_map(sample, candidate.uvs, resolution, options, p))
        uv = metrics.interpolate_corners(candidate.uvs, points.triangle, points.bary)
        lookup = metrics.bilinear_lookup(candidate_map, uv)
        refined, refined_map = candidate, candidate_map
        history.append(errors(stage, candidate, lookup, change))
    for entry in history:
        entry.setdefault("kept", True)
    return refined, refined_map, lookup, {"stages": history, "stopped": stopped,
                                          "repack": bool(further.get("repack", True))}


def _uniform_sweep(sample, uvs, uv_points, resolution, options, stages, label, first=None):
    """Uniform bakes of the layout `uvs` at R x each multiplier, read at the
    points' UVs `uv_points`: [{multiplier, resolution, lookup}]. `first`: the
    lookup at R when it is already baked."""
    sweep = []
    for multiplier in options.multipliers:
        size = int(round(resolution * multiplier))
        if multiplier == 1.0 and first is not None:
            lookup = first
        else:
            image = stages.run(label, lambda p: _bake_map(sample, uvs, size, options, p))
            lookup = metrics.bilinear_lookup(image, uv_points)
        sweep.append({"multiplier": multiplier, "resolution": size, "lookup": lookup})
    return sweep


def _uniform_repack(sample, uvs, triangles, resolution, padding, options, points, progress):
    """The input's charts repacked at one common scale (lmrefine.pack_charts,
    scales None), baked at R and read at the points; None when the charts do
    not pack (the report then has no second baseline)."""
    try:
        packed, report = pack_charts(uvs, triangles, None, None, resolution, padding, progress=progress)
    except ValueError:
        return None
    image = _bake_map(sample, packed, resolution, options, None)
    lookup = metrics.bilinear_lookup(image, metrics.interpolate_corners(packed, points.triangle, points.bary))
    return {"lookup": lookup, "utilisation_before": float(report["utilisation_input"]),
            "utilisation_after": float(report["utilisation"]), "global_scale": float(report["global_scale"])}


def _per_effect(sample, uvs, triangles, resolution, options, stages, points, truth, effect_truth, transitions,
                first_bakes, sweep):
    """Separate layouts for separate effects (lmrefine.per_effect), once per
    split rule: each effect's texels (R^2 split by the rule), its first bake
    on the input layout at its own resolution, refine_uvs from that bake, the
    effect baked on its refined layout; at the points, the effects' maps added
    up against the combined truth, and each effect against its own uniform
    bakes (its equal-error ratio). `first_bakes` {effect: (bake at R,
    another seed's)}, `sweep` the combined uniform bakes at R x multipliers.
    Returns (report, {(rule, effect): refined uvs})."""
    everywhere = np.ones(len(truth), bool)
    energies = {name: gradient_energy(*first_bakes[name]) for name in EFFECTS}
    # (effect, layout, side) -> (map or None, values at the points): rules
    # that give an effect the same side share its bakes on the input layout.
    bakes = {}

    def lookup(name, layout_uvs, side, key, keep_map=False):
        if (name, key, side) not in bakes:
            image = stages.run(f"per-effect bake {name}", lambda p: _bake_map(sample, layout_uvs, side, options, p,
                                                                              passes=name))
            at_points = metrics.interpolate_corners(layout_uvs, points.triangle, points.bary)
            bakes[(name, key, side)] = (image if keep_map else None, metrics.bilinear_lookup(image, at_points))
        return bakes[(name, key, side)]

    def figures(plain, refined, target, sweep_errors, sweep_transition_errors):
        out = {}
        for where, prefix, errors in ((everywhere, "", sweep_errors), (transitions, "transition_",
                                                                       sweep_transition_errors)):
            rmse_plain = metrics.error_stats(plain, target, where)["rmse"]
            rmse_refined = metrics.error_stats(refined, target, where)["rmse"]
            ratio, status = metrics.equal_error_resolution(options.multipliers, errors, rmse_refined)
            out.update({f"{prefix}rmse_plain": rmse_plain, f"{prefix}rmse_refined": rmse_refined,
                        f"{prefix}equal_error_resolution_ratio": ratio, f"{prefix}equal_error_status": status})
        return out

    combined_errors = [metrics.error_stats(s["lookup"], truth, everywhere)["rmse"] for s in sweep]
    combined_transition_errors = [metrics.error_stats(s["lookup"], truth, transitions)["rmse"] for s in sweep]
    rules, layouts = [], {}
    # Each effect's refinement takes the re-chart route as the add-on's per-effect maps do.
    route = _route_mesh(sample, options)
    for rule in options.per_effect:
        fractions = split_fractions(rule, energies)
        sides = split_resolutions(resolution, fractions)
        effects, plain_sum, refined_sum = {}, 0.0, 0.0
        for name in EFFECTS:
            side = sides[name]
            # Valid: as the input at this side where that is tighter than the padding (refine_uvs keeps it).
            gutter = check_layout(uvs, triangles, side, options.padding)["min_gutter_texels"]
            padding = min(float(options.padding), float(gutter))
            first, plain = lookup(name, uvs, side, "input", keep_map=True)
            refined = stages.run("per-effect refine", lambda p: refine_uvs(
                first, uvs, triangles, side, padding=options.padding, progress=p, **route,
                **options.refine_options))
            _, refined_lookup = lookup(name, refined.uvs, side, f"{rule} refined")
            layouts[(rule, name)] = refined.uvs
            # The effect's own uniform bakes at side x multipliers, against its own truth.
            target = effect_truth[name]
            sweep_lookups = [plain] + [lookup(name, uvs, int(round(side * m)), "input")[1]
                                       for m in options.multipliers[1:]]
            effects[name] = {
                "fraction": fractions[name], "resolution": side, "texels": side * side, "energy": energies[name],
                "layout_valid": bool(check_layout(refined.uvs, triangles, side, padding)["valid"]),
                "moved": bool(refined.report["moved"]),
                **figures(plain, refined_lookup, target,
                          [metrics.error_stats(s, target, everywhere)["rmse"] for s in sweep_lookups],
                          [metrics.error_stats(s, target, transitions)["rmse"] for s in sweep_lookups])}
            plain_sum, refined_sum = plain_sum + plain, refined_sum + refined_lookup
        texels = sum(e["texels"] for e in effects.values())
        rules.append({"rule": rule, "texels": texels, "texel_fraction": texels / resolution ** 2,
                      **figures(plain_sum, refined_sum, truth, combined_errors, combined_transition_errors),
                      "effects": effects})
    return {"effects": list(EFFECTS), "combined_texels": resolution ** 2, "rules": rules}, layouts


def _single_pass(sample, options):
    if options.per_effect:
        return "combined"
    if options.bake_pass:
        return options.bake_pass
    if len(sample.passes) != 1:
        raise ValueError(f"scene '{sample.name}' asks for passes {sample.passes}; the evaluation compares one "
                         "lightmap: use 'combined' for direct + indirect")
    return sample.passes[0]


def _json_safe(value):
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items() if not isinstance(v, np.ndarray) or v.size <= 16}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, float)):
        return None if not math.isfinite(float(value)) else float(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _coarse_note(texels, split):
    """What a scene whose transitions cross triangles of `texels` texels (median) can do about it;
    `split`: _split_trial's (object, vertices added, its vertices), the budget the split needs."""
    name, added, vertices = split
    needed = budget_to_end(added, vertices)
    budget = (f"--tessellate {TRIAL_BUDGET:g} or more ('{name}' takes +{added} to its {vertices} vertices and "
              "still has triangles to split)" if needed >= TRIAL_BUDGET else
              f"--tessellate {needed:g} (the split of '{name}' ends by itself there, at +{added} to its "
              f"{vertices} vertices)")
    return (f"coarse tessellation: a triangle under a transition covers {texels:.0f} texels (median), and the "
            "texel density is constant inside a triangle, so texels cannot gather at an edge that crosses it "
            f"(docs/method.md §5): split them with {budget}, as the add-on's Tessellate does, or subdivide the "
            "receivers")


def _split_trial(sample, variant, baseline):
    """The object whose split (evaluate --tessellate's, from `baseline` baked on `variant`, at
    TRIAL_BUDGET) adds the most vertices for its count: (its name(s), vertices added, its
    vertices), or None when the split adds none."""
    _, report, _ = _tessellated(sample, variant, baseline, TRIAL_BUDGET)
    worst = max(report["objects"], key=lambda r: r["vertices_added"] / max(r["vertices_before"], 1))
    if not worst["vertices_added"]:
        return None
    return "', '".join(worst["objects"]), int(worst["vertices_added"]), int(worst["vertices_before"])


def _objects_served_worse(objects, truth_noise):
    """A note naming the objects whose error the refined map raised by more
    than OBJECT_WORSE and by more than twice the truth's noise (so not by the
    truth's noise alone), with the share of texels each kept; None if none."""
    worse = [o for o in objects if o["points"] >= OBJECT_MIN_POINTS
             and o["rmse_refined"] > OBJECT_WORSE * o["rmse_baseline"]
             and o["rmse_refined"] - o["rmse_baseline"] > 2.0 * truth_noise]
    if not worse:
        return None
    named = ", ".join(f"{o['object']} (RMSE {o['rmse_baseline']:.4g} -> {o['rmse_refined']:.4g}, "
                      f"{o['texels']:.2f}x its texels)" for o in worse)
    return (f"objects the refined map serves worse than the plain bake: {named}; an object that lost texels "
            "gave them to light changes elsewhere (the figure over all points is what the texels buy), "
            "one that kept them may read a neighbour's light at its borders")


def _diagnose(result, context):
    """Why a scene shows no gain (or only a small one), from what we know."""
    notes = []
    report = context["refine_report"]
    if report.get("backoff", 1.0) < 1.0:
        where = (f" over {report['backoff_area'] * 100:.0f}% of the grid" if "backoff_area" in report else "")
        notes.append(f"the refiner backed off{where}, down to {report['backoff'] * 100:.0f}% of the full "
                     f"deformation (limited by {', '.join(report.get('limited_by', [])) or 'nothing reported'})")
    elif report.get("limited_by"):
        notes.append(f"the refiner was limited by {', '.join(report['limited_by'])}")
    widening = result["transition_widening"]
    if widening is not None and widening < 1.25:
        notes.append(f"transition points gained little texel density (widening {widening:.2f}x)")
    small_charts = context["chart_texels_at_transitions"] < 100
    if context["texels_per_transition_triangle"] > 16 and not small_charts:
        split = context["split_trial"]()
        if split is not None:  # else the split would add nothing: tessellation is no fix
            notes.append(_coarse_note(context["texels_per_transition_triangle"], split))
    if small_charts:
        notes.append(f"small charts: the charts under transitions cover {context['chart_texels_at_transitions']:.0f} "
                     "texels (median) and the gutters between charts keep their width, so texels can hardly move "
                     "towards an edge (Lightmap Pack makes one chart per face): use a layout with larger charts "
                     "(Smart UV Project, or --rechart: lmrefine.rechart) or a higher resolution")
    if result["transition_points"] < 30:
        notes.append(f"only {result['transition_points']} transition points: too few to measure; raise --points")
    return notes


def into_pieces(to_unsplit, points):
    """Surface points of an input mesh (metrics.SurfaceSamples: input
    triangle, barycentric coordinates there) as points of its tessellation:
    the piece of that triangle that holds each point, and its barycentric
    coordinates in the piece. `to_unsplit`: (parent triangle per piece, (3T', 3)
    barycentric coordinates of every piece corner in its parent), as
    _tessellated returns it. Positions and normals are kept."""
    parent, parent_bary = to_unsplit
    parent = np.asarray(parent, np.int64)
    # A point's coordinates b in its parent are l @ B, B the piece's corners (rows) there: l = b @ B^-1.
    inverse = np.linalg.inv(np.asarray(parent_bary, np.float64).reshape(-1, 3, 3))
    order = np.argsort(parent, kind="stable")
    count = np.bincount(parent, minlength=int(points.triangle.max(initial=-1)) + 1)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    first, pieces = start[points.triangle], count[points.triangle]
    best = np.full(len(points.triangle), -1, np.int64)
    best_bary = np.zeros((len(best), 3))
    best_inside = np.full(len(best), -np.inf)
    for k in range(int(pieces.max(initial=0))):
        rows = np.nonzero(pieces > k)[0]
        piece = order[first[rows] + k]
        bary = np.einsum("pk,pkj->pj", points.bary[rows], inverse[piece])
        inside = bary.min(axis=1)  # >= 0 in the piece that holds the point (rounding aside)
        better = inside > best_inside[rows]
        rows, piece, bary = rows[better], piece[better], bary[better]
        best[rows], best_bary[rows], best_inside[rows] = piece, bary, inside[better]
    best_bary = np.clip(best_bary, 0.0, None)
    best_bary /= best_bary.sum(axis=1, keepdims=True)
    return metrics.SurfaceSamples(best, best_bary, points.points, points.normals)


def surface_points(sample, density, options):
    """The points the error is measured at (area-uniform on the receivers)
    and, for the transition detector, two neighbours of each along the
    surface half a median texel away (`density`: texels per unit area of
    each triangle in the input layout). Returns (points, stencil points,
    stencil normals, distances, median texel size)."""
    areas = sample.triangle_areas()
    points = metrics.sample_surface(sample.positions, sample.triangles, options.points, normals=sample.normals,
                                    seed=options.seed)
    texel_size = 1.0 / np.sqrt(np.maximum(density, 1e-30))
    order = np.argsort(texel_size)
    cumulative = np.cumsum(areas[order])
    median_texel = float(texel_size[order][np.searchsorted(cumulative, cumulative[-1] / 2)])
    stencil_points, stencil_normals, distances = metrics.gradient_stencil(
        sample.positions, sample.triangles, points, 0.5 * median_texel, normals=sample.normals)
    return points, stencil_points, stencil_normals, distances, median_texel


def evaluate_sample(sample, options, out_dir=None, progress=None):
    """Run the whole evaluation on one SampleScene; returns its report dict
    (and writes report.md, report.json and pictures into `out_dir` if given)."""
    options.check()
    label = f"{sample.name}/{options.layout_name}"
    stages = _Stages(label, progress)
    resolution = int(options.resolution)
    passes = _single_pass(sample, options)
    variant = options.variant
    layout = {"source": "scene", "variant": variant}
    if options.rechart is not None:
        # The re-charted layout replaces the scene's UVs for every bake below
        # (a UV variant of its own, so a tessellation carries it too).
        recharted = stages.run("rechart", lambda p: rechart(sample.positions, sample.triangles, float(options.rechart),
                                                            resolution, options.padding, progress=p,
                                                            normals=sample.normals))
        variant = options.layout_name
        sample = replace(sample, uvs={**sample.uvs, variant: recharted.uvs})
        layout = {"source": "rechart", **{k: v for k, v in recharted.report.items() if k != "chart_ids"}}
    uvs, triangles = sample.layout(variant)

    first_bakes = None
    if options.per_effect:
        # The combined baseline and each effect's bake at R in one bake, and
        # the effects again with another seed: their energy without the noise.
        maps = stages.run("bake baseline", lambda p: _bake_passes(sample, uvs, resolution, options, p,
                                                                  ("combined",) + EFFECTS))
        again = stages.run("per-effect energy bake", lambda p: _bake_passes(
            sample, uvs, resolution, replace(options, seed=options.seed + 1), p, EFFECTS))
        baseline = np.ascontiguousarray(maps[0][..., :3])
        first_bakes = {name: (first, second) for name, first, second in zip(EFFECTS, maps[1:], again)}
    else:
        baseline = stages.run("bake baseline", lambda p: _bake_map(sample, uvs, resolution, options, p))
    # The map the refinement reads: the plain map itself, or with first_samples
    # a bake of its own (the same seed, so at equal samples the same map).
    first_map = baseline
    if options.first_samples not in (None, options.samples):
        first_map = stages.run("bake first map", lambda p: _bake_map(
            sample, uvs, resolution, replace(options, samples=options.first_samples), p))
    tessellation = unsplit = None
    refine_options = options.refine_options
    if options.tessellate is not None:
        # Same surface, same lightmap mapping: the baseline bake stays valid and
        # every later bake and the ground truth use the split triangles.
        unsplit = sample
        refine_options = tessellated_refine_options(refine_options, uvs, triangles)
        sample, tessellation, to_unsplit = stages.run("tessellate", lambda p: _tessellated(
            sample, variant, first_map, options.tessellate))
        uvs, triangles = sample.layout(variant)
    # The user's padding, as the add-on passes it: refine_uvs keeps a tighter
    # input's pairs at their own distance and packs no closer than a texel.
    padding = float(options.padding)
    original_check = check_layout(uvs, triangles, resolution, padding)
    route = _route_mesh(sample, options)
    refined = stages.run("refine", lambda p: refine_uvs(first_map, uvs, triangles, resolution, padding=padding,
                                                        progress=p, **route, **refine_options))
    refined_map = stages.run("bake refined", lambda p: _bake_map(sample, refined.uvs, resolution, options, p))

    # Ground truth at area-uniform points, and at two neighbours each along
    # the surface for the transition detector.
    areas = sample.triangle_areas()
    density_base = metrics.texel_density(uvs, triangles, areas, resolution)
    density_refined = metrics.texel_density(refined.uvs, triangles, areas, resolution)
    if unsplit is None:
        points, stencil_points, stencil_normals, distances, median_texel = surface_points(sample, density_base,
                                                                                          options)
    else:
        # The points of the run without the split (same seed), found in its pieces: every split rule
        # and the plain refinement are measured at the same points against the same truth.
        unsplit_uvs, unsplit_triangles = unsplit.layout(variant)
        unsplit_density = metrics.texel_density(unsplit_uvs, unsplit_triangles, unsplit.triangle_areas(), resolution)
        points, stencil_points, stencil_normals, distances, median_texel = surface_points(unsplit, unsplit_density,
                                                                                          options)
        points = into_pieces(to_unsplit, points)
    step = 0.5 * median_texel
    scene = sample.to_scene(uvs)

    # With per_effect the truth is traced per effect, the combined light their sum.
    truth_passes = EFFECTS if options.per_effect else passes

    def truth_at(p):
        every_point = np.concatenate([points.points, stencil_points])
        every_normal = np.concatenate([points.normals, stencil_normals])
        first = evaluate_light(scene, every_point, every_normal, passes=truth_passes,
                               samples=options.truth_samples, seed=options.seed + 1, progress=p)
        # A second, independent estimate at the points: the truth is their
        # mean, and their difference measures the truth's own noise.
        second = evaluate_light(scene, points.points, points.normals, passes=truth_passes,
                                samples=options.truth_samples, seed=options.seed + 2, progress=p)
        if isinstance(first, dict):
            return {name: value.astype(np.float64) for name, value in first.items()}, \
                {name: value.astype(np.float64) for name, value in second.items()}
        return first.astype(np.float64), second.astype(np.float64)
    every_truth, second_truth = stages.run("ground truth", truth_at)
    effect_truth = None
    if isinstance(every_truth, dict):
        effect_truth = {name: (every_truth[name][:len(points)] + second_truth[name]) / 2 for name in EFFECTS}
        every_truth, second_truth = sum(every_truth.values()), sum(second_truth.values())
    truth = (every_truth[:len(points)] + second_truth) / 2
    neighbour_truth = every_truth[len(points):]
    truth_noise = metrics.truth_noise(every_truth[:len(points)], second_truth)
    gradient = metrics.surface_gradient(truth, neighbour_truth, distances)
    transitions = metrics.transition_mask(gradient)

    uv_base = metrics.interpolate_corners(uvs, points.triangle, points.bary)
    uv_refined = metrics.interpolate_corners(refined.uvs, points.triangle, points.bary)
    lookup_base = metrics.bilinear_lookup(baseline, uv_base)
    lookup_refined = metrics.bilinear_lookup(refined_map, uv_refined)
    stage_history = None
    first_rechart = refined.report.get("rechart")  # the first stage chose the layout the later ones refine
    if options.stages > 1:
        refined, refined_map, lookup_refined, stage_history = _further_stages(
            sample, triangles, resolution, padding, options, stages, points, truth, transitions, refined,
            refined_map, lookup_refined)
        uv_refined = metrics.interpolate_corners(refined.uvs, points.triangle, points.bary)
        density_refined = metrics.texel_density(refined.uvs, triangles, areas, resolution)

    # The uniform baseline at higher resolutions, for the equal-error resolution.
    sweep = _uniform_sweep(sample, uvs, uv_base, resolution, options, stages, "bake resolution sweep",
                           first=lookup_base)
    per_effect = per_effect_layouts = None
    if options.per_effect:
        per_effect, per_effect_layouts = _per_effect(sample, uvs, triangles, resolution, options, stages, points,
                                                     truth, effect_truth, transitions, first_bakes, sweep)

    # The re-charted maps against uniform bakes of the scene's own layouts.
    compared = []
    others = [v for v in options.compare_variants if v in sample.uvs] if options.rechart is not None else []
    if options.rechart is not None and options.compare_variants and not others:  # a .blend's one layout
        others = [v for v in sample.uvs if v != variant]
    for other in others:
        other_uvs, _ = sample.layout(other)
        other_points = metrics.interpolate_corners(other_uvs, points.triangle, points.bary)
        compared.append((other, _uniform_sweep(sample, other_uvs, other_points, resolution, options, stages,
                                               "bake comparison layouts")))
    # The second baseline: the input's charts packed at one common scale, no
    # signal. What it gains is packing; what the refined map gains beyond it, signal.
    uniform = stages.run("uniform repack", lambda p: _uniform_repack(sample, uvs, triangles, resolution,
                                                                     pack_padding(padding, original_check),
                                                                     options, points, p))

    start = time.perf_counter()
    charts = find_charts(uvs, triangles)
    texels = metrics.uv_areas(uvs, triangles) * resolution * resolution
    chart_texels = np.bincount(charts, weights=texels)

    def figures(where):
        base = metrics.error_stats(lookup_base, truth, where)
        ref = metrics.error_stats(lookup_refined, truth, where)
        base_t = metrics.error_stats(lookup_base, truth, where & transitions)
        ref_t = metrics.error_stats(lookup_refined, truth, where & transitions)
        sweep_rmse = [metrics.error_stats(s["lookup"], truth, where)["rmse"] for s in sweep]
        sweep_t = [metrics.error_stats(s["lookup"], truth, where & transitions)["rmse"] for s in sweep]
        ratio, status = metrics.equal_error_resolution(options.multipliers, sweep_rmse, ref["rmse"])
        ratio_t, status_t = metrics.equal_error_resolution(options.multipliers, sweep_t, ref_t["rmse"])
        interval = metrics.equal_error_interval(options.multipliers, sweep_rmse, ref["rmse"])
        return {
            "points": int(where.sum()),
            "transition_points": int((where & transitions).sum()),
            "rmse_baseline": base["rmse"], "rmse_refined": ref["rmse"],
            "mae_baseline": base["mae"], "mae_refined": ref["mae"],
            "transition_rmse_baseline": base_t["rmse"], "transition_rmse_refined": ref_t["rmse"],
            "transition_mae_baseline": base_t["mae"], "transition_mae_refined": ref_t["mae"],
            "transition_widening": metrics.transition_widening(density_base, density_refined, points.triangle,
                                                               where & transitions),
            "equal_error_resolution_ratio": ratio, "equal_error_status": status,
            "equal_error_interval": list(interval),
            "transition_equal_error_resolution_ratio": ratio_t, "transition_equal_error_status": status_t,
            "resolution_sweep": [{"resolution": s["resolution"], "multiplier": s["multiplier"], "rmse": e,
                                  "transition_rmse": et} for s, e, et in zip(sweep, sweep_rmse, sweep_t)],
        }

    def against(other_sweep):
        """Equal-error ratios of the plain and the refined map on this layout
        against the uniform bakes of another layout."""
        out = {"resolution_sweep": [{"resolution": s["resolution"]} for s in other_sweep]}
        for where, prefix in ((np.ones(len(points), bool), ""), (transitions, "transition_")):
            errors = [metrics.error_stats(s["lookup"], truth, where)["rmse"] for s in other_sweep]
            for row, error in zip(out["resolution_sweep"], errors):
                row[f"{prefix}rmse"] = error
            for name, lookup in (("baseline", lookup_base), ("refined", lookup_refined)):
                target = metrics.error_stats(lookup, truth, where)["rmse"]
                ratio, status = metrics.equal_error_resolution(options.multipliers, errors, target)
                out[f"{prefix}equal_error_resolution_ratio_{name}"] = ratio
                out[f"{prefix}equal_error_status_{name}"] = status
        return out

    everywhere = np.ones(len(points), bool)
    if uniform is not None:
        sweep_all = [metrics.error_stats(s["lookup"], truth, everywhere)["rmse"] for s in sweep]
        rmse = metrics.error_stats(uniform.pop("lookup"), truth, everywhere)["rmse"]
        ratio, status = metrics.equal_error_resolution(options.multipliers, sweep_all, rmse)
        uniform.update(rmse=rmse, equal_error_resolution_ratio=ratio, equal_error_status=status)
    result = {"scene": sample.name, "variant": options.layout_name, "resolution": resolution, "pass": passes,
              "description": sample.description, "bake_samples": options.samples,
              "first_samples": options.first_samples or options.samples,
              "truth_samples": options.truth_samples, "gradient_step_m": step, "texel_size_m": median_texel}
    result.update(figures(everywhere))
    result["layout"] = layout
    result["layout_comparison"] = [{"variant": variant, **against(other_sweep)} for variant, other_sweep in compared]
    # Texels across the light change, measured along the truth's gradient on the surface (a stretched
    # chart gains more across its edges than the square root of its area change).
    directions = metrics.surface_gradient_direction(points.points, truth, stencil_points, neighbour_truth)
    corner_positions = sample.positions[sample.triangles]
    result["transition_widening_linear"] = metrics.transition_widening_across(
        corner_positions, np.asarray(uvs)[triangles], np.asarray(refined.uvs)[triangles], points.triangle,
        directions, transitions, resolution)
    result["truth_mean"] = float(truth.mean())
    result["truth_noise_rmse"] = truth_noise
    object_ids = sample.object_id[points.triangle]
    result["objects"] = []
    for index, name in enumerate(sample.objects):
        where = object_ids == index
        if where.any():
            mine = sample.object_id == index  # the object's share of the map, refined against plain
            texel_share = float((areas[mine] * density_refined[mine]).sum()
                                / max((areas[mine] * density_base[mine]).sum(), 1e-300))
            result["objects"].append({"object": name, **{k: v for k, v in figures(where).items()
                                                         if k != "resolution_sweep"}, "texels": texel_share})
    on_transitions = points.triangle[transitions]
    context = {
        "refine_report": refined.report,
        # The split a coarse note would advise, tried only when a note is written.
        "split_trial": functools.lru_cache(maxsize=None)(lambda: _split_trial(sample, variant, first_map)),
        "texels_per_transition_triangle": float(np.median(texels[on_transitions])) if on_transitions.size else 0.0,
        "chart_texels_at_transitions": (float(np.median(chart_texels[charts[on_transitions]]))
                                        if on_transitions.size else 0.0),
    }
    result.update({k: v for k, v in context.items() if k not in ("refine_report", "split_trial")})
    result["refine"] = {k: v for k, v in refined.report.items() if k != "triangle_density"}
    result["refine"]["rechart"] = first_rechart
    if uniform is not None:
        ratio, refined_ratio = uniform["equal_error_resolution_ratio"], result["equal_error_resolution_ratio"]
        uniform["signal_gain"] = (refined_ratio / ratio if ratio and refined_ratio and ratio > 0 else None)
        result["uniform_repack"] = uniform
    if tessellation is not None:
        result["tessellation"] = {**tessellation, **_plain_refinement(
            unsplit, variant, first_map, to_unsplit, points, truth, transitions, sweep, resolution, padding,
            options, stages, result)}
    if stage_history is not None:
        result["stages"] = stage_history
    if per_effect is not None:
        result["per_effect"] = per_effect
    gain = (result["transition_rmse_refined"] <= (1 - GAIN_THRESHOLD) * result["transition_rmse_baseline"])
    result["gain"] = bool(gain)
    result["notes"] = [] if gain else _diagnose(result, context)
    if gain and options.tessellate is None and context["texels_per_transition_triangle"] >= COARSE_TRIANGLE_TEXELS \
            and light_contrast(baseline, coverage_mask(uvs, triangles, resolution)) >= COARSE_CONTRAST:
        # A gain, and a larger one within reach: the add-on's Tessellate advice, by the same rule.
        split = context["split_trial"]()
        if split is not None:
            result["notes"].append(_coarse_note(context["texels_per_transition_triangle"], split))
    if not gain and not result["notes"]:
        result["notes"].append("no cause found among tessellation, chart size and refiner limits")
    if result["equal_error_status"] == "flat":
        sweep_rmse = [s["rmse"] for s in result["resolution_sweep"]]
        result["notes"].append(
            f"noise-limited: the uniform baseline's error hardly falls with resolution ({sweep_rmse[0]:.4g} at "
            f"{resolution}, {sweep_rmse[-1]:.4g} at {result['resolution_sweep'][-1]['resolution']}), so there is no "
            f"equal-error resolution; bake with more --samples or --denoise (ground-truth noise: {truth_noise:.3g}, "
            "raise --truth-samples if that is close to the errors)")
    note = _ill_determined_note(result)
    if note:
        result["notes"].append(note)
    if result["rmse_refined"] > result["rmse_baseline"]:
        result["notes"].append("the error over all points grew: the texels taken from flat areas cost more there "
                               "than the transitions gained")
    worse = _objects_served_worse(result["objects"], truth_noise)
    if worse:
        result["notes"].append(worse)
    stages.seconds["metrics"] = time.perf_counter() - start

    if out_dir is not None:
        from .evaluation_report import write_pictures, write_scene_report
        os.makedirs(out_dir, exist_ok=True)
        # The maps and the refined layout themselves, for a closer look.
        write_image(os.path.join(out_dir, "baseline.exr"), np.ascontiguousarray(baseline), format="half")
        write_image(os.path.join(out_dir, "refined.exr"), np.ascontiguousarray(refined_map), format="half")
        np.savez_compressed(os.path.join(out_dir, "refined_layout.npz"), uvs=refined.uvs, triangles=triangles,
                            original_uvs=uvs)
        for (rule, name), effect_uvs in (per_effect_layouts or {}).items():
            np.savez_compressed(os.path.join(out_dir, f"per_effect_{rule}_{name}_layout.npz"), uvs=effect_uvs,
                                triangles=triangles, original_uvs=uvs)
        stages.run("pictures", lambda p: write_pictures(out_dir, result, {
            "baseline": baseline, "refined": refined_map, "uvs": uvs, "refined_uvs": refined.uvs,
            "triangles": triangles, "density_ratio": density_refined / np.maximum(density_base, 1e-30),
            "uv_points": uv_base, "error_baseline": np.abs(lookup_base - truth).mean(axis=1),
            "error_refined": np.abs(lookup_refined - truth).mean(axis=1), "transitions": transitions,
            "multipliers": options.multipliers}))
        if options.view_width:
            stages.run("surface pictures", lambda p: _surface_pictures(
                out_dir, result, sample, scene, {"plain": (baseline, uvs), "refined": (refined_map, refined.uvs)},
                {"plain": density_base, "refined": density_refined}, passes, options, p))
    result["timings"] = dict(stages.seconds)
    result["timings"]["total"] = sum(stages.seconds.values())
    result = _json_safe(result)
    if out_dir is not None:
        write_scene_report(out_dir, result)
    return result


def _surface_pictures(out_dir, result, sample, scene, maps, density, passes, options, progress):
    """The lit surface through the scene's camera (lmrefine.surface_view):
    pictures, and their figures in result["surface"]."""
    from .evaluation_report import write_surface_pictures
    from .surface_view import render_views

    views = render_views(sample, scene, maps, passes, options.truth_samples, options.view_width,
                         seed=options.seed + 3, progress=progress)
    write_surface_pictures(out_dir, result, views, density)
    result["surface"] = {
        "camera": views["camera"].name, "width": views["hits"].width, "height": views["hits"].height,
        "receiver_pixels": int(views["hits"].receiver.sum()),
        "rmse_plain": views["rmse"]["plain"], "rmse_refined": views["rmse"]["refined"],
        "crops": [{"row": row, "column": column, "size": size, "rmse_plain": errors["plain"],
                   "rmse_refined": errors["refined"]}
                  for (row, column, size), errors in zip(views["crops"], views["crop_rmse"])],
    }


def evaluate_samples(samples, options, out_dir, variants=None, progress=None):
    """Evaluate SampleScenes in UV `variants` (default: options.variant),
    one sub-folder <scene>_<variant> each, and write the summary report.md
    and report.json into `out_dir`. Returns the summary."""
    from .evaluation_report import write_summary

    os.makedirs(out_dir, exist_ok=True)
    scenes = []
    for sample in samples:
        # A scene exported from a .blend has one layout: its own lightmap UV map.
        for variant in ("own",) if list(sample.uvs) == ["own"] else variants or (options.variant,):
            scene_options = replace(options, variant=variant)
            scene_dir = os.path.join(out_dir, f"{sample.name}_{scene_options.layout_name}")
            scenes.append(evaluate_sample(sample, scene_options, scene_dir, progress))
    options.check()
    summary = {"resolution": int(options.resolution), "multipliers": list(options.multipliers),
               "bake_samples": options.samples, "truth_samples": options.truth_samples, "points": options.points,
               "scenes": scenes}
    write_summary(out_dir, summary)
    return summary
