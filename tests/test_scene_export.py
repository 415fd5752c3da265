"""`python3 -m lmrefine export-scene` and `evaluate LEVEL.blend`: a user's
.blend through headless Blender into the scene .npz the evaluation reads
(addon/lmrefine_blender/export_scene.py, python/lmrefine/scene_export.py)."""

import json
import math
import os
import shutil
import subprocess

import numpy as np
import pytest

from lmrefine import cli
from lmrefine.sample_scenes import load_sample

REPO = os.path.normpath(os.path.join(os.path.dirname(__file__), ".."))
BLENDER = shutil.which("blender")
blender = pytest.mark.blender
needs_blender = pytest.mark.skipif(BLENDER is None, reason="Blender is not installed")


@pytest.fixture(scope="module")
def level(tmp_path_factory):
    """tests/blender/make_export_scene.py's level: a floor with a texture map
    and a lightmap UV map, a floating cube without UVs, a hidden plane, a sun
    and a camera."""
    folder = tmp_path_factory.mktemp("level")
    subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                    os.path.join(REPO, "tests", "blender", "make_export_scene.py"), "--", str(folder / "level.blend"),
                    str(folder / "twin.blend"), str(folder / "empty.blend"), str(folder / "arrayed.blend"),
                    str(folder / "faceless.blend")],
                   check=True, capture_output=True)
    return str(folder / "level.blend")


@blender
@needs_blender
def test_export_scene_writes_the_receivers_occluders_lights_and_camera(level, tmp_path, capsys):
    out = tmp_path / "scene.npz"
    assert cli.main(["export-scene", level, "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "left out (hidden or disabled for render): Hidden" in printed and "1 receivers, 128 triangles" in printed
    scene = load_sample(str(out))
    assert scene.name == "level" and scene.objects == ["Floor"]
    # 8 x 8 quads: 128 triangles, one position per face corner (256 loops).
    assert scene.triangles.shape == (128, 3) and scene.positions.shape == (256, 3)
    assert list(scene.uvs) == ["own"] and scene.uv_maps == {"Floor": "Lightmap"}  # the add-on's automatic choice
    uvs = scene.uvs["own"]
    assert uvs.shape == (384, 2)
    assert uvs.min() == pytest.approx(0.05, abs=1e-6) and uvs.max() == pytest.approx(0.95, abs=1e-6)
    # The lightmap map is the floor's x, y mapped onto [0.05, 0.95].
    corners = scene.positions[scene.triangles.reshape(-1)]
    np.testing.assert_allclose(uvs, 0.05 + 0.9 * (corners[:, :2] + 2.0) / 4.0, atol=1e-6)
    np.testing.assert_allclose(scene.normals, np.tile([0, 0, 1], (384, 1)), atol=1e-6)
    np.testing.assert_allclose(scene.base_color, 0.6, atol=1e-6)
    # The face each triangle was cut from: each quad's two triangles, the 64 quads apart.
    assert scene.polygons.shape == (128,) and len(np.unique(scene.polygons)) == 64
    assert all(len(set(scene.triangles[scene.polygons == face].ravel().tolist())) == 4
               for face in np.unique(scene.polygons))
    assert scene.occluder_triangles.shape == (12, 3)  # the cube; the hidden plane casts nothing
    np.testing.assert_allclose(scene.occluder_positions.min(axis=0), (-0.5, -0.5, 0.5), atol=1e-6)
    [sun] = scene.lights
    assert sun["name"] == "Sun" and sun["kind"] == "sun" and sun["energy"] == pytest.approx(3.0)
    assert sun["angle"] == pytest.approx(math.radians(1.0))
    assert np.asarray(sun["matrix"]).shape == (4, 4)
    assert scene.camera["name"] == "Camera"
    x0, x1, y0, y1, z = scene.camera["frame"]
    assert (x1 - x0) / (y1 - y0) == pytest.approx(640 / 400) and z < 0
    np.testing.assert_allclose(scene.camera["position"], (0, -6, 4), atol=1e-6)
    # The file bakes as it is.
    scene.to_scene(uvs)


@blender
@needs_blender
@pytest.mark.parametrize("flags, words", [
    (["--objects", "Cube"], "'Cube' has no UV map: give it a lightmap UV map in Blender"),
    (["--uv-map", "Nope"], "'Floor' has no UV map 'Nope' (it has: UVMap, Lightmap): pass --uv-map"),
    (["--uv-map", "UVMap"], "UV map 'UVMap' of 'Floor' has 175 UVs outside [0, 1]"),
    (["--objects", "Ghost"], "no object(s) named Ghost"),
])
def test_export_scene_says_what_to_do_with_a_scene_it_cannot_export(level, tmp_path, capsys, flags, words):
    assert cli.main(["export-scene", level, "-o", str(tmp_path / "s.npz"), *flags]) == 2
    error = capsys.readouterr().err
    assert error.startswith("lmrefine export-scene: error: cannot export") and words in error
    assert "Traceback" not in error and not (tmp_path / "s.npz").exists()


@blender
@needs_blender
def test_objects_that_do_not_share_one_atlas_are_refused_with_the_fix(level, tmp_path, capsys):
    twin = os.path.join(os.path.dirname(level), "twin.blend")
    assert cli.main(["export-scene", twin, "-o", str(tmp_path / "s.npz")]) == 2
    error = capsys.readouterr().err
    assert "the lightmap UV maps of 'Floor' and 'Twin' cover the same part of the UV square" in error
    assert "--objects NAME" in error and not (tmp_path / "s.npz").exists()
    assert cli.main(["export-scene", twin, "-o", str(tmp_path / "s.npz"), "--objects", "Floor"]) == 0


@blender
@needs_blender
def test_copies_a_modifier_makes_with_their_uvs_receive_no_lightmap(level, tmp_path, capsys):
    # The rail's Array copies its quad and its lightmap UVs: three places would share one set of
    # texels. Named, it is refused with the fix; picked by 'all', it only casts shadows, as the
    # add-on's run skips it.
    arrayed = os.path.join(os.path.dirname(level), "arrayed.blend")
    assert cli.main(["export-scene", arrayed, "-o", str(tmp_path / "s.npz"), "--objects", "Rail"]) == 2
    error = capsys.readouterr().err
    assert "'Rail': its modifiers (Array) copy faces with their UVs, so " in error
    assert "Apply > Visual Geometry to Mesh" in error and "or leave the object out of --objects" in error
    assert not (tmp_path / "s.npz").exists()
    assert cli.main(["export-scene", arrayed, "-o", str(tmp_path / "s.npz")]) == 0
    assert "left out as a receiver (it casts shadows): 'Rail': its modifiers (Array)" in capsys.readouterr().out
    scene = load_sample(str(tmp_path / "s.npz"))
    assert scene.objects == ["Floor"] and scene.uv_maps == {"Floor": "Lightmap"}
    assert len(scene.occluder_triangles) == 12 + 3 * 2  # the cube and the rail's three quads


@blender
@needs_blender
@pytest.mark.parametrize("name, words", [
    ("Guide", "'Guide' is a mesh without faces (2 vertices, 1 edges): a lightmap needs faces: fill them in"),
    ("Emptied", "'Emptied' is an empty mesh (no vertices): there is nothing to lightmap"),
    ("Collapsed", "'Collapsed': its modifiers (Weld) remove every face: disable the modifier that removes them"),
])
def test_objects_with_no_face_to_lightmap_are_named_or_left_out(level, tmp_path, capsys, name, words):
    # Named, each stops the export with its own cause and fix; picked by 'all', each is left out with a
    # note and the rest is exported (before, one such object stopped the whole export with a message
    # about modifiers and scale that fitted none of them).
    faceless = os.path.join(os.path.dirname(level), "faceless.blend")
    assert cli.main(["export-scene", faceless, "-o", str(tmp_path / "s.npz"), "--objects", f"Floor,{name}"]) == 2
    error = capsys.readouterr().err
    assert words in error and error.rstrip().endswith("or leave the object out of --objects")
    assert not (tmp_path / "s.npz").exists()
    assert cli.main(["export-scene", faceless, "-o", str(tmp_path / "s.npz")]) == 0
    assert f"left out (nothing to lightmap): {words}" in capsys.readouterr().out
    scene = load_sample(str(tmp_path / "s.npz"))
    assert scene.objects == ["Floor"] and len(scene.occluder_triangles) == 12  # the cube only


@blender
@needs_blender
def test_a_level_without_meshes_is_named(level, tmp_path, capsys):
    empty = os.path.join(os.path.dirname(level), "empty.blend")
    assert cli.main(["export-scene", empty, "-o", str(tmp_path / "s.npz")]) == 2
    assert "has no mesh object, so nothing to lightmap: check that this is the level's .blend" in \
        capsys.readouterr().err


def test_shared_atlas_check_tells_side_by_side_from_overlapping_layouts():
    from lmrefine.scene_export import shared_atlas_problem
    from test_surface_view import plane_scene

    scene = plane_scene()  # one floor in [0.1, 0.9]^2, two objects: its west and east halves
    uvs = scene.uvs.pop("smart")
    west = scene.positions[scene.triangles].mean(axis=1)[:, 0] < 0
    scene.object_id = np.where(west, 0, 1).astype(np.int32)
    scene.objects = ["West", "East"]
    scene.uvs["own"] = uvs
    assert shared_atlas_problem(scene) is None  # halves of one chart: neighbours, not overlapping
    stacked = uvs.copy().reshape(-1, 3, 2)
    stacked[~west] -= (stacked[~west].min(axis=(0, 1)) - stacked[west].min(axis=(0, 1)))  # east onto west
    scene.uvs["own"] = stacked.reshape(-1, 2)
    assert "'West' and 'East'" in shared_atlas_problem(scene)


def test_shared_atlas_check_names_the_objects_that_do_share_one():
    # Two objects laid out together and a third whose map (a texture map the automatic choice took)
    # covers the whole square: the message hands the user the --objects of the two.
    from lmrefine.scene_export import shared_atlas_problem
    from test_surface_view import plane_scene

    scene = plane_scene()
    uvs = scene.uvs.pop("smart").reshape(-1, 3, 2)
    centres = scene.positions[scene.triangles].mean(axis=1)
    west, south = centres[:, 0] < 0, centres[:, 1] < 0
    scene.object_id = np.where(west & south, 2, np.where(west, 0, 1)).astype(np.int32)
    scene.objects = ["West", "East", "Dome"]
    scene.uv_maps = {"West": "Lightmap", "East": "Lightmap", "Dome": "UVMap"}
    dome = scene.object_id == 2
    low, high = uvs[dome].min(axis=(0, 1)), uvs[dome].max(axis=(0, 1))
    uvs[dome] = 0.05 + 0.9 * (uvs[dome] - low) / (high - low)  # the whole square: over both others
    scene.uvs["own"] = uvs.reshape(-1, 2)
    problem = shared_atlas_problem(scene)
    assert "cover the same part of the UV square" in problem
    assert "these share one atlas: --objects West,East (leaving out 'Dome' (its map 'UVMap'))" in problem


def test_evaluate_names_a_file_that_is_no_scene(tmp_path, capsys):
    (tmp_path / "level.fbx").write_bytes(b"Kaydara FBX Binary  \x00")
    assert cli.main(["evaluate", str(tmp_path / "level.fbx"), "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert "is not a scene .npz" in error and "export-scene" in error
    np.save(tmp_path / "one.npy", np.zeros(3))
    assert cli.main(["evaluate", str(tmp_path / "one.npy"), "--out", str(tmp_path / "out")]) == 2
    assert "not a scene .npz" in capsys.readouterr().err


def test_export_scene_names_a_missing_or_wrong_file(tmp_path, capsys):
    assert cli.main(["export-scene", str(tmp_path / "nowhere.blend")]) == 2
    assert "no such file: '" in capsys.readouterr().err
    (tmp_path / "scene.npz").write_bytes(b"")
    assert cli.main(["export-scene", str(tmp_path / "scene.npz")]) == 2
    assert "is not a .blend file" in capsys.readouterr().err
    (tmp_path / "level.blend").write_bytes(b"BLENDER")
    (tmp_path / "a_file").write_bytes(b"")
    assert cli.main(["export-scene", str(tmp_path / "level.blend"), "-o", str(tmp_path / "a_file" / "s.npz")]) == 2
    assert "cannot write '" in capsys.readouterr().err


@blender
@needs_blender
@pytest.mark.slow
def test_evaluate_takes_a_blend_and_reports_the_ratio(level, tmp_path, capsys):
    out = tmp_path / "out"
    flags = ["--resolution", "32", "--points", "1000", "--samples", "4", "--truth-samples", "16",
             "--multipliers", "1,2,3", "--view-width", "96", "--out", str(out)]
    assert cli.main(["evaluate", level, *flags]) == 0
    report = json.loads((out / "level_own" / "report.json").read_text())
    assert report["scene"] == "level" and report["variant"] == "own" and report["resolution"] == 32
    assert report["equal_error_resolution_ratio"] is not None and report["equal_error_resolution_ratio"] > 0
    assert report["rmse_baseline"] > 0 and [o["object"] for o in report["objects"]] == ["Floor"]
    assert report["surface"]["camera"] == "Camera" and report["surface"]["width"] == 96
    assert (out / "level_own" / "surface.png").stat().st_size > 0
    assert (out / "scenes" / "level.npz").is_file()
    assert "equal-error" in (out / "report.md").read_text()
    capsys.readouterr()
    # Again: the export is reused while the .blend is unchanged.
    assert cli.main(["evaluate", level, *flags, "--view-width", "0"]) == 0
    assert "exported before, unchanged" in capsys.readouterr().out
