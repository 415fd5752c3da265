"""The native parallel loop (native/src/core/parallel.cpp, on oneTBB): loops
from several Python threads at once, in a child made by fork() (which runs
them serially) and with changing thread counts give the results of a lone
serial run."""

import os
import signal
import threading

import numpy as np
import pytest

import lmrefine


def _inputs(seed, shape=(90, 70)):
    rng = np.random.default_rng(seed)
    return (rng.random(shape) ** 3).astype(np.float32), rng.random(shape) < 0.9


def _serial(energy, mask, monkeypatch):
    monkeypatch.setenv("LMREFINE_THREADS", "1")
    result = lmrefine.run_automaton(energy, mask)
    monkeypatch.delenv("LMREFINE_THREADS")
    return result


def test_loops_from_several_python_threads_at_once(monkeypatch):
    inputs = [_inputs(seed) for seed in range(4)]
    expected = [_serial(energy, mask, monkeypatch)["grid"] for energy, mask in inputs]
    monkeypatch.setenv("LMREFINE_THREADS", "2")
    results = [None] * len(inputs)

    def work(k):
        for _ in range(3):  # overlap the calls (the GIL is released inside)
            results[k] = lmrefine.run_automaton(*inputs[k])["grid"]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(len(inputs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "a loop never finished (pool deadlock)"
    for got, want in zip(results, expected):
        np.testing.assert_array_equal(got, want)


def test_growing_and_shrinking_thread_counts(monkeypatch):
    energy, mask = _inputs(5)
    want = _serial(energy, mask, monkeypatch)["grid"]
    for threads in ("3", "2", "6", "1", "2"):
        monkeypatch.setenv("LMREFINE_THREADS", threads)
        np.testing.assert_array_equal(lmrefine.run_automaton(energy, mask)["grid"], want)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_a_forked_child_runs_parallel_loops(monkeypatch):
    energy, mask = _inputs(6)
    monkeypatch.setenv("LMREFINE_THREADS", "2")
    want = lmrefine.run_automaton(energy, mask)["grid"]  # oneTBB's workers now run in the parent
    pid = os.fork()
    if pid == 0:  # the child: none of the parent's workers exist here, its loops run serially
        code = 1
        try:
            signal.alarm(60)  # a hang (waiting for the parent's workers) fails instead of blocking
            got = lmrefine.run_automaton(energy, mask)["grid"]
            code = 0 if np.array_equal(got, want) else 2
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, f"child status {status}"

