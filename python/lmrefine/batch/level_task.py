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


def run_level(name, level_path, out_dir, flags, threads=None, blender=None, batch_script=None):
    """Run one attempt; returns a result dict (never raises for a failed Blender)."""
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
        result.update(ok=True, retry=False, objects=len(report.get("objects", {})), error=None)
    elif report is not None and report.get("ok") is False:
        # batch.py ran and refused the level (its message): the same again would fail the same way.
        result.update(ok=False, retry=False, error=report.get("error", f"exit code {returncode}"))
    elif returncode == 2:
        result.update(ok=False, retry=False, error=f"the add-on's batch entry refused the flags: {_tail(log_path)}")
    else:
        how = f"killed by signal {-returncode}" if returncode < 0 else f"exit code {returncode}"
        result.update(ok=False, retry=True, error=f"Blender failed ({how}) without a report: {_tail(log_path)}")
    _emit({"name": name, "state": "finished", "fraction": 1.0, "stage": "done" if result["ok"] else "failed",
           "attempt": attempt})
    return result


def _tail(log_path, lines=3):
    """The last meaningful lines of a log, for an error message."""
    with open(log_path, encoding="utf-8", errors="replace") as stream:
        kept = [line.strip() for line in stream if line.strip() and not line.startswith("$ ")
                and line.strip() not in ("Blender quit",)]
    return " | ".join(kept[-lines:]) or "(no output)"
