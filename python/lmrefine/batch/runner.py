"""The batch driver: decides what to run, submits one task per level, retries,
commits finished levels into OUT/<level>/ and keeps the manifest current.

The driver is the only writer of the manifest and of OUT/<level>/: workers
write into attempt folders under OUT/.work/ (see level_task), and a level's
folder appears by one rename once its report says it succeeded.
"""

import json
import os
import shutil
import sys
import time
import uuid
from dataclasses import dataclass, field

from .levels import find_levels, input_fingerprint
from .level_task import TOPIC, run_level, work_dir
from .manifest import Manifest, options_key
from .progress import BatchProgress, Ticker
from .summary import level_rows, summary_table, write_summary


@dataclass
class BatchOptions:
    flags: list = field(default_factory=list)  # the add-on batch entry's flags, passed as given
    workers: int = None
    scheduler: str = None
    force: bool = False
    retries: int = 2
    blender: str = None
    batch_script: str = None
    evaluate: bool = False  # also measure each level's equal-error resolution ratio (lmrefine evaluate)


def _rewrite_paths(value, old, new):
    if isinstance(value, str):
        return value.replace(old, new)
    if isinstance(value, dict):
        return {k: _rewrite_paths(v, old, new) for k, v in value.items()}
    if isinstance(value, list):
        return [_rewrite_paths(v, old, new) for v in value]
    return value


def _attempts_started(out_dir, name):
    folder = work_dir(out_dir, name)
    return len([d for d in os.listdir(folder) if not d.startswith("replaced")]) if os.path.isdir(folder) else 0


def _gather_logs(out_dir, name):
    """Every attempt's log of a level, oldest first, into OUT/logs/<level>.log."""
    folder = work_dir(out_dir, name)
    os.makedirs(os.path.join(out_dir, "logs"), exist_ok=True)
    path = os.path.join(out_dir, "logs", f"{name}.log")
    with open(path, "w", encoding="utf-8") as merged:
        for attempt in sorted(os.listdir(folder)) if os.path.isdir(folder) else []:
            log = os.path.join(folder, attempt, "blender.log")
            merged.write(f"===== attempt {attempt}\n")
            if os.path.isfile(log):
                with open(log, encoding="utf-8", errors="replace") as stream:
                    merged.write(stream.read())
            else:
                merged.write("(no log: the worker died before Blender started)\n")
    return path


def commit(out_dir, name, result):
    """Move a successful attempt's outputs into OUT/<name>/ (replacing an older
    run's); returns the outputs record."""
    final = os.path.join(out_dir, name)
    source = result["out"]
    report_path = os.path.join(source, "report.json")
    with open(report_path, encoding="utf-8") as stream:
        report = _rewrite_paths(json.load(stream), source, final)
    with open(report_path, "w", encoding="utf-8") as stream:
        json.dump(report, stream, indent=2)
    shutil.move(result["log"], os.path.join(source, "blender.log"))
    if os.path.exists(final):
        os.replace(final, os.path.join(work_dir(out_dir, name), f"replaced-{uuid.uuid4().hex[:8]}"))
    os.replace(source, final)
    shutil.rmtree(work_dir(out_dir, name), ignore_errors=True)
    images = {obj: info.get("images", {}) for obj, info in report.get("objects", {}).items()}
    # Which objects share which images (one atlas group each: docs/blender.md, "Shared atlas").
    atlases = {group: info.get("objects", []) for group, info in report.get("atlases", {}).items()}
    return {"dir": final, "blend": report.get("blend"), "report": os.path.join(final, "report.json"),
            "images": images, "atlases": atlases}


def _plan(levels, manifest, out_dir, flags, force, say):
    to_run, skipped = [], []
    for level in levels:
        record = manifest.record(level.name) or {}
        fingerprint = input_fingerprint(level.path, record.get("input"))
        run, reason = manifest.decide(level.name, fingerprint, flags, out_dir, force)
        if run:
            to_run.append((level, fingerprint, reason))
        else:
            skipped.append(level.name)
    if skipped:
        shown = ", ".join(skipped[:10]) + (f" and {len(skipped) - 10} more" if len(skipped) > 10 else "")
        say(f"skipping {len(skipped)} level(s) already done with the same input and options: {shown} "
            "(--force redoes them)")
    return to_run, skipped


def run_batch(inputs, out_dir, options, stream=None):
    """Run the batch; returns the summary dict (summary["ok"] is False when a level failed).
    Raises ValueError/OSError for bad inputs, KeyboardInterrupt after a clean stop."""
    stream = stream or sys.stderr
    started = time.perf_counter()
    levels = find_levels(inputs)
    out_dir = os.path.abspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    manifest = Manifest(out_dir)
    flags = list(options.flags)
    # What a level was done with: a run asking for the evaluation redoes levels done without it.
    recorded = flags + (["--evaluate"] if options.evaluate else [])
    progress = BatchProgress(len(levels), stream)
    to_run, skipped = _plan(levels, manifest, out_dir, recorded, options.force, progress.message)
    for level, fingerprint, reason in to_run:
        shutil.rmtree(work_dir(out_dir, level.name), ignore_errors=True)  # an interrupted run's attempts
        manifest.update(level.name, input={"path": level.path, **fingerprint}, options=recorded,
                        options_key=options_key(recorded), status="pending", reason=reason, attempts=0,
                        error=None)
    manifest.save()
    workers = 0
    if to_run:
        workers = _run_levels([level for level, _, _ in to_run], out_dir, flags, options, manifest, progress)
    progress.close()
    try:
        os.rmdir(os.path.join(out_dir, ".work"))  # only when no attempt is left in it
    except OSError:
        pass
    rows = level_rows(levels, manifest, set(skipped))
    summary = write_summary(out_dir, rows, time.perf_counter() - started, workers)
    print(summary_table(rows), file=stream)
    print(f"wrote {os.path.join(out_dir, 'summary.json')}", file=stream)
    return summary


def _run_levels(levels, out_dir, flags, options, manifest, progress):
    from distributed import wait
    from distributed.client import FIRST_COMPLETED

    from .cluster import Cluster

    by_name = {level.name: level for level in levels}
    cluster = Cluster(options.scheduler, options.workers, options.retries)
    try:
        progress.message(f"{len(levels)} level(s) on {cluster.workers} worker(s)"
                         + (f", {cluster.threads} thread(s) each" if isinstance(cluster.threads, int) else "")
                         + (f"; dashboard: {cluster.dashboard}" if cluster.dashboard else ""))
        cluster.client.subscribe_topic(TOPIC, lambda event: progress.event(
            event[1]["name"], event[1]["state"], event[1]["fraction"], event[1]["stage"]))

        def submit(level, exclude=None):
            others = [w for w in cluster.client.scheduler_info()["workers"] if w != exclude] if exclude else None
            return cluster.client.submit(
                run_level, level.name, level.path, out_dir, flags, cluster.threads, options.blender,
                options.batch_script, options.evaluate, key=f"lmrefine-batch-{level.name}-{uuid.uuid4().hex[:8]}", pure=False,
                **({"workers": others, "allow_other_workers": True} if others else {}))

        pending = {}
        for level in levels:
            pending[submit(level)] = level.name
            manifest.update(level.name, status="running")
        manifest.save()
        ticker = Ticker(progress.draw)
        try:
            while pending:
                try:
                    done, _ = wait(list(pending), timeout=0.2, return_when=FIRST_COMPLETED)
                except TimeoutError:  # nothing finished yet: redraw and wait again
                    done = ()
                ticker.tick()
                for future in done:
                    if future not in pending:  # cancelled by a refusal below
                        continue
                    name = pending.pop(future)
                    again, refused = _finish(future, name, out_dir, options, manifest, progress)
                    if again:
                        pending[submit(by_name[name], exclude=again)] = name
                    if refused:
                        _stop_after_refusal(pending, name, out_dir, manifest, progress)
                    manifest.save()
        except KeyboardInterrupt:
            for future in pending:
                future.cancel()
            for name in pending.values():
                manifest.update(name, status="interrupted", attempts=_attempts_started(out_dir, name))
            manifest.save()
            progress.message(f"interrupted: {len(pending)} level(s) left unfinished; run the same command "
                             "again to continue")
            raise
        return cluster.workers
    finally:
        cluster.close()


def _stop_after_refusal(pending, refused, out_dir, manifest, progress):
    """The add-on's batch entry refused the flags on level `refused`: they are
    every level's, so the levels still `pending` (future -> name) would fail
    the same way. Cancel them and record why they did not run; `pending` is
    emptied."""
    error = manifest.record(refused)["error"]
    for future, name in pending.items():
        future.cancel()  # a level already running finishes into its attempt folder, cleared by the next run
        manifest.update(name, status="not run", attempts=_attempts_started(out_dir, name), seconds=None,
                        error=f"{error} (on level '{refused}'; fix the flags and run again)",
                        log=None, outputs=None)
        progress.level_done(name, "not run", 0.0, "the flags were refused")
    if pending:
        progress.message(f"stopped: the flags were refused on '{refused}', so the {len(pending)} level(s) left "
                         "were not run")
    pending.clear()


def _finish(future, name, out_dir, options, manifest, progress):
    """Handle one finished task; returns (the worker to avoid when the level
    should run again, else None; whether the add-on refused the flags)."""
    attempts = _attempts_started(out_dir, name)
    try:
        result = future.result()
    except Exception as error:  # noqa: BLE001 - KilledWorker, a lost connection: the level may run again
        result = {"ok": False, "retry": True, "error": f"{type(error).__name__}: {error}", "seconds": None,
                  "worker": None}
    if result["ok"]:
        outputs = commit(out_dir, name, result)
        manifest.update(name, status="done", outputs=outputs, attempts=attempts, seconds=result["seconds"],
                        objects=result.get("objects"), warnings=result.get("warnings") or [],
                        log=os.path.join(outputs["dir"], "blender.log"),
                        error=None, host=result.get("host"), equal_error=result.get("equal_error"),
                        equal_error_objects=result.get("equal_error_objects"),
                        evaluation_error=result.get("evaluation_error"))
        progress.level_done(name, "done", result["seconds"],
                            f"attempt {attempts}" if attempts > 1 else "")
        return None, False
    if result["retry"] and attempts < 1 + options.retries:
        progress.message(f"{name}: attempt {attempts} failed ({result['error']}); retrying")
        return result.get("worker") or "-", False
    log = _gather_logs(out_dir, name)
    shutil.rmtree(work_dir(out_dir, name), ignore_errors=True)
    manifest.update(name, status="failed", attempts=attempts, seconds=result["seconds"], error=result["error"],
                    log=log, outputs=None)
    progress.level_done(name, "failed", result["seconds"] or 0.0, result["error"])
    return None, bool(result.get("flags_refused"))
