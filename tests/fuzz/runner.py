"""Runs fuzz cases, each in its own child process with a timeout, and sorts
the outcomes.

The parent imports lmrefine once but never calls it (so it holds no native
threads), then forks one child per case, `jobs` at a time: a fork costs about
a millisecond, where a fresh interpreter would cost a second. The child
builds the case from (seed, index), runs it, judges the result and writes
one JSON line to a pipe; its stderr goes to a file the parent keeps only when
the child dies. Outcomes:

    ok                      returned, and the result keeps its promises
    promised <type>         raised ValueError, TypeError, OSError, MemoryError
                            or lmrefine.CancelledError (or the callback's own error)
    crash                   the child died (signal, abort, sanitizer report)
    hang                    the child outlived the timeout and was killed
    other exception <type>  raised anything else
    invalid layout          refine_uvs returned a layout worse than its input
    unclear message <type>  a promised exception with an empty message or pybind11's
                            generic wording, which names no argument
    input modified          an argument's contents changed
    harness error           the case itself could not be built (a bug in the suite)
"""

import faulthandler
import json
import os
import re
import select
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter

import numpy as np

PROMISED = ("ValueError", "TypeError", "OSError", "MemoryError", "CancelledError")
TARGET_ZERO = ("crash", "hang", "other exception", "invalid layout", "input modified", "scene modified",
               "good object not refined", "unclear message", "harness error")
# pybind11's own wording for a failed cast: it names no argument (the bindings read arguments with
# py_util's readers, which do).
UNCLEAR = re.compile(r"incompatible function arguments|Unable to cast|cannot create a pybind11")


def _snapshot(value, depth=0):
    """A comparable copy of everything inside `value` that a call could modify."""
    if depth > 3:
        return None
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            return ("object", value.shape, repr(value.tolist()))
        if value.size * value.itemsize > 1 << 26:  # a zero-stride view of a huge shape: its one base
            return ("view", value.shape, value.strides, _snapshot(value.base, depth + 1))
        return ("array", value.shape, value.dtype.str, np.ascontiguousarray(value).tobytes())
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, [_snapshot(v, depth + 1) for v in value])
    if isinstance(value, dict):
        return ("dict", {k: _snapshot(v, depth + 1) for k, v in value.items()})
    return None


def _judge_layout(lm, case, result):
    """Why the returned layout breaks its function's promise, or None."""
    from lmrefine.backoff import worse_than_source

    uvs, triangles, resolution, padding = case.layout
    if case.recharted:  # a new per-corner layout: valid with the padding
        out = np.asarray(result.uvs)
        count = len(np.asarray(triangles))
        if out.shape != (3 * count, 2) or not np.isfinite(out).all():
            return f"uvs shape {out.shape} (or non-finite) for {count} triangles"
        corners = np.arange(3 * count).reshape(-1, 3)
        check = lm.check_layout(out, corners, resolution, padding=padding)
        return None if check["valid"] else f"recharted layout not valid: {check}"
    uvs = np.asarray(uvs, np.float32)
    triangles = np.asarray(triangles)
    out = np.asarray(result.uvs)
    if out.shape != uvs.shape:
        return f"uvs shape {out.shape} for input {uvs.shape}"
    if not np.isfinite(out).all():
        return "non-finite uvs"
    # With its chart lists, which worse_than_source's overlap rule reads (without them it checks the input again).
    source = lm.check_layout(uvs, triangles, resolution, padding=padding, failing_charts=True)
    if case.packed:  # pack_charts moves charts rigidly: it adds no fault, leaves none out of bounds, keeps the gutter
        check = lm.check_layout(out, triangles, resolution, padding=padding)
        worse = [key for key in ("flipped", "degenerate", "overlapping") if check[key] > source[key]]
        if check["out_of_bounds"]:
            worse.append("out_of_bounds")
        clean = not (source["degenerate"] or source["overlapping"])
        if clean and check["min_gutter_texels"] < padding - 1e-3:
            worse.append(f"gutter {check['min_gutter_texels']:.3f} < padding {padding}")
        return f"packed layout worse than its input: {worse}" if worse else None
    worse, _ = worse_than_source(out, uvs, triangles, resolution, padding, source=source)
    return f"worse than the source: {worse}" if worse else None


def run_case(lm, seed, index):
    """(outcome, detail) of case (seed, index), run in this process."""
    import api_cases
    import hostile

    try:
        case = api_cases.build(lm, seed, index)
    except Exception:  # noqa: BLE001
        return "harness error", traceback.format_exc(limit=4)
    before = [_snapshot(value) for value in case.inputs]
    outcome, detail = "ok", case.description
    try:
        result = case.call()
    except hostile.CallbackError:
        outcome = "promised CallbackError"
    except lm.CancelledError:
        outcome = "promised CancelledError"
    except (ValueError, TypeError, OSError, MemoryError) as error:
        outcome, detail = f"promised {type(error).__name__}", f"{case.description}: {error}"
        if UNCLEAR.search(str(error)) or not str(error).strip():
            outcome = f"unclear message {type(error).__name__}"
    except Exception as error:  # noqa: BLE001
        outcome = f"other exception {type(error).__name__}"
        detail = f"{case.description}: {traceback.format_exc(limit=6)}"
    else:
        if case.layout is not None:
            problem = _judge_layout(lm, case, result)
            if problem:
                outcome, detail = "invalid layout", f"{case.description}: {problem}"
    after = [_snapshot(value) for value in case.inputs]
    if before != after:
        changed = [i for i, (b, a) in enumerate(zip(before, after)) if b != a]
        outcome, detail = "input modified", f"{case.description}: arguments {changed} changed"
    return outcome, detail


def _child(lm, seed, index, write_fd, stderr_path):
    """In the forked child: run one case, write its outcome, exit without cleanup.

    The case's own temporary folders go under the run's scratch folder (the
    folder of stderr_path), which the parent removes: the child exits
    without running any cleanup.
    """
    try:
        tempfile.tempdir = os.path.dirname(stderr_path)
        fd = os.open(stderr_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(fd, 2)
        os.dup2(fd, 1)
        faulthandler.enable(file=2)  # a crash's Python traceback goes to this case's file (pytest's goes elsewhere)
        try:
            outcome, detail = run_case(lm, seed, index)
        except BaseException:  # noqa: BLE001  (the judging itself failed)
            outcome, detail = "harness error", traceback.format_exc(limit=6)
        os.write(write_fd, json.dumps([outcome, str(detail)[:2000]]).encode() + b"\n")
    finally:
        os._exit(0)


def run(seed, count, jobs=2, timeout=30.0, start=0, on_result=None, fresh=True):
    """Runs cases start .. start+count-1; returns (Counter of outcomes, {outcome: [(index, detail)]}).

    fresh: fork the cases from a new interpreter that has never called
    lmrefine (a process that has, like pytest after the baker's tests, holds
    Embree's and the thread pool's threads, and a fork of it can deadlock);
    the parent only collects the outcomes.
    """
    if fresh:
        return _run_in_fresh_process(seed, count, jobs, timeout, start, on_result)
    import lmrefine as lm

    os.environ.setdefault("LMREFINE_THREADS", "1")  # `jobs` children share the cores
    counts = Counter()
    examples = {}
    scratch = tempfile.mkdtemp(prefix="lmrefine_fuzz_")
    running = {}  # read fd -> (pid, index, deadline, stderr path, chunks)
    pending = iter(range(start, start + count))
    exhausted = False

    def record(index, outcome, detail):
        counts[outcome] += 1
        bucket = outcome if outcome.split(" ")[0] != "promised" and outcome != "ok" else None
        if bucket is not None:
            examples.setdefault(bucket, []).append((index, detail))
        if on_result is not None:
            on_result(index, outcome, detail)

    while running or not exhausted:
        while not exhausted and len(running) < jobs:
            index = next(pending, None)
            if index is None:
                exhausted = True
                break
            read_fd, write_fd = os.pipe()
            stderr_path = os.path.join(scratch, f"{index}.err")
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                os.close(read_fd)
                _child(lm, seed, index, write_fd, stderr_path)
            os.close(write_fd)
            running[read_fd] = (pid, index, time.monotonic() + timeout, stderr_path, [])
        if not running:
            break
        wait = max(0.0, min(deadline for _, _, deadline, _, _ in running.values()) - time.monotonic())
        ready, _, _ = select.select(list(running), [], [], min(wait, 1.0))
        now = time.monotonic()
        for fd in list(running):
            pid, index, deadline, stderr_path, chunks = running[fd]
            if fd in ready:
                data = os.read(fd, 65536)
                if data:
                    chunks.append(data)
                    continue
                # EOF: the child has exited (or closed the pipe dying).
                _, status = os.waitpid(pid, 0)
                os.close(fd)
                del running[fd]
                text = b"".join(chunks).decode(errors="replace").strip()
                if text and os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0:
                    outcome, detail = json.loads(text)
                else:
                    outcome = "crash"
                    how = (f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status)
                           else f"exit status {os.WEXITSTATUS(status)}")
                    detail = f"{how}; stderr: {_tail(stderr_path)}"
                _remove(stderr_path)
                record(index, outcome, detail)
            elif now > deadline:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                os.close(fd)
                del running[fd]
                _remove(stderr_path)
                record(index, "hang", f"still running after {timeout:.0f} s")
    shutil.rmtree(scratch, ignore_errors=True)
    return counts, examples


def _run_in_fresh_process(seed, count, jobs, timeout, start, on_result):
    import subprocess

    command = [sys.executable, os.path.abspath(__file__), str(seed), str(count), str(jobs), str(timeout), str(start)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True,
                               env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)))
    counts, examples = Counter(), {}
    for line in process.stdout:
        index, outcome, detail = json.loads(line)
        counts[outcome] += 1
        if outcome != "ok" and not outcome.startswith("promised"):
            examples.setdefault(outcome, []).append((index, detail))
        if on_result is not None:
            on_result(index, outcome, detail)
    if process.wait() != 0:
        counts["harness error"] += 1
        examples.setdefault("harness error", []).append((-1, f"the case server exited with {process.returncode}"))
    return counts, examples


def _serve(argv):
    """`runner.py SEED COUNT JOBS TIMEOUT START`: run the cases here, one JSON line per outcome on stdout."""
    seed, count, jobs, timeout, start = int(argv[0]), int(argv[1]), int(argv[2]), float(argv[3]), int(argv[4])
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:0] = [here, os.path.dirname(here)]

    def emit(index, outcome, detail):
        sys.stdout.write(json.dumps([index, outcome, detail]) + "\n")
        sys.stdout.flush()

    run(seed, count, jobs=jobs, timeout=timeout, start=start, on_result=emit, fresh=False)


def _tail(path, limit=1500):
    try:
        with open(path, "rb") as file:
            return file.read()[-limit:].decode(errors="replace")
    except OSError:
        return ""


def _remove(path):
    try:
        os.unlink(path)
    except OSError:
        pass


RERUN_API = "tests/fuzz/run.py --seed {seed} --only {index}"


def summary(counts, examples, seed, rerun=RERUN_API):
    """The outcome counts as printed lines, and the failures with how to rerun one."""
    lines = [f"{sum(counts.values())} cases (seed {seed}):"]
    for outcome, number in sorted(counts.items(), key=lambda item: (item[0] != "ok", item[0])):
        lines.append(f"  {number:7d}  {outcome}")
    for category in TARGET_ZERO:
        total = sum(n for outcome, n in counts.items() if outcome.startswith(category))
        lines.append(f"  target 0 {category}: {total}")
    for outcome, cases in sorted(examples.items()):
        for index, detail in cases[:3]:
            lines.append(f"  - {outcome}, case {index} (rerun: {rerun.format(seed=seed, index=index)}):")
            lines.append("      " + detail.strip().replace("\n", "\n      ")[:1500])
    return "\n".join(lines)


def failures(counts):
    return {outcome: n for outcome, n in counts.items() if outcome.startswith(TARGET_ZERO)}


if __name__ == "__main__":
    _serve(sys.argv[1:])
