"""The add-on's texel-density overlay, driven through real headless Blender (tests/blender/overlay_checks.py).

Headless Blender cannot draw: these tests assert on what the overlay would
draw (the arrays its batch is made of, the legend's text) and on which
handlers are installed when.
"""

import json
import math
import os
import shutil
import subprocess

import pytest

pytestmark = [pytest.mark.blender, pytest.mark.slow]

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER = shutil.which("blender")

if BLENDER is None:
    pytest.skip("Blender is not installed", allow_module_level=True)

GREEN = [0.2, 0.85, 0.2, 0.8]
CYAN = [0.1, 0.8, 0.95, 0.8]  # half the reference
NO_FACES = "no faces or no area after its modifiers and transform"
BLUE, RED, MAGENTA = [0.15, 0.35, 1.0, 0.8], [1.0, 0.15, 0.1, 0.8], [1.0, 0.0, 1.0, 0.8]


@pytest.fixture(scope="module")
def facts(tmp_path_factory):
    work = tmp_path_factory.mktemp("overlay")
    out = work / "facts.json"
    process = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                              os.path.join(REPO, "tests", "blender", "overlay_checks.py"), "--", REPO, str(out),
                              str(work)], capture_output=True, text=True, timeout=300)
    assert process.returncode == 0, process.stdout[-3000:] + process.stderr[-3000:]
    assert "must be None" not in process.stderr + process.stdout  # a property callback returned a value
    return json.loads(out.read_text())


def fact(facts, name):
    value = facts[name]
    assert "exception" not in value, value.get("exception")
    return value


def close(colours, expected):
    return len(colours) == len(expected) and all(
        all(abs(a - b) < 1e-3 for a, b in zip(colour, target)) for colour, target in zip(colours, expected))


def test_a_known_plane_has_128_texels_per_metre(facts):
    value = fact(facts, "known_plane")
    plane = value["plane"]
    assert plane["minimum"] == pytest.approx(128.0) and plane["median"] == pytest.approx(128.0)
    assert plane["maximum"] == pytest.approx(128.0) and plane["reference"] == pytest.approx(128.0)
    assert plane["vertices"] == 6 and plane["dtypes"] == ["float32", "float32"] and plane["finite"]
    assert close(plane["colours"], [GREEN])
    assert "min 128 / median 128 / max 128 texels per metre" in plane["legend"]
    assert plane["legend"][0] == "Texel density: refined maps at 256 x 256"
    # The fixed scale: 1/4x blue, 4x red, beyond them clamped, 0 magenta.
    assert close(value["ramp_ends"], [BLUE, RED, RED, BLUE, MAGENTA])


def test_transforms_modifiers_and_uv_edits_are_measured_after_a_change(facts):
    value = fact(facts, "known_plane")
    assert value["scaled"]["median"] == pytest.approx(64.0)  # the object's scale, after the cache was dropped
    assert value["array"]["median"] == pytest.approx(128.0) and value["array"]["vertices"] == 18  # 3 copies
    assert value["uv_edit"]["median"] == pytest.approx(64.0)


def test_refined_and_source_maps(facts):
    value = fact(facts, "source_and_refined_maps")
    refined, source = value["refined"], value["source"]
    assert refined["drawn"] == [["Plane", "UVMap_refined"], ["Other", "UVMap"]] and refined["fallback"] == ["Other"]
    # Green stays the source maps' median, so the refined plane shows as 1/2x.
    assert refined["reference"] == pytest.approx(128.0)
    assert refined["minimum"] == pytest.approx(64.0) and refined["maximum"] == pytest.approx(128.0)
    assert close(refined["colours"], [CYAN, GREEN]) and close(value["half"], [CYAN])
    assert "1 object(s) without a refined map show the source map" in refined["legend"]
    assert source["drawn"] == [["Plane", "UVMap"], ["Other", "UVMap"]] and source["fallback"] == []
    assert source["median"] == pytest.approx(128.0) and source["legend"][0].startswith("Texel density: source maps")


def test_messy_meshes_draw_without_errors(facts):
    value = fact(facts, "messy_meshes")
    # An n-gon is one face: its ten triangles share one value, sqrt(UV area x R^2 / world area).
    assert value["ngon_triangles"] == 10 and len(value["ngon_values"]) == 1
    assert value["ngon_values"][0] == pytest.approx(value["ngon_expected"], rel=1e-5)
    # The zero-area triangle has no value; the other one is measured.
    assert value["sliver_values"][0] > 0 and math.isnan(value["sliver_values"][1])
    skipped = dict(value["skipped"])
    assert skipped == {"Bare": "no lightmap UV map", "Huge": "vertices at NaN, Inf or beyond 1e9 units",
                       "Flat": NO_FACES, "Dropped": NO_FACES}
    assert value["finite"] and value["minimum"] > 0
    assert any(line.startswith("not drawn: 4 object(s)") for line in value["legend"])
    assert value["draw_raised"] == []  # background Blender cannot draw: the callbacks swallow it
    assert value["draw_messages"] == 1  # and say so once, not every frame
    assert value["rows"][0][0].startswith("Median: ")


def test_depth_bias_and_cache(facts):
    value = fact(facts, "depth_bias_and_cache")
    assert value["apparent"] == pytest.approx([value["expected"]] * 3, abs=2e-5) and value["expected"] < 0.999
    assert value["unchanged"]
    assert value["ortho_shift"] == pytest.approx([value["ortho_shift"][0]] * 3) and value["ortho_shift"][0] > 0
    assert value["keys"] == {"refined": [["Plane", "UVMap", 256], ["Plane", "UVMap_refined", 256]],
                             "source": [["Plane", "UVMap", 256]], "resolution": [["Plane", "UVMap", 512]]}


def test_random_broken_meshes(facts):
    value = fact(facts, "random_broken_meshes")
    assert value["finite"] and value["colours_in_range"]
    assert value["drawn"] + value["skipped"] == 40 and value["drawn"] > 0 and value["vertices"] > 0
    assert max(len(line) for line in value["legend"]) < 90  # huge densities are written short (1.23e+28)


def test_the_toggle_adds_and_removes_every_handler(facts):
    value = fact(facts, "toggle_adds_and_removes_handlers")
    off = {"handles": 0, "enabled": False, "depsgraph": False, "undo": False, "redo": False, "load_pre": True,
           "view": False}
    assert value["off"] == off and value["after"] == off
    on = {"handles": 2, "enabled": True, "depsgraph": True, "undo": True, "redo": True, "load_pre": True,
          "view": True}
    assert value["on"] == on and value["twice"] == on
    assert value["depsgraph_handlers_after"] == 0
    assert value["scene_unchanged"]  # nothing written into meshes, materials or images
    assert value["rows_on"][0] == ["Median: 128 texels/m", True]
    assert [row[1] for row in value["rows_off"]] == [False, False, False] and len(value["rows_on"]) == 3


def test_loading_a_file_and_unregistering_remove_the_handlers(facts):
    value = fact(facts, "loading_a_file_removes_the_handlers")
    assert value["on"]
    assert value["after_open"] == {"enabled": False, "handles": 0, "depsgraph": False, "load_pre_kept": True,
                                   "property": False}
    assert value["again"] and value["after_new_file"] is False
    value = fact(facts, "unregister_removes_the_handlers")
    assert value == {"on": True, "enabled": False, "depsgraph": False, "load_pre": False,
                     "load_pre_after_register": True}
