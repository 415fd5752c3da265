"""`python3 -m lmrefine batch`: many levels on Dask, with real headless Blender.

The levels are tiny .blend files (a subdivided floor, a cube, a sun, a
"Lightmap" UV map) made by one Blender process (tests/blender/make_levels.py);
each refines at 32^2 in about a second. The batch runs on a real LocalCluster
(or a dask-scheduler and two dask-workers started here, loopback only). The
tests at the top need neither Blender nor Dask.
"""

import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

from lmrefine.batch import BatchOptions, run_batch
from lmrefine.batch.cli import add_batch_parser
from lmrefine.batch.levels import find_levels, input_fingerprint
from lmrefine.batch.manifest import Manifest, options_key

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PYTHON_DIR = os.path.join(REPO, "python")
BLENDER = shutil.which("blender")
FLAGS = ["--objects", "Floor,Cube", "--resolution", "32", "--samples", "4"]

blender = pytest.mark.blender
needs_blender = pytest.mark.skipif(BLENDER is None, reason="Blender is not installed")


# ------------------------------------------------------------ without Blender


def test_levels_from_files_and_folders(tmp_path):
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    for path in ("one/x.blend", "one/y.blend", "one/y.blend1", "two/y.blend", "z.blend"):
        (tmp_path / path).write_bytes(b"BLENDER")
    levels = find_levels([str(tmp_path / "one"), str(tmp_path / "two" / "y.blend"), str(tmp_path / "z.blend")])
    assert [level.name for level in levels] == ["x", "one_y", "two_y", "z"]
    assert levels[0].path == str(tmp_path / "one" / "x.blend")


@pytest.mark.parametrize("make, message", [
    (lambda p: str(p / "missing.blend"), "does not exist"),
    (lambda p: (p / "a.txt").write_text("x") and str(p / "a.txt"), "is not a .blend file"),
    (lambda p: (p / "empty").mkdir() or str(p / "empty"), "has no .blend files"),
])
def test_bad_level_arguments_are_named(tmp_path, make, message):
    with pytest.raises(ValueError, match=message):
        find_levels([make(tmp_path)])


def test_fingerprint_reuses_hash_only_for_same_size_and_time(tmp_path):
    level = tmp_path / "a.blend"
    level.write_bytes(b"one")
    first = input_fingerprint(str(level))
    assert input_fingerprint(str(level), {**first, "hash": "cached"})["hash"] == "cached"
    level.write_bytes(b"two!")  # another size: read again
    again = input_fingerprint(str(level), {**first, "hash": "cached"})
    assert again["hash"] not in ("cached", first["hash"]) and again["size"] == 4


def test_manifest_decides_what_to_redo(tmp_path):
    manifest = Manifest(str(tmp_path))
    fingerprint = {"hash": "h1", "size": 1, "mtime_ns": 1}
    assert manifest.decide("a", fingerprint, FLAGS, str(tmp_path)) == (True, "new")
    manifest.update("a", status="done", input=fingerprint, options_key=options_key(FLAGS))
    assert manifest.decide("a", fingerprint, FLAGS, str(tmp_path)) == (True, "outputs missing")
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "report.json").write_text("{}")
    assert manifest.decide("a", fingerprint, FLAGS, str(tmp_path)) == (False, "unchanged")
    assert manifest.decide("a", fingerprint, FLAGS, str(tmp_path), force=True) == (True, "--force")
    assert manifest.decide("a", {**fingerprint, "hash": "h2"}, FLAGS, str(tmp_path)) == (True, "input changed")
    assert manifest.decide("a", fingerprint, FLAGS + ["--strength", "3"], str(tmp_path)) == (True, "options changed")
    manifest.update("a", status="failed")
    assert manifest.decide("a", fingerprint, FLAGS, str(tmp_path)) == (True, "was failed")
    manifest.save()
    assert not [f for f in os.listdir(tmp_path) if ".tmp-" in f]  # the atomic write left no temporary
    assert Manifest(str(tmp_path)).record("a")["status"] == "failed"


def test_unreadable_manifest_is_an_oserror(tmp_path):
    (tmp_path / "manifest.json").write_text("{not json")
    with pytest.raises(OSError, match="move it away"):
        Manifest(str(tmp_path))


def test_addon_flags_pass_through_in_order():
    import argparse

    parser = argparse.ArgumentParser()
    add_batch_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["batch", "lv", "--out", "o", "--strength", "3", "--objects", "A,B", "--no-preview",
                              "--resolution", "64", "--workers", "2"])
    assert args.flags == ["--strength", "3", "--objects", "A,B", "--no-preview", "--resolution", "64"]
    assert args.workers == 2 and args.levels == ["lv"]


def test_the_summary_names_the_objects_a_level_skipped():
    from lmrefine.batch.summary import skipped_objects, summary_table

    warnings = ["Skipped: 'Posts': its modifiers (Array) copy faces with their UVs, so 129 triangles ...",
                "'Ground': UV map 'Lightmap' was invalid at 256 texels ...",
                "Skipped: atlas 'Floor_atlas' (Floor, Box) could not be refined: ...",
                "Skipped: 'Cube' has no UV map: ..."]
    assert skipped_objects(warnings) == ["Posts", "Floor", "Box", "Cube"]
    assert skipped_objects(warnings[1:2]) == [] and skipped_objects(None) == []
    row = {"level": "stall", "status": "done", "seconds": 5.0, "objects": 4, "attempts": 1, "warnings": warnings,
           "skipped_objects": skipped_objects(warnings), "outputs": {"report": "/out/stall/report.json"},
           "log": "/out/stall/blender.log", "error": None}
    quiet = {**row, "level": "plaza", "warnings": [], "skipped_objects": []}
    table = summary_table([row, quiet]).splitlines()
    assert table[0].split() == ["level", "status", "seconds", "objects", "warnings", "attempts"]
    assert table[2].split() == ["stall", "done", "5.0", "4", "4", "1"]
    assert table[3].split() == ["plaza", "done", "5.0", "4", "0", "1"]
    assert table[4] == ("stall: 4 object(s) skipped, not refined: Posts, Floor, Box, Cube (why, and every warning: "
                        "/out/stall/report.json)")
    assert len(table) == 5


# ------------------------------------------------------------ with Blender and Dask


@pytest.fixture(scope="module")
def level_dir(tmp_path_factory):
    """a, b, c, d, b2 (b with another sun) and broken (not a .blend), made by one Blender."""
    if BLENDER is None:
        pytest.skip("Blender is not installed")
    folder = tmp_path_factory.mktemp("levels")
    process = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                              os.path.join(REPO, "tests", "blender", "make_levels.py"), "--", str(folder),
                              "a", "b", "c", "d", "b2:3"], capture_output=True, text=True, timeout=300)
    assert process.returncode == 0, process.stdout[-2000:] + process.stderr[-2000:]
    (folder / "broken.blend").write_bytes(b"this is not a blend file\n")
    return folder


def copy_levels(level_dir, target, names):
    target.mkdir(parents=True, exist_ok=True)
    for name in names:
        shutil.copy2(level_dir / f"{name}.blend", target / f"{name}.blend")
    return target


def load(path):
    with open(path, encoding="utf-8") as stream:
        return json.load(stream)


def check_done(out, name):
    """A finished level: its report says ok and names files that exist in OUT/<name>/."""
    report = load(out / name / "report.json")
    assert report["ok"] is True
    assert report["blend"] == str(out / name / f"{name}.blend") and os.path.isfile(report["blend"])
    images = {(obj, kind): path for obj, info in report["objects"].items() for kind, path in info["images"].items()}
    # One baked pass per object, plus the first lightmap the preview shows as "before".
    assert sorted(kind for _, kind in images) == ["before", "before", "direct", "direct"]
    assert all(os.path.isfile(path) and path.startswith(str(out / name)) for path in images.values())
    assert os.path.isfile(out / name / "blender.log")


@blender
@needs_blender
def test_batch_runs_every_level_then_skips_them_then_redoes_a_changed_one(level_dir, tmp_path):
    levels = copy_levels(level_dir, tmp_path / "levels", ["a", "b", "c"])
    out = tmp_path / "out"
    stream = io.StringIO()
    summary = run_batch([str(levels)], str(out), BatchOptions(flags=FLAGS, workers=2), stream=stream)
    assert summary["ok"] and summary["counts"] == {"done": 3} and summary["workers"] == 2
    for name in "abc":
        check_done(out, name)
    manifest = load(out / "manifest.json")["levels"]
    assert {name: record["status"] for name, record in manifest.items()} == {"a": "done", "b": "done", "c": "done"}
    assert all(record["attempts"] == 1 and record["objects"] == 2 for record in manifest.values())
    # Each level's two objects have a lightmap each: two atlas groups of one, an image each.
    assert all(len(record["outputs"]["atlases"]) == 2 for record in manifest.values())
    assert all(objects == [name] for record in manifest.values() for name, objects in record["outputs"]["atlases"].items())
    assert manifest["a"]["options"] == FLAGS
    assert not os.path.exists(out / ".work")
    assert load(out / "summary.json")["counts"] == {"done": 3}
    first_blend = os.stat(out / "b" / "b.blend").st_mtime_ns

    # The same command again: nothing runs, no cluster starts.
    stream = io.StringIO()
    summary = run_batch([str(levels)], str(out), BatchOptions(flags=FLAGS, workers=2), stream=stream)
    assert summary["workers"] == 0 and summary["counts"] == {"skipped": 3}
    assert "skipping 3 level(s)" in stream.getvalue() and "a, b, c" in stream.getvalue()
    assert load(out / "manifest.json")["levels"] == manifest

    # b changes (another sun): only b runs again, into the same folder.
    shutil.copy(level_dir / "b2.blend", levels / "b.blend")
    stream = io.StringIO()
    summary = run_batch([str(levels)], str(out), BatchOptions(flags=FLAGS, workers=2), stream=stream)
    assert summary["counts"] == {"done": 1, "skipped": 2}
    assert [row["status"] for row in summary["levels"]] == ["skipped (done before)", "done", "skipped (done before)"]
    check_done(out, "b")
    assert os.stat(out / "b" / "b.blend").st_mtime_ns != first_blend
    after = load(out / "manifest.json")["levels"]
    assert after["b"]["reason"] == "input changed" and after["b"]["input"]["hash"] != manifest["b"]["input"]["hash"]
    assert after["a"] == manifest["a"]
    assert sorted(os.listdir(out)) == ["a", "b", "c", "manifest.json", "summary.json"]


@blender
@needs_blender
def test_failing_level_is_reported_while_the_rest_finish(level_dir, tmp_path):
    levels = copy_levels(level_dir, tmp_path / "levels", ["a", "broken", "c"])
    out = tmp_path / "out"
    process = subprocess.run([sys.executable, "-m", "lmrefine", "batch", str(levels), "--out", str(out),
                              "--workers", "2", "--retries", "1", *FLAGS], capture_output=True, text=True,
                             timeout=300, env={**os.environ, "PYTHONPATH": PYTHON_DIR})
    assert process.returncode == 1, process.stderr
    assert " - INFO - " not in process.stderr, "worker processes log at INFO (preload chatter)"
    check_done(out, "a")
    check_done(out, "c")
    record = load(out / "manifest.json")["levels"]["broken"]
    assert record["status"] == "failed" and record["attempts"] == 2  # the first try and one retry
    assert "File format is not supported" in record["error"]
    log = open(record["log"]).read()
    assert log.count("===== attempt") == 2 and "File format is not supported" in log
    assert not os.path.exists(out / "broken") and not os.path.exists(out / ".work")
    table = process.stderr[re.search(r"^level +status", process.stderr, re.M).start():]
    assert re.search(r"^broken +failed +[\d.]+ +- +- +2$", table, re.M) and record["log"] in table
    summary = load(out / "summary.json")
    assert summary["ok"] is False and summary["counts"] == {"done": 2, "failed": 1}

    # A re-run tries the failed level again and skips the others.
    process = subprocess.run([sys.executable, "-m", "lmrefine", "batch", str(levels), "--out", str(out),
                              "--workers", "1", "--retries", "0", *FLAGS], capture_output=True, text=True,
                             timeout=300, env={**os.environ, "PYTHONPATH": PYTHON_DIR})
    assert process.returncode == 1
    assert "skipping 2 level(s)" in process.stderr
    assert load(out / "manifest.json")["levels"]["broken"]["reason"] == "was failed"


def _blender_processes(marker):
    """(pid, parent pid) of running Blender processes whose command line holds `marker`."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as stream:
                command = stream.read().split(b"\0")
            with open(f"/proc/{entry}/stat") as stream:
                parent = int(stream.read().rsplit(")", 1)[1].split()[1])
        except OSError:
            continue
        if command and os.path.basename(command[0]) == b"blender" and marker.encode() in b" ".join(command):
            found.append((int(entry), parent))
    return found


@blender
@needs_blender
def test_a_worker_killed_mid_level_loses_and_duplicates_nothing(level_dir, tmp_path):
    names = ["a", "b", "c", "d"]
    levels = copy_levels(level_dir, tmp_path / "levels", names)
    out = tmp_path / "out"
    killed = []

    def kill_one_worker():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            for pid, worker in _blender_processes(str(out)):
                os.kill(worker, signal.SIGKILL)  # the Dask worker process running this Blender
                killed.append((pid, worker))
                break
            time.sleep(0.02)

    killer = threading.Thread(target=kill_one_worker)
    killer.start()
    stream = io.StringIO()
    try:
        summary = run_batch([str(levels)], str(out), BatchOptions(flags=FLAGS, workers=2), stream=stream)
    finally:
        killed.append(None)  # stops the killer if nothing was found
        killer.join()
    assert killed[0] is not None, "no Blender was seen running"
    assert summary["ok"] and summary["counts"] == {"done": 4}
    manifest = load(out / "manifest.json")["levels"]
    for name in names:
        check_done(out, name)
        assert stream.getvalue().count(f"\n{name}: done") + stream.getvalue().startswith(f"{name}: done") == 1
    attempts = sorted(record["attempts"] for record in manifest.values())
    assert attempts == [1, 1, 1, 2]  # the killed level ran once more, nothing else did
    assert sorted(os.listdir(out)) == names + ["manifest.json", "summary.json"]  # no attempt folder left
    time.sleep(0.5)
    assert not _blender_processes(str(out))  # the killed worker's Blender died with it


def _free_port():
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@blender
@needs_blender
def test_existing_cluster_from_the_command_line(level_dir, tmp_path):
    levels = copy_levels(level_dir, tmp_path / "levels", ["a", "b", "c"])
    out = tmp_path / "out"
    address = f"tcp://127.0.0.1:{_free_port()}"
    env = {**os.environ, "PYTHONPATH": PYTHON_DIR}
    started = []
    try:
        started.append(subprocess.Popen(["dask-scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                                         "--no-dashboard"], env=env, cwd=tmp_path, start_new_session=True,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        for _ in range(2):
            started.append(subprocess.Popen(["dask-worker", address, "--host", "127.0.0.1", "--nworkers", "1",
                                             "--nthreads", "1", "--no-dashboard"], env=env, cwd=tmp_path,
                                            start_new_session=True, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        process = subprocess.run([sys.executable, "-m", "lmrefine", "batch", str(levels), "--out", str(out),
                                  "--scheduler", address, *FLAGS], capture_output=True, text=True, timeout=300,
                                 env=env)
        assert process.returncode == 0, process.stderr
        assert "3 level(s) on 2 worker(s)" in process.stderr
        for name in "abc":
            check_done(out, name)
        hosts = {record["host"] for record in load(out / "manifest.json")["levels"].values()}
        assert len(hosts) == 1
        # Each worker's Blender got its share of this machine's cores.
        share = max(1, (os.cpu_count() or 1) // 2)
        assert f" -t {share} " in open(out / "a" / "blender.log").readline()
    finally:
        for process in reversed(started):
            try:
                os.killpg(process.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for process in started:
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


@blender
@needs_blender
def test_evaluate_puts_the_equal_error_figure_in_the_summary(level_dir, tmp_path):
    levels = copy_levels(level_dir, tmp_path / "levels", ["a"])
    out = tmp_path / "out"
    stream = io.StringIO()
    summary = run_batch([str(levels)], str(out), BatchOptions(flags=FLAGS, workers=1, evaluate=True), stream=stream)
    assert summary["ok"], stream.getvalue()
    row = summary["levels"][0]
    # Floor and Cube have a lightmap each (not one atlas): each is measured alone, the level gets the lower.
    reports = {name: load(out / "a" / "evaluation" / name / "report.json")["scenes"][0] for name in ("Floor", "Cube")}
    ratios = {name: r["equal_error_resolution_ratio"] for name, r in reports.items()}
    assert row["equal_error"] == min(ratios.values()) and row["equal_error"] > 0, (row, ratios)
    assert all(r["resolution"] == int(FLAGS[FLAGS.index("--resolution") + 1]) for r in reports.values())
    table = stream.getvalue()
    assert re.search(r"^level +status +seconds +objects +warnings +attempts +equal-error$", table, re.M)
    # The level's warnings (the cube's too-narrow gutter, its coarse triangles): counted, none skipped.
    warnings = load(out / "a" / "report.json")["warnings"]
    assert row["warnings"] == warnings and row["skipped_objects"] == [] and len(warnings) >= 1
    assert re.search(rf"^a +done +[\d.]+ +2 +{len(warnings)} +1 +{row['equal_error']:.2f}x$", table, re.M)
    manifest = load(out / "manifest.json")["levels"]["a"]
    assert manifest["equal_error"] == row["equal_error"] and manifest["options"][-1] == "--evaluate"
    # Done without the evaluation before: a run that asks for it redoes the level; the same run again skips it.
    again = run_batch([str(levels)], str(out), BatchOptions(flags=FLAGS, workers=1, evaluate=True),
                      stream=io.StringIO())
    assert again["counts"] == {"skipped": 1}


def _refusing_blender(tmp_path):
    """A fake Blender whose batch entry refuses its flags as argparse does (usage lines, then the error,
    exit 2), logging each start into tmp_path/starts, a second late on every level but a.blend; and an
    empty batch script."""
    fake = tmp_path / "blender"
    fake.write_text("#!/bin/sh\n"
                    f"echo started >> '{tmp_path / 'starts'}'\n"
                    "case \"$*\" in *a.blend*) ;; *) sleep 1 ;; esac\n"  # level a refuses first
                    "echo 'usage: blender -b scene.blend --python batch.py -- [-h] --objects OBJECTS --out OUT'\n"
                    "echo '        [--preview | --no-preview] [--report REPORT]'\n"
                    "echo 'blender -b scene.blend --python batch.py --: error: the following arguments are "
                    "required: --objects'\n"
                    "exit 2\n")
    fake.chmod(0o755)
    script = tmp_path / "batch.py"
    script.write_text("")
    return str(fake), str(script)


def test_flags_the_addon_refuses_are_named_without_its_usage_lines(tmp_path):
    # The level's error is argparse's own sentence, not the last lines of the usage (no Blender needed).
    from lmrefine.batch.level_task import run_level
    fake, script = _refusing_blender(tmp_path)
    level = tmp_path / "level.blend"
    level.write_bytes(b"BLENDER")
    result = run_level("level", str(level), str(tmp_path / "out"), [], blender=fake, batch_script=script)
    assert result["ok"] is False and result["retry"] is False and result["flags_refused"] is True
    assert result["error"] == ("the add-on's batch entry refused the flags: the following arguments are required: "
                               "--objects")


def test_refused_flags_stop_the_batch_instead_of_failing_every_level(tmp_path):
    # The flags are every level's: after the first refusal the levels left are not started (each would
    # start Blender to fail the same way), and the summary says why (Dask, a fake Blender).
    fake, script = _refusing_blender(tmp_path)
    levels = tmp_path / "levels"
    levels.mkdir()
    for name in "abcdef":
        (levels / f"{name}.blend").write_bytes(b"BLENDER")
    stream = io.StringIO()
    summary = run_batch([str(levels)], str(tmp_path / "out"),
                        BatchOptions(flags=[], workers=1, blender=fake, batch_script=script), stream=stream)
    starts = len((tmp_path / "starts").read_text().splitlines())
    statuses = [row["status"] for row in summary["levels"]]
    # Level a refuses first; the worker's two threads may have started one or two more by then.
    assert summary["ok"] is False and statuses == ["failed"] + ["not run"] * 5 and starts <= 4, (statuses, starts)
    refused = summary["levels"][0]
    for row in summary["levels"]:
        if row["status"] == "not run":
            assert row["error"] == (f"the add-on's batch entry refused the flags: the following arguments are "
                                    f"required: --objects (on level '{refused['level']}'; fix the flags and run "
                                    "again)")
    assert f"stopped: the flags were refused on '{refused['level']}'" in stream.getvalue()
