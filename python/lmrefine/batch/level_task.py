"""One level, run on a Dask worker: headless Blender into a fresh attempt folder.

The task never touches OUT/<level>/ itself: it writes into
OUT/.work/<level>/<attempt>/out and returns where; the batch driver (the only
writer of the manifest and of finished folders) renames it into place. So an
attempt that dies half-way leaves only its own attempt folder behind, and a
level is committed once even if Dask runs its task twice.
"""

import ctypes
import json
import os
import re
import signal
import socket
import subprocess
import time
import uuid

from .blender_command import blender_command, blender_environment, find_batch_script, find_blender

TOPIC = "lmrefine-batch"
PROGRESS_LINE = re.compile(r"^lmrefine:\s+(\d+)% (.*)$")


def work_dir(out_dir, name):
    return os.path.join(out_dir, ".work", name)


def _die_with_parent():
    """Blender is killed when its worker process dies (Linux), so a lost
    worker leaves no orphan Blender writing on."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def _emit(event):
    """Progress to the driver via Dask's event log (nothing outside a worker)."""
    try:
        from distributed import get_worker
        get_worker().log_event(TOPIC, event)
    except (ImportError, ValueError):
        pass


def _worker_address():
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return None


def _threads_here(threads):
    """`threads` is a number, or {host: workers on that host} for an existing
    cluster, where each worker's Blender gets its share of that host's cores."""
    if not isinstance(threads, dict):
        return threads
    try:
        from distributed import get_worker
        host = get_worker().address.split("://")[-1].rsplit(":", 1)[0]
    except (ImportError, ValueError):
        return None
    return max(1, (os.cpu_count() or 1) // max(1, threads.get(host, 1)))


def run_level(name, level_path, out_dir, flags, threads=None, blender=None, batch_script=None, evaluate=False):
    """Run one attempt; returns a result dict (never raises for a failed Blender).
    With `evaluate`, a refined level is also measured (evaluate_level)."""
    attempt = f"{time.strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:8]}"
    attempt_dir = os.path.join(work_dir(out_dir, name), attempt)
    target = os.path.join(attempt_dir, "out")
    os.makedirs(target)
    log_path = os.path.join(attempt_dir, "blender.log")
    threads = _threads_here(threads)
    result = {"name": name, "attempt": attempt, "attempt_dir": attempt_dir, "out": target, "log": log_path,
              "host": socket.gethostname(), "threads": threads, "worker": _worker_address()}
    started = time.perf_counter()
    _emit({"name": name, "state": "started", "fraction": 0.0, "stage": "starting Blender", "attempt": attempt})
    try:
        command = blender_command(find_blender(blender), find_batch_script(batch_script), level_path, target,
                                  flags, threads)
    except OSError as error:
        result.update(ok=False, retry=False, returncode=None, error=str(error),
                      seconds=time.perf_counter() - started)
        with open(log_path, "w", encoding="utf-8") as log:
            log.write(f"{error}\n")
        return result
    with open(log_path, "w", encoding="utf-8") as log:
        log.write("$ " + " ".join(command) + "\n")
        log.flush()
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                   env=blender_environment(threads), preexec_fn=_die_with_parent)
        try:
            for line in process.stdout:
                log.write(line)
                match = PROGRESS_LINE.match(line.strip())
                if match:
                    _emit({"name": name, "state": "running", "fraction": int(match.group(1)) / 100,
                           "stage": match.group(2), "attempt": attempt})
        finally:
            process.stdout.close()
            returncode = process.wait()
    result.update(returncode=returncode, seconds=time.perf_counter() - started)
    report_path = os.path.join(target, "report.json")
    report = None
    if os.path.isfile(report_path):
        try:
            with open(report_path, encoding="utf-8") as stream:
                report = json.load(stream)
        except ValueError:
            report = None
    if returncode == 0 and report and report.get("ok"):
        result.update(ok=True, retry=False, objects=len(report.get("objects", {})), error=None,
                      warnings=list(report.get("warnings", [])))
        if evaluate:
            _emit({"name": name, "state": "running", "fraction": 0.95, "stage": "evaluating", "attempt": attempt})
            result.update(evaluate_level(level_path, os.path.join(target, "evaluation"), flags, blender, log_path,
                                         objects=sorted(report.get("objects", {}))))
            result["seconds"] = time.perf_counter() - started
    elif report is not None and report.get("ok") is False:
        # batch.py ran and refused the level (its message): the same again would fail the same way.
        result.update(ok=False, retry=False, error=report.get("error", f"exit code {returncode}"))
    elif returncode == 2:
        # The flags are every level's: the runner stops the batch (runner._stop_after_refusal).
        result.update(ok=False, retry=False, flags_refused=True,
                      error=f"the add-on's batch entry refused the flags: {_refusal(log_path)}")
    else:
        how = f"killed by signal {-returncode}" if returncode < 0 else f"exit code {returncode}"
        result.update(ok=False, retry=True, error=f"Blender failed ({how}) without a report: {_tail(log_path)}")
    _emit({"name": name, "state": "finished", "fraction": 1.0, "stage": "done" if result["ok"] else "failed",
           "attempt": attempt})
    return result


# The add-on batch flags that say what the evaluation must measure: the same
# receivers, UV map and lightmap size.
EVALUATION_FLAGS = {"--objects": "--objects", "--source-layer": "--uv-map", "--resolution": "--resolution"}


def evaluate_level(level_path, out, flags, blender, log_path, objects=()):
    """`python3 -m lmrefine evaluate LEVEL.blend` into `out` (its report and
    pictures). Objects that share one atlas are measured together; when their
    lightmap maps are separate (one lightmap each, as the add-on bakes them),
    each of `objects` is measured on its own into out/<object>/ and the level's
    figure is the lowest (the object that gained least). Returns
    {"equal_error": ratio or None, "equal_error_objects": {...}} and, when it
    could not measure, "evaluation_error". A failed evaluation never fails the
    level: the refined outputs are there either way."""
    figure, why = _evaluate(level_path, out, flags, blender, log_path)
    if figure is not None or "cover the same part" not in (why or "") or len(objects) < 2:
        return {"equal_error": figure} if figure is not None else {"equal_error": None, "evaluation_error": why}
    per_object, problems = {}, []
    for name in objects:
        figure, why = _evaluate(level_path, os.path.join(out, name), flags, blender, log_path, only=name)
        per_object[name] = figure
        if figure is None:
            problems.append(f"{name}: {why}")
    measured = [f for f in per_object.values() if f is not None]
    result = {"equal_error": min(measured) if measured else None, "equal_error_objects": per_object}
    if problems:
        result["evaluation_error"] = "; ".join(problems)
    return result


def _evaluate(level_path, out, flags, blender, log_path, only=None):
    """One evaluate run; returns (equal-error ratio, None) or (None, why)."""
    import sys

    import lmrefine

    command = [sys.executable, "-m", "lmrefine", "evaluate", level_path, "--out", out]
    for index, flag in enumerate(flags[:-1]):
        if flag in EVALUATION_FLAGS and not (only and flag == "--objects"):
            command += [EVALUATION_FLAGS[flag], flags[index + 1]]
    if only:
        command += ["--objects", only]
    if blender:
        command += ["--blender", blender]
    package_root = os.path.dirname(os.path.dirname(os.path.abspath(lmrefine.__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH")) if p))
    with open(log_path, "a", encoding="utf-8") as log:
        log.write("$ " + " ".join(command) + "\n")
        log.flush()
        code = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, env=env).returncode
    try:
        with open(os.path.join(out, "report.json"), encoding="utf-8") as stream:
            scene = json.load(stream)["scenes"][0]
    except (OSError, ValueError, KeyError, IndexError):
        return None, f"the evaluation failed (exit code {code}): {_tail(log_path, 1)}"
    if scene.get("equal_error_status") == "flat":
        return None, "noise-limited: no equal-error resolution"
    return scene.get("equal_error_resolution_ratio"), None


def _refusal(log_path):
    """What argparse said when the add-on's batch entry refused its flags (the
    text after "error: ", without the usage lines before it), else the log's tail."""
    with open(log_path, encoding="utf-8", errors="replace") as stream:
        said = [line.strip().split(": error: ", 1)[1] for line in stream if ": error: " in line]
    return said[-1] if said else _tail(log_path)


def _tail(log_path, lines=3):
    """The last meaningful lines of a log, for an error message."""
    with open(log_path, encoding="utf-8", errors="replace") as stream:
        kept = [line.strip() for line in stream if line.strip() and not line.startswith("$ ")
                and line.strip() not in ("Blender quit",)]
    return " | ".join(kept[-lines:]) or "(no output)"
