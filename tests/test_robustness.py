"""Bad input never takes the process down (issue 12): one regression test per
defect class. Cases that once aborted the process run in a child process,
so a regression fails the test instead of killing pytest."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import lmrefine

from baker_scenes import floor  # noqa: E402  (tests/ is on sys.path)

PYTHONPATH = os.environ.get("LMREFINE_PYTHONPATH") or os.path.join(os.path.dirname(__file__), "..", "python")


def run_child(code, timeout=60):
    """Runs `code` in a fresh Python; returns (returncode, output)."""
    env = dict(os.environ, PYTHONPATH=PYTHONPATH)
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=env)
    return done.returncode, done.stdout + done.stderr


# --- geometry that once aborted in Embree -------------------------------------------------

def test_zero_area_triangles_are_skipped_and_counted():
    # An n-gon cap fanned from a vertex on its rim: collinear corners, zero
    # area in 3-D (what Blender's subdivided caps give), next to real quads.
    code = """
    import numpy as np, lmrefine
    rim = [(np.cos(a), np.sin(a), 0.0) for a in np.linspace(0, 2 * np.pi, 9)[:-1]]
    mid = [((rim[i][0] + rim[(i + 1) % 8][0]) / 2, (rim[i][1] + rim[(i + 1) % 8][1]) / 2, 0.0) for i in range(8)]
    positions = np.array(rim + mid + [(0, 0, 0)], np.float32)
    triangles = []
    for i in range(8):
        triangles += [(16, i, 8 + i), (16, 8 + i, (i + 1) % 8), (i, 8 + i, (i + 1) % 8)]  # last one: zero area
    triangles = np.array(triangles)
    uvs = np.random.default_rng(1).uniform(0.1, 0.9, (len(triangles) * 3, 2)).astype(np.float32)
    scene = lmrefine.Scene()
    scene.add_mesh(positions, triangles, uvs=uvs)
    scene.add_light("point", energy=100.0, position=(0, 0, 2))
    result = lmrefine.bake(scene, 16, samples=4, passes=("direct", "ao", "indirect"))
    print("degenerate", scene.degenerate_triangles(0), result.stats["degenerate_triangles"])
    """
    code_ok, out = run_child(code)
    assert code_ok == 0, out
    assert "degenerate 8 8" in out, out


@pytest.mark.parametrize("where", ["positions", "points"])
def test_huge_coordinates_raise_value_error(where):
    code = f"""
    import numpy as np, lmrefine
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1e30, 0, 0]], np.float32)
    triangles = np.array([[0, 1, 2], [0, 1, 3]]) if "{where}" == "positions" else np.array([[0, 1, 2]])
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 0], [.5, 0], [.5, .5]], np.float32)[:len(triangles) * 3]
    scene = lmrefine.Scene()
    try:
        scene.add_mesh(positions, triangles, uvs=uvs)
        scene.add_light("point", energy=100.0, position=(0, 0, 2))
        lmrefine.evaluate(scene, np.array([[1e30, 0, 0]], np.float32), np.array([[0, 0, 1]], np.float32))
    except ValueError as error:
        print("ValueError", error)
    """
    code_ok, out = run_child(code)
    assert code_ok == 0, out
    assert "ValueError" in out and "1e9" in out, out


# --- the binding boundary ---------------------------------------------------------------

HUGE_VIEW = np.broadcast_to(np.float32(0.5), (1 << 20, 1 << 20))  # 4 TiB if copied


@pytest.mark.parametrize("call", [
    lambda v: lmrefine.gradient_map(v),
    lambda v: lmrefine.dwt2(v),
    lambda v: lmrefine.idwt2((v, v, v, v)),
    lambda v: lmrefine.run_automaton(v),
    lambda v: lmrefine.write_image("/tmp/never_written.exr", v),
    lambda v: lmrefine.grid_cell_areas(np.broadcast_to(np.float32(0.5), (1 << 20, 1 << 20, 2))),
    lambda v: lmrefine.warp_uvs(np.broadcast_to(np.float32(0.5), (1 << 40, 2)), lmrefine.identity_grid(4)),
    lambda v: lmrefine.coverage_mask(np.broadcast_to(np.float32(0.5), (1 << 40, 2)), np.zeros((1, 3), int), 8),
    lambda v: lmrefine.find_charts(np.zeros((3, 2), np.float32), np.broadcast_to(np.int64(0), (1 << 40, 3))),
])
def test_a_view_too_large_to_copy_is_a_memory_error_naming_it(call):
    with pytest.raises(MemoryError, match="copy of"):
        call(HUGE_VIEW)


@pytest.mark.parametrize("resolution, error, match", [
    (2 ** 31, ValueError, "at most"), (2 ** 63, ValueError, "at most"), (2 ** 200, ValueError, "at most"),
    ((16.5, 16), TypeError, "resolution must be an int"), ("16", TypeError, "resolution must be an int"),
    (None, TypeError, "resolution"), (True, TypeError, "resolution"), ((16,), ValueError, "resolution"),
    (-(2 ** 70), ValueError, "positive"),
])
def test_bad_resolutions_name_the_argument(resolution, error, match):
    uvs, triangles = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9]], np.float32), np.array([[0, 1, 2]])
    for call in (lambda: lmrefine.coverage_mask(uvs, triangles, resolution),
                 lambda: lmrefine.check_layout(uvs, triangles, resolution),
                 lambda: lmrefine.LayoutChecker(uvs, triangles, resolution),
                 lambda: lmrefine.refine_uvs(None, uvs, triangles, resolution),
                 lambda: lmrefine.identity_grid(resolution)):
        with pytest.raises(error, match=match):
            call()


def test_huge_resolution_is_a_memory_error_before_allocating():
    uvs, triangles = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9]], np.float32), np.array([[0, 1, 2]])
    for call in (lambda: lmrefine.coverage_mask(uvs, triangles, 10 ** 6),
                 lambda: lmrefine.LayoutChecker(uvs, triangles, 10 ** 6),
                 lambda: lmrefine.refine_uvs(None, uvs, triangles, 10 ** 6)):
        with pytest.raises(MemoryError, match=r"1000000x1000000 needs about \d+\.\d+ GiB"):
            call()


@pytest.mark.parametrize("params, error", [
    ({"energy": "3"}, TypeError), ({"energy": None}, TypeError), ({"energy": (1, 2)}, TypeError),
    ({"energy": float("nan")}, ValueError), ({"energy": True}, TypeError),
    ({"energy": 3, "shape": None}, TypeError), ({"energy": 3, "size": "1"}, TypeError),
    ({"energy": 3, "color": "red"}, ValueError),
])
def test_bad_light_parameters_name_the_parameter(params, error):
    name = [k for k in params if k != "energy"] or ["energy"]
    with pytest.raises(error, match=name[-1]):
        lmrefine.Scene().add_light("area", **params)


def test_degenerate_triangles_of_an_unknown_mesh_is_a_value_error():
    with pytest.raises(ValueError, match="mesh"):
        lmrefine.Scene().degenerate_triangles(99)


# --- files ------------------------------------------------------------------------------

def test_non_regular_files_are_os_errors(tmp_path):
    with pytest.raises(OSError, match="not a regular file"):
        lmrefine.read_image("/dev/zero")
    with pytest.raises(OSError, match="not a regular file"):
        lmrefine.read_image(str(tmp_path))
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="not a regular file"):
        lmrefine.read_image(fifo)


def test_nul_in_a_path_is_a_value_error_and_writes_nothing(tmp_path):
    with pytest.raises(ValueError, match="NUL"):
        lmrefine.write_image(str(tmp_path / "a\x00b.png"), np.zeros((4, 4, 3), np.float32))
    with pytest.raises(ValueError, match="NUL"):
        lmrefine.read_image(str(tmp_path / "a\x00b.png"))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(TypeError, match="path"):
        lmrefine.read_image(42)


def test_an_image_header_declaring_too_many_pixels_is_a_memory_error(tmp_path):
    # A Radiance header is text: declare 100000^2 pixels and give none.
    path = tmp_path / "huge.hdr"
    path.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n" + bytes(64))
    with pytest.raises(MemoryError, match=r"100000x100000.*needs about \d+\.\d+ GiB"):
        lmrefine.read_image(path)


# --- cancellation -----------------------------------------------------------------------

@pytest.mark.parametrize("answer", [False, np.False_, 0, 0.0])
def test_every_false_answer_cancels_even_the_final_report(answer):
    image = np.random.default_rng(2).random((32, 32)).astype(np.float32)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.gradient_map(image, progress=lambda fraction, stage: answer if fraction >= 1.0 else None)


@pytest.mark.parametrize("answer", [None, True, 1, np.True_])
def test_none_and_true_answers_go_on(answer):
    image = np.random.default_rng(2).random((32, 32)).astype(np.float32)
    assert lmrefine.gradient_map(image, progress=lambda fraction, stage: answer).shape == (32, 32, 4)


def test_an_exception_in_the_final_report_is_raised():
    def progress(fraction, stage):
        if fraction >= 1.0:
            raise KeyError("from the callback")

    image = np.random.default_rng(2).random((32, 32)).astype(np.float32)
    with pytest.raises(KeyError, match="from the callback"):
        lmrefine.gradient_map(image, progress=progress)
    energy = np.ones((16, 16), np.float32)
    with pytest.raises(KeyError, match="from the callback"):
        lmrefine.run_automaton(energy, progress=progress)


def test_cancelling_the_bake_at_its_last_report():
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor()
    scene.add_mesh(positions, triangles, uvs=uvs)
    scene.add_light("sun", energy=1.0)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.bake(scene, 8, samples=1, passes=("ao",), progress=lambda f, s: f < 1.0)


# --- layouts ----------------------------------------------------------------------------

def test_stacked_faces_overlap_inside_their_chart():
    # Six faces on one square: identical corner UVs join them into one chart.
    square = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]], np.float32)
    uvs = np.concatenate([square[[0, 1, 2]], square[[0, 2, 3]]] * 6)
    triangles = np.arange(36).reshape(12, 3)
    report = lmrefine.check_layout(uvs, triangles, 64)
    assert report["charts"] == 1
    assert report["overlapping"] == 12 and not report["valid"]
    # One face alone, shared corners: clean.
    one = lmrefine.check_layout(uvs[:6], triangles[:2], 64)
    assert one["overlapping"] == 0 and one["valid"]


def test_a_chart_folded_onto_itself_overlaps():
    # A strip of three quads whose last quad folds back over the first, all
    # counter-clockwise: no flip, but two quads share texels.
    uvs = np.array([[0.1, 0.1], [0.4, 0.1], [0.4, 0.4], [0.1, 0.4],   # quad A
                    [0.4, 0.1], [0.7, 0.1], [0.7, 0.4], [0.4, 0.4],   # quad B, shares A's right edge
                    [0.7, 0.1], [0.7, 0.4], [0.2, 0.45], [0.2, 0.15]], np.float32)  # C, wraps over A
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]])
    report = lmrefine.check_layout(uvs, triangles, 64)
    assert report["overlapping"] > 0 and not report["valid"]


def test_inputs_are_never_modified_by_bad_calls():
    uvs = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9]], np.float32)
    triangles = np.array([[0, 1, 2]])
    before = uvs.copy(), triangles.copy()
    for call in (lambda: lmrefine.check_layout(uvs, triangles, "16"),
                 lambda: lmrefine.coverage_mask(uvs, triangles, 10 ** 6),
                 lambda: lmrefine.refine_uvs(None, uvs, triangles, (16.5, 16))):
        with pytest.raises((TypeError, ValueError, MemoryError)):
            call()
    np.testing.assert_array_equal(uvs, before[0])
    np.testing.assert_array_equal(triangles, before[1])


# --- found by the fuzz suite (tests/fuzz) ----------------------------------------------------

_E = np.ones((4, 4), np.float32)
_UVS = np.float32([[0, 0], [1, 0], [0, 1]])
_TRIS = np.array([[0, 1, 2]])


def _mesh_scene():
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor()
    scene.add_mesh(positions, triangles, uvs=uvs)
    scene.add_light("point", energy=10.0, position=(0, 0, 1))
    return scene


@pytest.mark.parametrize("call, error, name", [
    (lambda: lmrefine.run_automaton(_E, max_steps=1.5), TypeError, "max_steps"),
    (lambda: lmrefine.run_automaton(_E, diffusion="0.1"), TypeError, "diffusion"),
    (lambda: lmrefine.run_automaton(_E, coarse_to_fine="yes"), TypeError, "coarse_to_fine"),
    (lambda: lmrefine.dwt2(_E, wavelet=5), TypeError, "wavelet"),
    (lambda: lmrefine.dwt(_E[0], mode=None), TypeError, "mode"),
    (lambda: lmrefine.gradient_map(_E, wavelet="\udcff"), ValueError, "wavelet"),
    (lambda: lmrefine.check_layout(_UVS, _TRIS, 8, padding="2"), TypeError, "padding"),
    (lambda: lmrefine.check_layout(_UVS, _TRIS, 8, failing_charts="x"), TypeError, "failing_charts"),
    (lambda: lmrefine.LayoutChecker(_UVS, _TRIS, 8, None), TypeError, "padding"),
    (lambda: lmrefine.write_image("x.png", _E, format=3), TypeError, "format"),
    (lambda: lmrefine.write_image("x.png", _E, srgb="on"), TypeError, "srgb"),
    (lambda: lmrefine.Scene().add_mesh(*floor()[:2], receiver="no"), TypeError, "receiver"),
    (lambda: lmrefine.Scene().add_light(None, energy=1.0), TypeError, "kind"),
    (lambda: lmrefine.bake(_mesh_scene(), 8, samples=float("inf")), TypeError, "samples"),
    (lambda: lmrefine.bake(_mesh_scene(), 8, seed=-1), ValueError, "seed"),
    (lambda: lmrefine.bake("scene", 8), TypeError, "scene"),
    (lambda: lmrefine.bake(_mesh_scene(), 8, passes=3), TypeError, "passes"),
    (lambda: lmrefine.evaluate(_mesh_scene(), np.zeros((1, 3)), np.ones((1, 3)), ao_distance=None), TypeError,
     "ao_distance"),
    (lambda: lmrefine.refine_uvs(_E[0], _UVS, _TRIS, 4), ValueError, "lightmap"),
    (lambda: lmrefine.refine_uvs(_E, _UVS, _TRIS, 4, strength="1"), TypeError, "strength"),
])
def test_a_wrong_argument_is_named_never_a_generic_cast_error(call, error, name):
    with pytest.raises(error, match=name) as raised:
        call()
    assert "incompatible function arguments" not in str(raised.value)
    assert "Unable to cast" not in str(raised.value)


@pytest.mark.parametrize("call, match", [
    (lambda: lmrefine.run_automaton(_E, max_steps=2**31 - 1), "max_steps must be at most 10000"),
    (lambda: lmrefine.run_automaton(_E, passes=10**6), "passes must be at most 64"),
    (lambda: lmrefine.refine_uvs(_E, _UVS, _TRIS, 4, passes=2**31 - 1), r"passes must be in \[1, 64\]"),
])
def test_step_and_pass_counts_are_bounded_so_nothing_runs_for_days(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_identity_grid_checks_memory_before_allocating():
    with pytest.raises(MemoryError, match="identity grid of 46341x46341 texels needs about"):
        lmrefine.identity_grid(46341)


def test_an_undecodable_file_name_is_written_as_its_bytes(tmp_path):
    path = str(tmp_path) + "/x\udcff.png"  # what os.fsdecode gives for the byte 0xff
    lmrefine.write_image(path, np.zeros((2, 2), np.float32))
    assert os.path.exists(os.fsencode(path))
    assert lmrefine.read_image(path).shape == (2, 2, 1)
