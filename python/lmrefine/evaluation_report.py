"""Pictures, report.md and report.json of an evaluation (lmrefine.evaluation).

Pictures (matplotlib, Agg backend, one PNG each):

    lightmaps.png            baseline and refined lightmaps side by side, same exposure
    layout.png               the refined layout (red) over the original one (grey)
    density.png              texel density, refined over baseline, per triangle (log2 scale)
    error.png                absolute error at the surface points, baseline and refined
    error_vs_resolution.png  baseline error against resolution, the refined map's at R
    surface.png              the lit surface seen by a camera: plain lightmap, refined lightmap
                             (same resolution), ground truth; the crops' places marked
    surface_crops.png        close-ups where the ground truth changes most (shadow edges)
    surface_density.png      texels per metre on the surface, plain layout and refined layout
"""

import json
import math
import os

import numpy as np

PICTURES = ("lightmaps.png", "layout.png", "density.png", "error.png", "error_vs_resolution.png")
SURFACE_PICTURES = ("surface.png", "surface_crops.png", "surface_density.png")
# The three lit-surface pictures, left to right.
SURFACE_PANELS = (("plain", "plain lightmap"), ("refined", "refined lightmap, same resolution"),
                  ("truth", "ground truth"))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _display(image, scale):
    return np.clip(image[..., :3] / scale, 0, 1) ** (1 / 2.2) if scale > 0 else np.zeros_like(image[..., :3])


def _uv_axes(axis, title):
    axis.set_xlim(0, 1)
    axis.set_ylim(0, 1)
    axis.set_aspect("equal")
    axis.set_title(title, fontsize=10)
    axis.set_xticks([])
    axis.set_yticks([])


def _edges(uvs, triangles):
    corners = np.asarray(uvs)[np.asarray(triangles)]
    return np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]])


def write_pictures(out_dir, result, data):
    plt = _pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.tri import Triangulation

    resolution = result["resolution"]
    scale = float(np.percentile(data["baseline"], 99.5)) or 1.0

    figure, axes = plt.subplots(1, 2, figsize=(12, 6.4))
    for axis, key, title in ((axes[0], "baseline", "baseline (uniform layout)"),
                             (axes[1], "refined", "refined layout, re-baked")):
        axis.imshow(_display(data[key], scale), extent=(0, 1, 0, 1), interpolation="nearest")
        _uv_axes(axis, f"{title}, {resolution}x{resolution}")
    figure.suptitle(f"{result['scene']} ({result['variant']}): lightmaps at the same resolution")
    figure.tight_layout()
    figure.savefig(os.path.join(out_dir, "lightmaps.png"), dpi=110)
    plt.close(figure)

    figure, axis = plt.subplots(figsize=(8, 8))
    axis.add_collection(LineCollection(_edges(data["uvs"], data["triangles"]), colors="0.65", linewidths=0.3))
    axis.add_collection(LineCollection(_edges(data["refined_uvs"], data["triangles"]), colors="tab:red",
                                       linewidths=0.3))
    _uv_axes(axis, f"{result['scene']} ({result['variant']}): refined layout (red) over the original (grey)")
    figure.tight_layout()
    figure.savefig(os.path.join(out_dir, "layout.png"), dpi=150)
    plt.close(figure)

    figure, axis = plt.subplots(figsize=(8.6, 8))
    ratio = np.log2(np.clip(data["density_ratio"], 1 / 64, 64))
    limit = max(1.0, float(np.abs(ratio).max()))
    uv = np.asarray(data["refined_uvs"])
    shading = axis.tripcolor(Triangulation(uv[:, 0], uv[:, 1], data["triangles"]), facecolors=ratio,
                             cmap="RdBu_r", norm=TwoSlopeNorm(0.0, -limit, limit))
    bar = figure.colorbar(shading, ax=axis, fraction=0.046)
    bar.set_label("log2(texel density refined / baseline)")
    _uv_axes(axis, f"texel density change (transition widening {result['transition_widening']:.2f}x)"
             if result["transition_widening"] is not None else "texel density change")
    figure.tight_layout()
    figure.savefig(os.path.join(out_dir, "density.png"), dpi=110)
    plt.close(figure)

    figure, axes = plt.subplots(1, 2, figsize=(13, 6.4))
    vmax = float(np.percentile(np.concatenate([data["error_baseline"], data["error_refined"]]), 99.5)) or 1.0
    points = data["uv_points"]
    for axis, key, rmse in ((axes[0], "error_baseline", result["rmse_baseline"]),
                            (axes[1], "error_refined", result["rmse_refined"])):
        order = np.argsort(data[key])  # large errors drawn last, on top
        shading = axis.scatter(points[order, 0], points[order, 1], c=data[key][order], s=1.5, cmap="inferno",
                               vmin=0, vmax=vmax, linewidths=0)
        _uv_axes(axis, f"{key.replace('error_', '')}: RMSE {rmse:.4g} (points at their original UVs)")
        axis.set_facecolor("0.85")
    figure.colorbar(shading, ax=axes, fraction=0.03).set_label("mean absolute error (RGB) at the point")
    figure.suptitle(f"{result['scene']} ({result['variant']}): world-space error against the ground truth")
    figure.savefig(os.path.join(out_dir, "error.png"), dpi=110)
    plt.close(figure)

    figure, axis = plt.subplots(figsize=(7.5, 5))
    sweep = result["resolution_sweep"]
    sizes = [s["resolution"] for s in sweep]
    for key, refined_key, ratio_key, colour, label in (
            ("rmse", "rmse_refined", "equal_error_resolution_ratio", "tab:blue", "all points"),
            ("transition_rmse", "transition_rmse_refined", "transition_equal_error_resolution_ratio",
             "tab:orange", "transition points")):
        values = [s[key] for s in sweep]
        axis.plot(sizes, values, "o-", color=colour, label=f"uniform baseline, {label}")
        refined = result[refined_key]
        if refined is not None:
            axis.plot([resolution], [refined], "*", color=colour, markersize=14, markeredgecolor="k",
                      label=f"refined at {resolution}, {label}")
            ratio = result[ratio_key]
            if ratio is not None:
                axis.plot([resolution, resolution * ratio], [refined, refined], "--", color=colour, linewidth=1)
                axis.annotate(f"{ratio:.2f}x", (resolution * ratio, refined), textcoords="offset points",
                              xytext=(4, 4), color=colour)
    axis.set_xscale("log", base=2)
    axis.set_xticks(sizes)
    axis.set_xticklabels([str(s) for s in sizes])
    axis.set_xlabel("lightmap resolution (texels per side)")
    axis.set_ylabel("RMSE against the ground truth")
    axis.set_title(f"{result['scene']} ({result['variant']}): error against resolution")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(os.path.join(out_dir, "error_vs_resolution.png"), dpi=110)
    plt.close(figure)


def write_surface_pictures(out_dir, result, views, density):
    """surface.png, surface_crops.png and surface_density.png from
    surface_view.render_views; `density` = {"plain": (T,), "refined": (T,)}
    texels per square metre of every receiver triangle."""
    plt = _pyplot()
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    hits, pictures, crops = views["hits"], views["pictures"], views["crops"]
    resolution = result["resolution"]
    title = f"{result['scene']} ({result['variant']}), camera '{views['camera'].name}'"
    aspect = hits.width / hits.height
    figure, axes = plt.subplots(1, 3, figsize=(15, 15 / 3 / aspect + 0.9))
    for axis, (key, label) in zip(axes, SURFACE_PANELS):
        axis.imshow(pictures[key], interpolation="nearest")
        if key == "truth":
            label = f"{label} ({result['truth_samples']} samples per pixel)"
        else:
            label = f"{label}, {resolution}x{resolution}: RMSE {_number(views['rmse'][key], 3)}"
        axis.set_title(label, fontsize=10)
        for index, (row, column, size) in enumerate(crops):
            axis.add_patch(Rectangle((column - 0.5, row - 0.5), size, size, fill=False, edgecolor="tab:orange",
                                     linewidth=1.2))
            axis.annotate(str(index + 1), (column, row), color="tab:orange", fontsize=9, xytext=(2, 9),
                          textcoords="offset points")
        axis.set_xticks([])
        axis.set_yticks([])
    figure.suptitle(f"{title}: the lit surface (RMSE against the ground truth over the pixels)")
    figure.tight_layout()
    figure.savefig(os.path.join(out_dir, "surface.png"), dpi=110)
    plt.close(figure)

    rows = max(1, len(crops))
    figure, axes = plt.subplots(rows, 3, figsize=(10.5, 3.6 * rows), squeeze=False)
    for index, (row, column, size) in enumerate(crops):
        for axis, (key, label) in zip(axes[index], SURFACE_PANELS):
            axis.imshow(pictures[key][row:row + size, column:column + size], interpolation="nearest")
            if key != "truth":
                label = f"{label}: RMSE {_number(views['crop_rmse'][index][key], 3)}"
            axis.set_title(f"{index + 1}: {label}", fontsize=9)
            axis.set_xticks([])
            axis.set_yticks([])
    if not crops:
        for axis in axes[0]:
            axis.set_axis_off()
        axes[0][1].text(0.5, 0.5, "no light transition in view", ha="center", va="center")
    figure.suptitle(f"{title}: where the light changes most")
    figure.tight_layout()
    figure.savefig(os.path.join(out_dir, "surface_crops.png"), dpi=110)
    plt.close(figure)

    per_metre = {key: hits.per_triangle(np.sqrt(np.maximum(values, 0.0))) for key, values in density.items()}
    shown = np.concatenate([v[np.isfinite(v) & (v > 0)] for v in per_metre.values()])
    low, high = (np.percentile(shown, [1, 99]) if shown.size else (1.0, 2.0))
    norm = LogNorm(max(low, 1e-6), max(high, low * 1.01, 1e-6))
    figure, axes = plt.subplots(1, 2, figsize=(12, 12 / 2 / aspect + 1.0), constrained_layout=True)
    colours = plt.get_cmap("viridis")
    # Shaded by how squarely the camera sees the surface, so the shapes stay
    # readable where the density is uniform.
    shade = (0.55 + 0.45 * np.clip(hits.facing, 0.0, 1.0))[:, None]
    for axis, key, label in ((axes[0], "plain", "plain layout"), (axes[1], "refined", "refined layout")):
        values = per_metre[key]
        image = np.full((len(values), 3), 0.2)
        shown_here = np.isfinite(values) & (values > 0)
        image[shown_here] = colours(norm(values[shown_here]))[:, :3] * shade[shown_here]
        axis.imshow(image.reshape(hits.height, hits.width, 3), interpolation="nearest")
        axis.set_title(f"{label}, {resolution}x{resolution}", fontsize=10)
        axis.set_xticks([])
        axis.set_yticks([])
    from matplotlib.cm import ScalarMappable
    shading = ScalarMappable(norm=norm, cmap=colours)
    figure.colorbar(shading, ax=axes, fraction=0.025, shrink=0.9).set_label("texels per metre (log scale)")
    figure.suptitle(f"{title}: texel density on the surface")
    figure.savefig(os.path.join(out_dir, "surface_density.png"), dpi=110)
    plt.close(figure)


def _first_samples(r):
    """The first bake's samples, where they differ from the other bakes'."""
    first = r.get("first_samples", r["bake_samples"])
    return "" if first == r["bake_samples"] else f" ({first} for the first bake, the map the refinement reads)"


def _number(value, digits=4):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"


def _change(before, after):
    if before is None or after is None or not before:
        return "n/a"
    return f"{(after / before - 1) * 100:+.1f}%"


def equal_error_text(ratio, status):
    if ratio is None:
        return "n/a"
    if status == "above":
        return f">= {ratio:.2f}x (better than the baseline at the largest resolution tested)"
    if status == "flat":
        return "undefined (the baseline's error hardly falls with resolution: noise-limited)"
    if status == "below":
        return f"{ratio:.2f}x (below 1: worse than the baseline at the same resolution)"
    return f"{ratio:.2f}x"


def _backoff_text(refine):
    kept = refine.get("backoff", 1.0)
    if kept >= 1.0:
        return "kept its full deformation everywhere"
    area = refine.get("backoff_area")
    where = f" over {area * 100:.0f}% of the grid" if area is not None else ""
    return f"backed off{where}, down to {kept * 100:.0f}% of the full deformation"


def layout_text(r):
    """Which layout the baseline and refined maps were baked on."""
    layout = r.get("layout") or {}
    if layout.get("source") != "rechart":
        text = f"Layout: the scene's own `{layout.get('variant', r['variant'])}` lightmap UVs."
        rechart = (r.get("refine") or {}).get("rechart") or {}
        if rechart.get("used"):
            room, folds = rechart["room"], rechart.get("folds") or {}
            if room["no_room"]:
                why = (f"the source gives the refiner no room ({room['charts']} charts for {room['triangles']} "
                       f"triangles, {room['room_fraction']:.0%} of its area in triangles with a UV inside their "
                       "chart)")
            elif rechart.get("always"):
                charts = f"{room['charts']} chart" + ("s were" if room["charts"] != 1 else " was")
                why = f"the source's {charts} one face each before the tessellation split their triangles"
            else:
                why = (f"the source's charts fold over {folds.get('count', 0)} creases holding "
                       f"{folds.get('energy_fraction', 0.0):.0%} of the first bake's light changes")
            text += (f" The refined map's layout was **re-charted from the mesh** by refine_uvs (the route a user "
                     f"gets): {why}, so {rechart['charts']} charts at {rechart['angle']:g} degrees were "
                     f"refined; the model predicted {rechart['predicted_error']:.2f} of the source's error. The "
                     "baseline is the source layout baked plain.")
            if rechart.get("edge_room") is not None:
                kept = "kept" if rechart["edge_room"] else "not kept"
                text += (" The first packing's refinement had its automaton fit reset a region (every chart edge "
                         "rigid, the charts exactly the padding apart), so they were packed half a texel farther "
                         f"apart and refined again: {kept}.")
        elif rechart.get("room", {}).get("no_room"):
            text += f" Not re-charted although the source gives no room: {rechart.get('reason')}."
        return text
    check = layout.get("layout") or {}
    return (f"Layout: **re-charted from the mesh** (`--rechart {layout['angle']:g}`, `lmrefine.rechart`), not the "
            f"scene's own UVs: {layout['charts']} charts ({layout['split_charts']} split because their unwrap "
            f"folded, {layout['degenerate_triangles']} degenerate triangles), texel density spread "
            f"{_number(layout['density_spread'], 3)}x, mean angle error {_number(layout['angle_error_deg_mean'], 2)} "
            f"degrees, {_number(layout['utilisation'] * 100, 3)}% of the texels covered, "
            f"{'valid' if check.get('valid') else 'NOT valid'} at padding {layout['padding']:g}. "
            "The baseline and the refined map both use it.")


def _ratio_text(ratio, status):
    if ratio is None or status in ("flat", "undefined"):
        return "n/a" if status != "flat" else "noise-limited"
    return {"above": ">=", "below": ""}.get(status, "") + f"{ratio:.2f}x"


def comparison_lines(r):
    """The re-charted maps against uniform bakes of the scene's own layouts."""
    rows = r.get("layout_comparison") or []
    if not rows:
        return []
    lines = ["", "## Against the scene's own layouts", "",
             f"Equal-error resolution: the uniform bake on the scene's layout needs this times {r['resolution']} to "
             "match the map on the re-charted layout (all points / transition points).", "",
             f"| scene's layout | its RMSE at {r['resolution']} | re-charted, plain bake | re-charted + refined |",
             "|---|---|---|---|"]
    for c in rows:
        lines.append(
            f"| {c['variant']} | {_number(c['resolution_sweep'][0]['rmse'])} | "
            f"{_ratio_text(c['equal_error_resolution_ratio_baseline'], c['equal_error_status_baseline'])} / "
            f"{_ratio_text(c['transition_equal_error_resolution_ratio_baseline'], c['transition_equal_error_status_baseline'])} | "
            f"{_ratio_text(c['equal_error_resolution_ratio_refined'], c['equal_error_status_refined'])} / "
            f"{_ratio_text(c['transition_equal_error_resolution_ratio_refined'], c['transition_equal_error_status_refined'])} |")
    return lines


def per_effect_lines(r, heading="## Separate layouts for separate effects"):
    """The per-effect maps added up against the one combined map of the same
    total texels (lmrefine.per_effect), one row per split rule."""
    pe = r.get("per_effect")
    if not pe:
        return []
    lines = ["", heading, "",
             f"Each effect ({' + '.join(pe['effects'])}) refined from its own first bake and baked at its own "
             f"resolution, added up at the points, against the combined map refined at {r['resolution']}^2 "
             f"(RMSE {_number(r['rmse_refined'])}, transitions {_number(r['transition_rmse_refined'])}, equal-error "
             f"{_ratio_text(r['equal_error_resolution_ratio'], r['equal_error_status'])}). Equal-error ratios of the "
             "sum against the combined uniform bakes; of each effect against its own uniform bakes at its own "
             "resolution.", "",
             "| split | resolutions | texels / R^2 | RMSE plain -> refined | transition RMSE plain -> refined | "
             "equal-error (transitions) | per effect: equal-error |", "|---|---|---|---|---|---|---|"]
    for rule in pe["rules"]:
        effects = rule["effects"]
        lines.append(
            f"| {rule['rule']} | " + " + ".join(f"{name} {e['resolution']}^2 ({e['fraction']:.0%})"
                                               for name, e in effects.items()) +
            f" | {rule['texel_fraction']:.3f} | {_number(rule['rmse_plain'])} -> {_number(rule['rmse_refined'])} | "
            f"{_number(rule['transition_rmse_plain'])} -> {_number(rule['transition_rmse_refined'])} | "
            f"{_ratio_text(rule['equal_error_resolution_ratio'], rule['equal_error_status'])} "
            f"({_ratio_text(rule['transition_equal_error_resolution_ratio'], rule['transition_equal_error_status'])})"
            " | " + ", ".join(f"{name} {_ratio_text(e['equal_error_resolution_ratio'], e['equal_error_status'])}"
                              for name, e in effects.items()) + " |")
    return lines


def per_effect_summary(summary):
    """One line per scene and split rule in the summary report.md."""
    lines = []
    for r in summary["scenes"]:
        for rule in (r.get("per_effect") or {}).get("rules", []):
            lines.append(
                f"- {r['scene']} ({r['variant']}) per-effect layouts, split `{rule['rule']}` ("
                + " + ".join(f"{name} {e['resolution']}^2" for name, e in rule["effects"].items())
                + f" = {rule['texel_fraction']:.3f} R^2): RMSE {_number(rule['rmse_refined'])} against "
                f"{_number(r['rmse_refined'])} for one combined refined map "
                f"({_change(r['rmse_refined'], rule['rmse_refined'])}); equal-error "
                f"{_ratio_text(rule['equal_error_resolution_ratio'], rule['equal_error_status'])} against "
                f"{_ratio_text(r['equal_error_resolution_ratio'], r['equal_error_status'])}.")
    return lines


def repack_lines(repack):
    """The report's lines on how the chart repack was packed: the scales
    softened to their square roots, the chart stretch and its candidate."""
    lines = []
    softened = (repack or {}).get("softened")
    if softened and softened["used"]:
        refused = softened["refused"]
        lines.append(f"- Chart scales: at the model's scales the atlas packed too loosely ("
                     f"{refused['padded_utilisation_after']:.0%} full with its gutters, the input "
                     f"{refused['padded_utilisation_before']:.0%}); their square roots were packed and kept.")
    stretched = (repack or {}).get("stretch")
    if stretched:
        first = (stretched.get("candidates") or [{}])[0].get("largest_stretch", stretched["largest_stretch"])
        half = stretched["used"] and stretched.get("kind") == "half"
        lines.append(f"- Chart stretch: {stretched['charts_stretched']} chart(s) stretched across their light "
                     f"changes, up to {stretched['largest_stretch']:.2f}x; " + (
                         "kept" if stretched["used"] else f"not kept ({stretched.get('reason', '')})") + (
                         f", {stretched['charts_turned']} of them turned to their smallest boxes"
                         if stretched.get("charts_turned") else "") + (
                         ", each along its chart's u or v axis (stretched along the light changes' own directions "
                         "the atlas packed too loosely)" if stretched.get("kind") == "axes" else "") + (
                         f" (each at the square root of its factor: stretched fully, up to {first:.2f}x, the "
                         f"atlas packed too loosely)" if half else "") + ".")
    return lines


def scene_markdown(result):
    r = result
    lines = [
        f"# {r['scene']} ({r['variant']} UVs) at {r['resolution']}x{r['resolution']}",
        "",
        r.get("description", ""),
        "",
        f"Pass `{r['pass']}`, {r['bake_samples']} bake samples per texel{_first_samples(r)}, ground truth from "
        f"{r['truth_samples']} samples (twice) at {r['points']} surface points ({r['transition_points']} transition "
        f"points: top decile of the surface gradient, step {r['gradient_step_m'] * 1000:.1f} mm); the ground truth's "
        f"own noise is {_number(r['truth_noise_rmse'], 3)} RMS.",
        "",
        layout_text(r),
        "",
        "| | baseline | refined | change |",
        "|---|---|---|---|",
    ]
    for label, key in (("RMSE, all points", "rmse"), ("MAE, all points", "mae"),
                       ("RMSE, transition points", "transition_rmse"), ("MAE, transition points", "transition_mae")):
        before, after = r[f"{key}_baseline"], r[f"{key}_refined"]
        lines.append(f"| {label} | {_number(before)} | {_number(after)} | {_change(before, after)} |")
    lines += [
        "",
        f"- Transition widening (texel density at transition points, refined / baseline): "
        f"**{_number(r['transition_widening'], 3)}x** in area, {_number(r['transition_widening_linear'], 3)}x "
        "in texels across an edge.",
        f"- Equal-error resolution (the uniform baseline needs this times the resolution to match the refined "
        f"map): **{equal_error_text(r['equal_error_resolution_ratio'], r['equal_error_status'])}** over all points, "
        f"{equal_error_text(r['transition_equal_error_resolution_ratio'], r['transition_equal_error_status'])} "
        "on transition points.",
        f"- Refiner: {_backoff_text(r['refine'])}, limited by: "
        f"{', '.join(r['refine'].get('limited_by') or []) or 'nothing'}.",
        "",
    ]
    lines[-1:-1] = repack_lines(r["refine"].get("repack"))
    if r.get("uniform_repack"):
        u = r["uniform_repack"]
        gain = f"{u['signal_gain']:.2f}x" if u.get("signal_gain") else "n/a"
        lines[-1:-1] = [f"- Second baseline, the input's charts repacked at one scale (no signal; texels covered "
                        f"{u['utilisation_before']:.0%} -> {u['utilisation_after']:.0%}): equal-error "
                        f"{equal_error_text(u['equal_error_resolution_ratio'], u['equal_error_status'])} from "
                        f"packing alone; the refined map's ratio over it (signal gain): {gain}."]
    if r.get("stages"):
        rows = "; ".join(f"stage {e['stage']}: " + (f"RMSE {_number(e['rmse'])}, transitions "
                                                     f"{_number(e['transition_rmse'])}" if e["kept"] else
                                                     f"not kept (layout change {e['layout_change']:.1%})")
                         for e in r["stages"]["stages"])
        inside = ("; the later stages refined inside the charts only (the source layout has no room)"
                  if r["stages"].get("repack") is False else "")
        lines[-1:-1] = [f"- Multi-stage refinement: {rows}; stopped: {r['stages']['stopped']}{inside}."]
    if r.get("tessellation"):
        t = r["tessellation"]
        lines[-1:-1] = [f"- Tessellated along transitions before refining: {t['vertices_before']} -> "
                        f"{t['vertices_after']} vertices (+{t['vertices_added']}, budget {t['vertex_budget']}), "
                        f"{t['triangles_before']} -> {t['triangles_after']} triangles in {t['rounds']} rounds; "
                        f"stopped: {t['stopped']}."]
        if "plain_equal_error_resolution_ratio" in t:
            gain = f"{t['gain_over_plain']:.2f}x" if t.get("gain_over_plain") else "n/a"
            lines[-1:-1] = [f"- The plain refinement (the same scene unsplit, refined from the same bake) at the same "
                            f"points: RMSE {_number(t['plain_rmse'])}, equal-error "
                            f"{equal_error_text(t['plain_equal_error_resolution_ratio'], t['plain_equal_error_status'])}"
                            f"; the tessellated refinement's ratio over it: {gain}."]
    if r["gain"]:
        lines.append(f"**Gain**: transition-point RMSE {_change(r['transition_rmse_baseline'], r['transition_rmse_refined'])}.")
        lines += [f"- {note}" for note in r["notes"]]
    else:
        lines.append("**No gain on this scene.** Why:")
        lines += [f"- {note}" for note in r["notes"]]
    lines += comparison_lines(r)
    lines += per_effect_lines(r)
    lines += ["", "## Error against resolution (uniform baseline)", "",
              "| resolution | RMSE | transition RMSE |", "|---|---|---|"]
    for s in r["resolution_sweep"]:
        lines.append(f"| {s['resolution']} | {_number(s['rmse'])} | {_number(s['transition_rmse'])} |")
    lines += ["", "## Per object", "",
              "| object | points | transition points | RMSE base | RMSE refined | transition RMSE base | "
              "transition RMSE refined | widening | texels, refined / plain | equal-error ratio |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for o in r["objects"]:
        ratio = o["equal_error_resolution_ratio"]
        lines.append(
            f"| {o['object']} | {o['points']} | {o['transition_points']} | {_number(o['rmse_baseline'])} | "
            f"{_number(o['rmse_refined'])} | {_number(o['transition_rmse_baseline'])} | "
            f"{_number(o['transition_rmse_refined'])} | {_number(o['transition_widening'], 3)} | "
            f"{_number(o.get('texels'), 3)} | "
            f"{'n/a' if ratio is None else ('>=' if o['equal_error_status'] == 'above' else '') + f'{ratio:.2f}'} |")
    lines += ["", "## Time per stage (seconds)", "", "| stage | seconds |", "|---|---|"]
    lines += [f"| {stage} | {seconds:.2f} |" for stage, seconds in r["timings"].items()]
    lines += surface_markdown(r)
    lines += ["", "## Pictures", ""]
    lines += [f"![{name}]({name})" for name in PICTURES]
    lines.append("")
    return "\n".join(lines)


def surface_markdown(r, folder="", heading="## The lit surface"):
    """The report's section on the pictures of the lit surface (none when they were not made)."""
    surface = r.get("surface")
    if not surface:
        return []
    lines = ["", heading, "",
             f"Camera '{surface['camera']}', {surface['width']}x{surface['height']} pixels: the surfaces lit by the "
             f"plain lightmap, by the refined lightmap at the same resolution ({r['resolution']}x{r['resolution']}) "
             f"and by the ground truth at every pixel. RMSE against the ground truth over the pixels: plain "
             f"{_number(surface['rmse_plain'], 3)}, refined {_number(surface['rmse_refined'], 3)} "
             f"({_change(surface['rmse_plain'], surface['rmse_refined'])}).", "",
             f"![surface]({folder}surface.png)", ""]
    if surface["crops"]:
        lines += ["Where the light changes most (crops marked in the picture above):", "",
                  "| crop | RMSE plain | RMSE refined | change |", "|---|---|---|---|"]
        lines += [f"| {i + 1} | {_number(c['rmse_plain'], 3)} | {_number(c['rmse_refined'], 3)} | "
                  f"{_change(c['rmse_plain'], c['rmse_refined'])} |" for i, c in enumerate(surface["crops"])]
        lines += ["", f"![crops]({folder}surface_crops.png)", ""]
    lines += ["Texels per metre on the surface, plain and refined layout:", "",
              f"![texel density]({folder}surface_density.png)"]
    return lines


def write_scene_report(out_dir, result):
    with open(os.path.join(out_dir, "report.json"), "w") as handle:
        json.dump(result, handle, indent=2)
    with open(os.path.join(out_dir, "report.md"), "w") as handle:
        handle.write(scene_markdown(result))


def _uniform_text(r):
    """The uniform repack's equal-error ratio (the second baseline), or why there is none."""
    u = r.get("uniform_repack")
    if not u or u["equal_error_resolution_ratio"] is None:
        return "n/a"
    if u["equal_error_status"] == "flat":
        return "noise-limited"
    return {"above": ">="}.get(u["equal_error_status"], "") + f"{u['equal_error_resolution_ratio']:.2f}x"


def summary_table(summary):
    """The Markdown table of every evaluated scene (also printed by the CLI)."""
    lines = ["| scene | UVs | R | RMSE base -> refined | transition RMSE base -> refined | widening | "
             "equal-error ratio | packing alone | gain | seconds |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in summary["scenes"]:
        ratio = r["equal_error_resolution_ratio"]
        ratio_text = "n/a" if ratio is None else {"above": ">=", "below": ""}.get(r["equal_error_status"], "") + \
            f"{ratio:.2f}x"
        if r["equal_error_status"] == "flat":
            ratio_text = "noise-limited"
        lines.append(
            f"| {r['scene']} | {r['variant']} | {r['resolution']} | {_number(r['rmse_baseline'])} -> "
            f"{_number(r['rmse_refined'])} ({_change(r['rmse_baseline'], r['rmse_refined'])}) | "
            f"{_number(r['transition_rmse_baseline'])} -> {_number(r['transition_rmse_refined'])} "
            f"({_change(r['transition_rmse_baseline'], r['transition_rmse_refined'])}) | "
            f"{_number(r['transition_widening'], 3)}x | {ratio_text} | {_uniform_text(r)} | "
            f"{'yes' if r['gain'] else 'NO'} | "
            f"{r['timings']['total']:.1f} |")
    return "\n".join(lines)


def write_summary(out_dir, summary):
    with open(os.path.join(out_dir, "report.json"), "w") as handle:
        json.dump(summary, handle, indent=2)
    lines = ["# lmrefine evaluation", "",
             f"Uniform baseline against refined layout at the same resolution; baseline also at "
             f"{', '.join(f'{m:g}' for m in summary['multipliers'])} x R for the equal-error resolution. "
             f"{summary['bake_samples']} bake samples per texel, ground truth from {summary['truth_samples']} "
             f"samples at {summary['points']} surface points per scene. Definitions: docs/evaluation.md.", "",
             summary_table(summary), ""]
    for r in summary["scenes"]:
        for c in r.get("layout_comparison") or []:
            lines.append(
                f"- {r['scene']} ({r['variant']}) against the scene's `{c['variant']}` layout baked uniformly: "
                f"equal-error ratio {_ratio_text(c['equal_error_resolution_ratio_baseline'], c['equal_error_status_baseline'])} "
                f"plain, {_ratio_text(c['equal_error_resolution_ratio_refined'], c['equal_error_status_refined'])} "
                "refined.")
    lines += per_effect_summary(summary)
    for r in summary["scenes"]:
        t = r.get("tessellation") or {}
        if "plain_equal_error_resolution_ratio" in t:
            gain = f"{t['gain_over_plain']:.2f}x" if t.get("gain_over_plain") else "n/a"
            lines.append(f"- {r['scene']} ({r['variant']}) tessellated (+{t['vertices_added']} vertices): equal-error "
                         f"ratio {_ratio_text(r['equal_error_resolution_ratio'], r['equal_error_status'])} against "
                         f"the plain refinement's "
                         f"{_ratio_text(t['plain_equal_error_resolution_ratio'], t['plain_equal_error_status'])} at "
                         f"the same points: **{gain}** over plain.")
    for r in summary["scenes"]:
        if not r["gain"]:
            lines.append(f"- **{r['scene']} ({r['variant']}) shows no gain**: " + "; ".join(r["notes"]) + ".")
        elif r["notes"]:
            lines.append(f"- {r['scene']} ({r['variant']}): " + "; ".join(r["notes"]) + ".")
    if any(r.get("surface") for r in summary["scenes"]):
        lines += ["", "## The lit surface"]
    for r in summary["scenes"]:
        lines += surface_markdown(r, f"{r['scene']}_{r['variant']}/", f"### {r['scene']} ({r['variant']})")
    lines += ["", "Per scene: " + ", ".join(f"[{r['scene']}_{r['variant']}]({r['scene']}_{r['variant']}/report.md)"
                                            for r in summary["scenes"]), ""]
    with open(os.path.join(out_dir, "report.md"), "w") as handle:
        handle.write("\n".join(lines))
