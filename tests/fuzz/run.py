"""lmrefine's fuzz suite (`make fuzz`; a slice runs in `make test`).

    tests/fuzz/run.py [--cases N] [--seed S] [--jobs J] [--timeout T] [--blender-cases M]
    tests/fuzz/run.py --seed S --only INDEX      # rerun one case in this process, with its traceback

Random and hostile inputs to every public function of lmrefine, each case
in its own child process with a timeout (runner.py), then the Blender
add-on's operator on broken meshes in one headless Blender (blender_cases.py).
Prints the outcome counts; exits 1 when any outcome that must stay at zero
(crash, hang, other exception, invalid layout, input modified) occurred.
"""

import argparse
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
TESTS = os.path.dirname(HERE)
REPO = os.path.dirname(TESTS)
PYTHONPATH = os.environ.get("LMREFINE_PYTHONPATH") or os.path.join(REPO, "python")
sys.path[:0] = [PYTHONPATH, TESTS, HERE]

import runner  # noqa: E402


RERUN_BLENDER = ("blender -b --factory-startup --python tests/fuzz/blender_cases.py -- . /tmp/case.jsonl "
                 "{seed} {index} 1")


def run_blender_cases(count, seed, timeout):
    """The add-on cases in one Blender, restarted after a case that kills it; returns (Counter, examples)."""
    import json
    from collections import Counter

    blender = shutil.which("blender")
    if blender is None:
        return Counter({"skipped: Blender is not installed": count}), {}
    counts, examples, start = Counter(), {}, 0
    env = dict(os.environ, LMREFINE_FUZZ_DUMP_AFTER=str(max(1.0, timeout - 10)))
    log = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"lmrefine_fuzz_blender_{os.getpid()}.jsonl")
    while start < count:
        if os.path.exists(log):
            os.unlink(log)
        # Output goes to a file: a pipe nobody reads while the cases run would fill and block Blender.
        output_file = open(log + ".out", "w+")
        process = subprocess.Popen(
            [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
             os.path.join(HERE, "blender_cases.py"), "--", REPO, log, str(seed), str(start), str(count - start)],
            stdout=output_file, stderr=subprocess.STDOUT, env=env)
        # One case must finish within `timeout`: the log grows a line per case.
        done, last_change, size = start, time.monotonic(), -1
        while process.poll() is None:
            time.sleep(0.2)
            current = os.path.getsize(log) if os.path.exists(log) else 0
            if current != size:
                size, last_change = current, time.monotonic()
            elif time.monotonic() - last_change > timeout:
                process.kill()
                break
        process.wait()
        output_file.seek(0)
        output = output_file.read()
        output_file.close()
        os.unlink(log + ".out")
        lines = open(log).read().splitlines() if os.path.exists(log) else []
        results = [json.loads(line) for line in lines if line.startswith("{")]
        for result in results:
            if result.get("started"):
                continue
            counts[result["outcome"]] += 1
            if result["outcome"] not in ("ok", "skipped object") and not result["outcome"].startswith("refused"):
                examples.setdefault(result["outcome"], []).append((result["index"], result["detail"]))
        finished = {r["index"] for r in results if not r.get("started")}
        started = [r["index"] for r in results if r.get("started") and r["index"] not in finished]
        done = max(finished | {start - 1}) + 1
        if started:  # the case that was running when Blender died or hung
            index = started[-1]
            outcome = "hang" if process.returncode in (-9, None) else "crash"
            counts[outcome] += 1
            examples.setdefault(outcome, []).append((index, output[-6000:]))
            done = index + 1
        elif process.returncode != 0 and done < count:
            counts["harness error"] += 1
            examples.setdefault("harness error", []).append((done, output[-3000:]))
            break
        start = done
    if os.path.exists(log):
        os.unlink(log)
    return counts, examples


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", type=int, default=10000, help="API cases (default 10000)")
    parser.add_argument("--blender-cases", type=int, default=200, help="add-on cases in Blender (default 200)")
    parser.add_argument("--seed", type=int, default=int(time.time()) % 100000, help="default: from the clock")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per case (default 60)")
    parser.add_argument("--only", type=int, help="run this one API case here, printing its outcome")
    args = parser.parse_args(argv)

    if args.only is not None:
        import lmrefine
        outcome, detail = runner.run_case(lmrefine, args.seed, args.only)
        print(outcome)
        print(detail)
        return 0

    clock = time.perf_counter()
    counts, examples = runner.run(args.seed, args.cases, jobs=args.jobs, timeout=args.timeout)
    print("lmrefine API: " + runner.summary(counts, examples, args.seed))
    print(f"  ({time.perf_counter() - clock:.0f} s)")
    failed = runner.failures(counts)
    if args.blender_cases:
        clock = time.perf_counter()
        blender_counts, blender_examples = run_blender_cases(args.blender_cases, args.seed, args.timeout)
        print("Blender add-on: " + runner.summary(blender_counts, blender_examples, args.seed, RERUN_BLENDER))
        print(f"  ({time.perf_counter() - clock:.0f} s)")
        failed.update({f"blender {k}": v for k, v in runner.failures(blender_counts).items()})
    print("FAILED: " + ", ".join(f"{v} {k}" for k, v in failed.items()) if failed else "All targets met.")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
