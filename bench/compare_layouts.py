"""Which starting layout gives the best lightmap: Lightmap Pack, Smart UV
Project or lmrefine.rechart, each baked plain and refined, all measured
against one reference, the plain Smart UV bake's resolution sweep.

Reads the report.json files of evaluation runs on the same scenes with the
same seed, points and multipliers (so the ground truth and the surface points
are the same in every run), for example:

    PYTHONPATH=python /usr/bin/python3 -m lmrefine evaluate courtyard atrium --variant both --out eval_inputs
    PYTHONPATH=python /usr/bin/python3 -m lmrefine evaluate courtyard atrium --rechart --out eval_rechart
    PYTHONPATH=python /usr/bin/python3 bench/compare_layouts.py eval_inputs eval_rechart

Prints one row per scene: the equal-error resolution ratio of each map
against the plain Smart UV bake (the Smart UV bake needs this times R to
match it; 1.00 = as good as plain Smart UV at R).
"""

import glob
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))

from lmrefine import metrics  # noqa: E402


def load_reports(folders):
    """{scene: {layout name: scene report}} from every <scene>_<layout>/report.json under the folders."""
    reports = {}
    for folder in folders:
        for path in sorted(glob.glob(os.path.join(folder, "*", "report.json"))):
            with open(path) as handle:
                report = json.load(handle)
            reports.setdefault(report["scene"], {})[report["variant"]] = report
    return reports


def ratio_text(multipliers, sweep, target):
    ratio, status = metrics.equal_error_resolution(multipliers, sweep, target)
    if status in ("flat", "undefined"):
        return status
    return {"above": ">=", "below": ""}.get(status, "") + f"{ratio:.2f}"


def main(folders):
    reports = load_reports(folders)
    layouts = sorted({name for scene in reports.values() for name in scene if name != "smart"})
    header = ["scene", "smart refined"] + [f"{name} {kind}" for name in layouts for kind in ("plain", "refined")]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for scene, by_layout in reports.items():
        smart = by_layout.get("smart")
        if smart is None:
            continue
        multipliers = [s["multiplier"] for s in smart["resolution_sweep"]]
        sweep = [s["rmse"] for s in smart["resolution_sweep"]]
        if smart["truth_mean"] != by_layout.get(layouts[0], smart)["truth_mean"]:
            print(f"(skipping {scene}: the runs' ground truths differ; same seed and points needed)")
            continue
        row = [scene, ratio_text(multipliers, sweep, smart["rmse_refined"])]
        for name in layouts:
            report = by_layout.get(name)
            row += (["n/a", "n/a"] if report is None else
                    [ratio_text(multipliers, sweep, report["rmse_baseline"]),
                     ratio_text(multipliers, sweep, report["rmse_refined"])])
        print("| " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__)
        sys.exit(2)
    sys.exit(main(sys.argv[1:]))
