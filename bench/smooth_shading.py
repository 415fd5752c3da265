"""The re-chart route on smooth-shaded meshes: shading normals given to it or not
(docs/refiner.md, "Smooth-shaded meshes").

    PYTHONPATH=python /usr/bin/python3 bench/smooth_shading.py courtyard atrium [--variant both] [--resolution 256]

Every bundled sample is flat-shaded. This writes a copy of each scene named
with its shading normals auto-smoothed as Blender's Auto Smooth does (a
corner's normal is the area-weighted mean of the faces at its vertex whose
normals are within --auto-smooth degrees of its own face's; columns, arches
and ramps turn smooth, box corners stay sharp), then runs `lmrefine evaluate`
on the copy twice: with the route given the shading normals (as the add-on
and evaluate give them), and without (every crease counted as a step in the
light, as before the route read them). The baker and the ground truth use
the smooth normals in both runs. Prints the equal-error ratio, whether the
route re-charted, and the folds it saw.
"""

import argparse
import json
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))

from lmrefine import cli, evaluation  # noqa: E402
from lmrefine.sample_scenes import SAMPLES_DIR  # noqa: E402


def auto_smooth(path, out_path, angle):
    """Writes the scene .npz at `path` to `out_path` with auto-smoothed
    per-corner normals; returns the fraction of corners whose normal changed."""
    data = dict(np.load(path))
    corners = data["positions"].astype(np.float64)[data["triangles"].astype(np.int64)]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    unit = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-30)[:, None]
    _, vertex = np.unique(np.round(corners.reshape(-1, 3), 5), axis=0, return_inverse=True)
    order = np.argsort(vertex, kind="stable")
    starts = np.flatnonzero(np.r_[True, vertex[order][1:] != vertex[order][:-1]])
    normals = np.repeat(unit, 3, axis=0)
    cos_limit = np.cos(np.radians(angle))
    for begin, end in zip(starts, np.r_[starts[1:], len(order)]):
        at_vertex = order[begin:end]
        faces = at_vertex // 3
        joined = (unit[faces] @ unit[faces].T >= cos_limit).astype(np.float64) @ cross[faces]
        normals[at_vertex] = joined / np.maximum(np.linalg.norm(joined, axis=1), 1e-30)[:, None]
    changed = float(((normals * np.repeat(unit, 3, axis=0)).sum(axis=1) < 0.9999).mean())
    meta = json.loads(str(data["meta"]))
    meta["name"] = os.path.splitext(os.path.basename(out_path))[0]
    data.update(normals=normals.astype(np.float32), meta=np.array(json.dumps(meta)))
    np.savez_compressed(out_path, **data)
    return changed


def evaluate(path, out, variant, resolution, with_normals):
    route_mesh = evaluation._route_mesh
    if not with_normals:
        evaluation._route_mesh = lambda sample, options: {**route_mesh(sample, options), "normals": None}
    try:
        cli.main(["evaluate", path, "--variant", variant, "--resolution", str(resolution), "--view-width", "0",
                  "--out", out])
    finally:
        evaluation._route_mesh = route_mesh
    with open(os.path.join(out, "report.json")) as file:
        return json.load(file)["scenes"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--variant", default="both", choices=("smart", "lightmap", "both"))
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--auto-smooth", type=float, default=60.0)
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name in args.scenes:
            path = os.path.join(folder, f"{name}_smooth.npz")
            changed = auto_smooth(os.path.join(SAMPLES_DIR, f"{name}.npz"), path, args.auto_smooth)
            for with_normals in (False, True):
                out = os.path.join(folder, f"{name}_{with_normals}")
                for scene in evaluate(path, out, args.variant, args.resolution, with_normals):
                    rechart = scene["refine"]["rechart"] or {}
                    folds = rechart.get("folds") or {}
                    rows.append((name, f"{changed:.0%}", scene["variant"], "given" if with_normals else "not given",
                                 f"{scene['equal_error_resolution_ratio']:.2f}x", "yes" if rechart.get("used") else "no",
                                 str(rechart.get("charts", "")),
                                 f"{folds['count']} ({folds.get('smooth', 0)} smooth)" if folds else "",
                                 f"{folds['energy_fraction']:.1%}" if folds else ""))
    print(f"| scene (auto smooth {args.auto_smooth:g} deg, {args.resolution}^2) | smooth corners | UVs | "
          "normals to the route | equal-error ratio | re-charted | charts | folds (smooth-shaded) | folds' light changes |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
