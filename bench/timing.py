"""The benchmarks' timing: the least wall time of a few runs (the machines are
shared and noisy; the least is the run the other jobs disturbed least)."""

import time


def best_of(runs, work):
    """(the least wall time in seconds of `runs` calls of work(), the last call's result)."""
    times, result = [], None
    for _ in range(runs):
        start = time.perf_counter()
        result = work()
        times.append(time.perf_counter() - start)
    return min(times), result
