"""A slice of the fuzz suite (tests/fuzz; `make fuzz` runs 10^4 cases and
more add-on cases): hostile inputs to every public function, each in a
forked child with a timeout, must give only promised outcomes. The seed
changes with the day, so the slice explores over time; a failure prints the
command that reruns its case."""

import datetime
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "fuzz"))

import api_cases  # noqa: E402
import runner  # noqa: E402

import lmrefine  # noqa: E402

SEED = int(os.environ.get("LMREFINE_FUZZ_SEED", datetime.date.today().toordinal()))
ASAN = "asan" in os.environ.get("LD_PRELOAD", "")


def test_the_cases_cover_every_public_name():
    assert sorted(lmrefine.__all__) == sorted(api_cases.COVERED)


def test_api_slice_keeps_every_promise():
    cases = 120 if ASAN else 400
    counts, examples = runner.run(SEED, cases, jobs=os.cpu_count() or 2, timeout=300.0 if ASAN else 60.0)
    print(runner.summary(counts, examples, SEED))  # shown with pytest -s
    assert sum(counts.values()) == cases
    assert runner.failures(counts) == {}, runner.summary(counts, examples, SEED)
    # The slice reaches both ends: calls that succeed and calls refused with a promised error.
    assert counts["ok"] > cases // 10
    assert sum(n for outcome, n in counts.items() if outcome.startswith("promised")) > cases // 3


@pytest.mark.blender
@pytest.mark.slow
def test_addon_slice_on_broken_meshes():
    import shutil

    if shutil.which("blender") is None:
        pytest.skip("Blender is not installed")
    import run

    counts, examples = run.run_blender_cases(40, SEED, timeout=120.0)
    print(runner.summary(counts, examples, SEED, run.RERUN_BLENDER))
    assert sum(counts.values()) == 40
    assert runner.failures(counts) == {}, runner.summary(counts, examples, SEED, run.RERUN_BLENDER)
    assert counts["ok"] > 10


def test_a_crash_and_a_hang_are_caught_and_counted(monkeypatch):
    """The runner itself: a case that kills its process and one that never returns are counted, not fatal."""
    import os as _os
    import signal
    import time

    def fake_run_case(lm, seed, index):
        if index == 0:
            # SIGKILL, not SIGSEGV: under ASan a SEGV runs the sanitizer's report in a
            # child forked from this threaded process, which can stall past the timeout.
            _os.kill(_os.getpid(), signal.SIGKILL)
        if index == 1:
            time.sleep(60)
        if index == 2:
            return "other exception KeyError", "x"
        return "ok", ""

    monkeypatch.setattr(runner, "run_case", fake_run_case)
    counts, examples = runner.run(0, 4, jobs=2, timeout=2.0, fresh=False)
    assert counts == {"crash": 1, "hang": 1, "other exception KeyError": 1, "ok": 1}
    assert runner.failures(counts) == {"crash": 1, "hang": 1, "other exception KeyError": 1}
    assert "signal 9" in examples["crash"][0][1]


def test_cases_leave_no_temporary_folders(monkeypatch, tmp_path):
    """Children exit without cleanup, so a case's temporary folders must land where the runner removes them."""
    import signal
    import tempfile

    def fake_run_case(lm, seed, index):
        folder = tempfile.mkdtemp(prefix="lmrefine_fuzz_")
        open(os.path.join(folder, "out.png"), "wb").close()
        if index == 1:
            os.kill(os.getpid(), signal.SIGKILL)
        return "ok", ""

    monkeypatch.setattr(runner, "run_case", fake_run_case)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    counts, _ = runner.run(0, 3, jobs=2, timeout=10.0, fresh=False)
    assert counts == {"ok": 2, "crash": 1}
    assert list(tmp_path.iterdir()) == []
