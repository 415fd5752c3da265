"""Speed of the wavelet core against PyWavelets, measured in one run.

    PYTHONPATH=python /usr/bin/python3 bench/bench_wavelet.py [--sizes 1024 4096] [--repeats 3]

Rows:
  gradient map   lmrefine.gradient_map(img)            vs pywt.swt2(img, 'db2', level=1)
                 (both undecimated D4 details at every texel; ours adds the
                 absolute value, both senses and the run-aware borders)
  dwt2 d4        lmrefine.dwt2(img, 'd4')              vs pywt.dwt2(img, 'db2', mode='periodization')
Best of `repeats` wall-clock times on float32 images; ratio = pywt / lmrefine.
The cpu columns are process CPU time summed over all threads (lmrefine uses
every core, PyWavelets one): their ratio is the work per result, and it does
not move when other jobs share the machine, unlike the wall-clock ratio.
Both sides allocate fresh outputs every call, and page zeroing of those
(256 MB for a 4096^2 gradient map or swt2) is a large part of both times.
"""
import argparse
import os
import time

import numpy as np
import pywt

import lmrefine


def best_time(fn, repeats):
    """Best wall-clock and best process CPU time (all threads) of `repeats` calls."""
    wall = cpu = float("inf")
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return wall, cpu


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 4096])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    # Other work on the machine skews both columns; the load is printed so a
    # reader can tell a quiet run from a busy one.
    print(f"threads: {os.environ.get('LMREFINE_THREADS', os.cpu_count())}, pywt {pywt.__version__}, "
          f"best of {args.repeats}, load average {os.getloadavg()[0]:.1f}")
    print(f"{'case':<14} {'size':>9} {'lmrefine ms':>12} {'pywt ms':>10} {'ratio':>7}   "
          f"{'cpu: lmrefine':>13} {'pywt':>7} {'ratio':>6}")
    for size in args.sizes:
        # A smooth light field with a hard shadow edge and noise, float32.
        y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
        image = (0.5 + 0.4 * x + 0.2 * np.sin(6 * y) + 0.02 * rng.standard_normal((size, size))).astype(np.float32)
        image[:, size // 3:] *= 0.2
        cases = [
            ("gradient map", lambda: lmrefine.gradient_map(image),
             lambda: pywt.swt2(image, "db2", level=1)),
            ("dwt2 d4", lambda: lmrefine.dwt2(image, "d4"),
             lambda: pywt.dwt2(image, "db2", mode="periodization")),
        ]
        for name, ours, theirs in cases:
            (t_ours, c_ours), (t_theirs, c_theirs) = best_time(ours, args.repeats), best_time(theirs, args.repeats)
            print(f"{name:<14} {size:>4}x{size:<4} {t_ours * 1e3:>12.1f} {t_theirs * 1e3:>10.1f} "
                  f"{t_theirs / t_ours:>6.1f}x   {c_ours * 1e3:>13.1f} {c_theirs * 1e3:>7.1f} {c_theirs / c_ours:>5.1f}x")


if __name__ == "__main__":
    main()
