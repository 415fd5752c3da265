"""The end of a batch: a table on the terminal and OUT/summary.json."""

import os
import re

from .manifest import write_json_atomic

COLUMNS = ("level", "status", "seconds", "objects", "warnings", "attempts")
# The add-on's warnings for objects it left as they were (pipeline.py): "Skipped: 'NAME' ..." for an
# object, "Skipped: atlas 'GROUP' (A, B) could not be refined: ..." for the objects of a shared atlas.
_SKIPPED_ATLAS = re.compile(r"^Skipped: atlas '.*?' \((.+?)\) could not be refined")
_SKIPPED = re.compile(r"^Skipped: '(.+?)'[: ]")


def skipped_objects(warnings):
    """The names of the objects a level's run skipped, from its warnings."""
    names = []
    for warning in warnings or []:
        atlas, single = _SKIPPED_ATLAS.match(warning), _SKIPPED.match(warning)
        names += atlas.group(1).split(", ") if atlas else [single.group(1)] if single else []
    return names


def level_rows(levels, manifest, skipped):
    rows = []
    for level in levels:
        record = manifest.record(level.name) or {}
        status = record.get("status", "pending")
        if level.name in skipped and status == "done":
            status = "skipped (done before)"
        rows.append({"level": level.name, "status": status, "seconds": record.get("seconds"),
                     "objects": record.get("objects"), "attempts": record.get("attempts"),
                     "warnings": record.get("warnings"), "skipped_objects": skipped_objects(record.get("warnings")),
                     "equal_error": record.get("equal_error"), "equal_error_objects": record.get("equal_error_objects"),
                     "evaluation_error": record.get("evaluation_error"),
                     "error": record.get("error"), "log": record.get("log"), "outputs": record.get("outputs")})
    return rows


def summary_table(rows):
    """The terminal table; the equal-error column only when some level was evaluated."""
    def cell(row, key):
        value = row[key]
        if value is None:
            return "-"
        if key == "equal_error":
            return f"{value:.2f}x"
        if key == "warnings":
            return str(len(value))
        return f"{value:.1f}" if isinstance(value, float) else str(value)

    columns = COLUMNS + (("equal_error",) if any(row.get("equal_error") is not None or row.get("evaluation_error")
                                                 for row in rows) else ())
    table = [[("equal-error" if key == "equal_error" else key) for key in columns]]
    table += [[cell(row, key) for key in columns] for row in rows]
    widths = [max(len(line[i]) for line in table) for i in range(len(columns))]
    lines = ["  ".join(text.ljust(width) for text, width in zip(line, widths)).rstrip() for line in table]
    lines.insert(1, "  ".join("-" * width for width in widths))
    for row in rows:
        if row["status"] in ("failed", "not run"):
            lines.append(f"{row['level']}: {row['error']}" + (f" (log: {row['log']})" if row["log"] else ""))
        elif row.get("evaluation_error"):
            lines.append(f"{row['level']}: not measured: {row['evaluation_error']}")
        if row.get("skipped_objects"):
            where = (row.get("outputs") or {}).get("report") or row.get("log")
            lines.append(f"{row['level']}: {len(row['skipped_objects'])} object(s) skipped, not refined: "
                         f"{', '.join(row['skipped_objects'])} (why, and every warning: {where})")
    return "\n".join(lines)


def write_summary(out_dir, rows, wall_seconds, workers):
    counts = {}
    for row in rows:
        key = "skipped" if row["status"].startswith("skipped") else row["status"]
        counts[key] = counts.get(key, 0) + 1
    summary = {"levels": rows, "counts": counts, "wall_seconds": wall_seconds, "workers": workers,
               "ok": counts.get("failed", 0) == 0 and all(r["status"] in ("done", "skipped (done before)")
                                                          for r in rows)}
    write_json_atomic(os.path.join(out_dir, "summary.json"), summary)
    return summary
