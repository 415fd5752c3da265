"""Run every benchmark in bench/ (bench_*.py) in one process group.

Each benchmark measures lmrefine against a named baseline in the same run and
prints ratios (machines here are shared and noisy: absolute times mean little).

    PYTHONPATH=python /usr/bin/python3 bench/run.py [NAME ...]
"""

import glob
import os
import subprocess
import sys


def main(names):
    here = os.path.dirname(os.path.abspath(__file__))
    scripts = sorted(glob.glob(os.path.join(here, "bench_*.py")))
    if names:
        scripts = [s for s in scripts if any(n in os.path.basename(s) for n in names)]
    failed = []
    for script in scripts:
        print(f"== {os.path.basename(script)}", flush=True)
        if subprocess.call([sys.executable, script]) != 0:
            failed.append(os.path.basename(script))
    if failed:
        print("failed:", ", ".join(failed))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
