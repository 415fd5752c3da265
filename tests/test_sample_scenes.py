import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

import lmrefine
from lmrefine import sample_scenes

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("courtyard", "room", "fence_and_tree", "game_level", "atrium", "plaza", "alley", "village", "cloister",
         "depot", "stairs", "hillside")
# Coarse on purpose (for the tessellation option): its triangles are metres long.
COARSE = ("plaza",)
FINE = tuple(name for name in NAMES if name not in COARSE)


def test_every_bundled_scene_loads_with_consistent_arrays():
    assert set(NAMES) <= set(sample_scenes.sample_names())
    for name in NAMES:
        scene = sample_scenes.load_sample(name)
        triangles = len(scene.triangles)
        assert (100 if name in COARSE else 2000) < triangles < 20000, name
        assert scene.triangles.min() >= 0 and scene.triangles.max() < len(scene.positions)
        assert scene.normals.shape == (3 * triangles, 3)
        np.testing.assert_allclose(np.linalg.norm(scene.normals, axis=1), 1.0, atol=1e-4)
        for variant in ("smart", "lightmap"):
            uvs, corner_triangles = scene.layout(variant)
            assert uvs.shape == (3 * triangles, 2) and corner_triangles.shape == (triangles, 3)
            assert uvs.min() >= 0.0 and uvs.max() <= 1.0
            # Every receiver triangle has lightmap area (no zero-area UVs).
            uv = uvs.reshape(-1, 3, 2)
            area = np.abs(np.cross(uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0])) / 2
            assert (area > 0).all(), (name, variant)
        assert (scene.triangle_areas() > 0).all()
        assert scene.base_color.shape == (triangles, 3) and 0 <= scene.base_color.min() <= scene.base_color.max() <= 1
        assert set(np.unique(scene.object_id)) == set(range(len(scene.objects)))
        assert scene.lights and all(light["kind"] in sample_scenes.LIGHT_PROPERTIES for light in scene.lights)
        # The face each triangle was cut from: a face's triangles share an edge with one another, and
        # one object's faces are never another's.
        faces = scene.polygons
        assert faces.shape == (triangles,) and faces.min() >= 0
        for face in np.flatnonzero(np.bincount(faces) > 1)[:200]:
            members = scene.triangles[faces == face]
            assert len(set(members.ravel().tolist())) == len(members) + 2, (name, face)
            assert len(set(scene.object_id[faces == face].tolist())) == 1


def test_every_bundled_scene_is_either_for_tuning_or_for_reporting():
    tuning, reporting = set(sample_scenes.TUNING_SCENES), set(sample_scenes.REPORTING_SCENES)
    assert tuning == {"courtyard", "game_level", "fence_and_tree"}
    assert not tuning & reporting
    assert tuning | reporting == set(sample_scenes.sample_names()) == set(NAMES)


def _assert_valid_small_sample(scene, name):
    """Both atlases of a bundled holdout pass check_layout with 2-texel gutters at the resolutions they
    were made for (Smart UV 256^2, Lightmap Pack 512^2), and its .blend stays small."""
    for variant, resolution in (("smart", 256), ("lightmap", 512)):
        uvs, triangles = scene.layout(variant)
        report = lmrefine.check_layout(uvs, triangles, resolution, padding=2)
        assert report["valid"] and report["min_gutter_texels"] >= 2.0, (variant, report)
    assert (ROOT / "blend_samples" / f"{name}.blend").stat().st_size < 300_000


def test_atrium_has_a_sun_a_spot_and_a_rectangular_area_light_over_valid_layouts():
    scene = sample_scenes.load_sample("atrium")
    lights = {light["kind"]: light for light in scene.lights}
    assert sorted(lights) == ["area", "spot", "sun"]
    assert lights["area"]["shape"].upper() == "RECTANGLE" and lights["area"]["size"] != lights["area"]["size_y"]
    assert len(scene.occluder_triangles) > 0  # the lattice roof casts, is not lightmapped
    _assert_valid_small_sample(scene, "atrium")


def test_alley_is_a_street_of_walls_under_a_sun_and_two_lamps_over_valid_layouts():
    scene = sample_scenes.load_sample("alley")
    assert sorted(light["kind"] for light in scene.lights) == ["point", "point", "sun"]
    assert len(scene.occluder_triangles) > 0  # the beams across the street cast, are not lightmapped
    # Most of the receiver area is vertical (the two house fronts), unlike the other scenes' floors.
    corner_normals = scene.normals.reshape(-1, 3, 3).mean(axis=1)
    vertical = np.abs(corner_normals[:, 2]) < 0.1
    assert scene.triangle_areas()[vertical].sum() > 0.5 * scene.triangle_areas().sum()
    _assert_valid_small_sample(scene, "alley")


def test_village_smart_uv_charts_fold_over_creases_over_valid_layouts():
    # The holdout of the re-chart route's folds rule: Smart UV Project's charts fold over the pitched
    # roof's ridge, the octagonal kiosk's sides and the ramp's crest (creases of 25-60 degrees).
    from lmrefine.folds import fold_faces
    scene = sample_scenes.load_sample("village")
    assert [light["kind"] for light in scene.lights] == ["sun"] and len(scene.occluder_triangles) > 0
    positions = scene.positions[scene.triangles].reshape(-1, 3)
    uvs, triangles = scene.layout("smart")
    faces, _, length = fold_faces(uvs, triangles, positions, 20.0)
    assert len(faces) > 20 and length.sum() > 10.0
    uvs, triangles = scene.layout("lightmap")
    assert len(fold_faces(uvs, triangles, positions, 20.0)[0]) == 0  # one chart per face: nothing folds
    _assert_valid_small_sample(scene, "village")


def test_cloister_is_smooth_shaded_where_it_is_curved_over_valid_layouts():
    # The smooth-shaded holdout (Shade Smooth, Auto Smooth 60 degrees): the columns, vault, well and mound
    # have one shading normal per vertex, so Smart UV's charts fold over edges the light does not step at.
    from lmrefine.folds import fold_faces, smooth_shaded
    scene = sample_scenes.load_sample("cloister")
    corners = scene.positions[scene.triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    smooth_corners = (scene.normals.reshape(-1, 3, 3) * face[:, None]).sum(axis=2) < 0.9999
    assert 0.3 < smooth_corners.mean() < 0.7  # the paving (flat) is about half the triangles
    positions = corners.reshape(-1, 3)
    uvs, triangles = scene.layout("smart")
    faces, corner, _ = fold_faces(uvs, triangles, positions, 20.0)
    smooth = smooth_shaded(positions, triangles, scene.normals, faces, corner)
    assert len(faces) > 50 and smooth.mean() > 0.8
    _assert_valid_small_sample(scene, "cloister")


def test_depot_has_props_resting_on_the_floor_and_on_each_other_over_valid_layouts():
    # The holdout made after the baker's border fix: crate faces lie on the floor and on other crates, so
    # chart borders run along contact lines; a skylit roof and the rack's uprights cast, are not lightmapped.
    scene = sample_scenes.load_sample("depot")
    assert sorted(light["kind"] for light in scene.lights) == ["area", "point", "sun"]
    assert len(scene.occluder_triangles) > 0
    corners = scene.positions[scene.triangles]
    normal_z = scene.normals.reshape(-1, 3, 3).mean(axis=1)[:, 2]
    crates = scene.object_id == scene.objects.index("Crates")
    on_floor = crates & (np.abs(corners[:, :, 2]).max(axis=1) < 1e-4) & (normal_z < -0.99)
    stacked = crates & (np.abs(corners[:, :, 2].max(axis=1) - corners[:, :, 2].min(axis=1)) < 1e-4) \
        & (corners[:, 0, 2] > 0.5) & (normal_z < -0.99)
    assert on_floor.sum() >= 20 and stacked.sum() >= 8  # crate bottoms on the floor, on other crates
    _assert_valid_small_sample(scene, "depot")


def test_stairs_have_a_comb_of_baluster_shadows_over_treads_and_risers_over_valid_layouts():
    # The holdout added with the unflip back-off: twelve steps, each a riser (facing the
    # viewer) and a tread (facing up); the balusters cast, are not lightmapped.
    scene = sample_scenes.load_sample("stairs")
    assert sorted(light["kind"] for light in scene.lights) == ["point", "sun"]
    assert len(scene.occluder_triangles) == 24 * 12  # 24 balusters, 6 quads each
    flight = scene.object_id == scene.objects.index("Flight")
    normals = scene.normals.reshape(-1, 3, 3).mean(axis=1)[flight]
    treads, risers = normals[:, 2] > 0.99, normals[:, 1] < -0.99
    assert treads.sum() == risers.sum() > 0 and (treads | risers).all()
    heights = np.unique(np.round(scene.positions[scene.triangles[flight]][..., 2], 4))
    assert len(heights) == 13  # ground level and the twelve steps' tops
    _assert_valid_small_sample(scene, "stairs")


def test_hillside_is_smooth_shaded_organic_ground_with_a_tight_lightmap_pack():
    # The organic holdout: rolling terrain and displaced boulders, smooth-shaded (the other
    # samples are flat-shaded), under a dead tree that casts but is not lightmapped.
    scene = sample_scenes.load_sample("hillside")
    assert sorted(light["kind"] for light in scene.lights) == ["point", "sun"]
    assert set(scene.objects) == {"Terrain", "Boulders"} and len(scene.occluder_triangles) > 0
    corner_normals = scene.normals.reshape(-1, 3, 3)
    smooth = np.linalg.norm(corner_normals - corner_normals[:, :1], axis=2).max(axis=1) > 1e-3
    assert smooth.mean() > 0.9  # corners of one triangle shade with different normals
    heights = scene.positions[scene.triangles[scene.object_id == scene.objects.index("Terrain")]][..., 2]
    assert heights.max() - heights.min() > 0.8  # rolling, not a floor
    uvs, triangles = scene.layout("smart")
    report = lmrefine.check_layout(uvs, triangles, 256, padding=2)
    assert report["valid"] and report["min_gutter_texels"] >= 2.0, report
    # Lightmap Pack boxes the boulders' triangles in pairs: those pairs sit closer than the
    # margin's 2 texels at 512^2, as Blender makes them for any triangulated mesh.
    uvs, triangles = scene.layout("lightmap")
    report = lmrefine.check_layout(uvs, triangles, 512, padding=1)
    assert report["valid"] and 1.0 <= report["min_gutter_texels"] < 2.0, report
    assert (ROOT / "blend_samples" / "hillside.blend").stat().st_size < 300_000
    # The terrain is quads (two triangles a face), the boulders triangles.
    per_face = np.bincount(scene.polygons)
    terrain = scene.object_id == scene.objects.index("Terrain")
    assert (per_face[scene.polygons[terrain]] == 2).all() and (per_face[scene.polygons[~terrain]] == 1).all()


def test_receivers_are_tessellated_finely_enough_to_move_texels():
    # The method moves vertices only (docs/method.md §5): the big receivers
    # must be cut into cells of about 0.3 m, not one quad (except the coarse
    # holdout, whose 2 m floor quads are what tessellation is measured on).
    for name in FINE:
        scene = sample_scenes.load_sample(name)
        edges = scene.positions[scene.triangles]
        longest = np.linalg.norm(edges - np.roll(edges, 1, axis=1), axis=2).max(axis=1)
        weights = scene.triangle_areas()
        assert np.average(longest, weights=weights) < 0.75, name
    plaza = sample_scenes.load_sample("plaza")
    edges = plaza.positions[plaza.triangles]
    assert np.linalg.norm(edges - np.roll(edges, 1, axis=1), axis=2).max(axis=1).min() > 0.5


def test_unknown_sample_names_the_known_ones():
    with pytest.raises(ValueError, match="courtyard"):
        sample_scenes.load_sample("no_such_scene")


def test_to_scene_builds_a_bakeable_scene():
    scene = sample_scenes.load_sample("fence_and_tree")
    uvs, _ = scene.layout("smart")
    built = scene.to_scene(uvs)
    # The receivers, the occluders (fence and tree) as a second mesh, every light.
    assert built.mesh_count == 2 and built.light_count == len(scene.lights) == 1
    atrium = sample_scenes.load_sample("atrium")
    built = atrium.to_scene(atrium.layout("smart")[0])
    assert built.mesh_count == 2 and built.light_count == 3
    with pytest.raises(ValueError, match="per corner"):
        scene.to_scene(uvs[:10])


@pytest.mark.blender
def test_blend_files_hold_the_exported_scenes(tmp_path):
    script = tmp_path / "check.py"
    script.write_text(
        "import bpy, json, sys\n"
        "out = {}\n"
        f"for name in {list(NAMES)!r}:\n"
        f"    bpy.ops.wm.open_mainfile(filepath=r'{ROOT / 'blend_samples'}/' + name + '.blend')\n"
        "    receivers = [o for o in bpy.data.objects if o.type == 'MESH' and o.get('lmrefine_receiver', True)]\n"
        "    for o in receivers: o.data.calc_loop_triangles()\n"
        "    out[name] = {'triangles': sum(len(o.data.loop_triangles) for o in receivers),\n"
        "                 'layers': sorted({l.name for o in receivers for l in o.data.uv_layers}),\n"
        "                 'lights': len([o for o in bpy.data.objects if o.type == 'LIGHT']),\n"
        "                 'packed': len([i for i in bpy.data.images if i.packed_file])}\n"
        f"open(r'{tmp_path / 'out.json'}', 'w').write(json.dumps(out))\n")
    subprocess.run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(script)],
                   check=True, capture_output=True)
    found = json.loads((tmp_path / "out.json").read_text())
    for name in NAMES:
        scene = sample_scenes.load_sample(name)
        assert found[name]["triangles"] == len(scene.triangles)
        assert found[name]["layers"] == ["Lightmap", "LightmapSmart"]
        assert found[name]["lights"] == len(scene.lights)
        assert found[name]["packed"] == 0
        assert (ROOT / "blend_samples" / f"{name}.blend").stat().st_size < 400_000


def test_scene_files_place_lights_by_matrix_and_older_files_still_load(tmp_path):
    """A light's matrix (make_samples.py writes matrix_world) places it with
    its spin and scale; a file without one (older) keeps Blender's default
    spin, and its lower-case shape still loads."""
    positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    triangles = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]], np.float32) * 0.9 + 0.05
    spun = np.eye(4)
    spun[:3, :3] = [[0, -2, 0], [1, 0, 0], [0, 0, 1]]  # local X along world y; local Y scaled 2
    spun[:3, 3] = [0, 0, 0.6]
    strip = dict(kind="area", name="Strip", energy=20.0, shape="RECTANGLE", size=1.0, size_y=0.1,
                 position=[0, 0, 0.6], direction=[0, 0, -1], matrix=spun.tolist())
    old = dict(kind="area", name="Old", energy=20.0, shape="rectangle", size=1.0, size_y=0.1,
               position=[0, 0, 0.6], direction=[0, 0, -1])
    points = np.array([[0.5, 0, 0], [0, 0.5, 0]], np.float32)
    normals = np.tile(np.float32([0, 0, 1]), (2, 1))
    values = {}
    for light in (strip, old):
        scene = sample_scenes.SampleScene(
            name="strip", positions=positions, triangles=triangles, normals=np.tile(normals[:1], (6, 1)),
            uvs={"smart": uvs}, base_color=np.full((2, 3), 0.8, np.float32), object_id=np.zeros(2, np.int32),
            objects=["Floor"], lights=[light])
        scene.save(tmp_path / "strip.npz")
        loaded = sample_scenes.load_sample(str(tmp_path / "strip.npz"))
        assert loaded.polygons is None  # a file without faces (written before them) loads
        built = loaded.to_scene(loaded.uvs["smart"])
        values[light["name"]] = lmrefine.evaluate(built, points, normals, samples=1024, seed=1)[:, 0]
    expected = {}
    for name, params in (("Strip", dict(size=1.0, size_y=0.2, axis_x=(0, 1, 0))), ("Old", dict(size=1.0, size_y=0.1))):
        scene = lmrefine.Scene()
        scene.add_light("area", energy=20.0, shape="RECTANGLE", position=(0, 0, 0.6), direction=(0, 0, -1), **params)
        expected[name] = lmrefine.evaluate(scene, points, normals, samples=1024, seed=1)[:, 0]
    np.testing.assert_allclose(values["Strip"], expected["Strip"], rtol=1e-5)
    np.testing.assert_allclose(values["Old"], expected["Old"], rtol=1e-5)
    # The spun strip runs along y, the old one along x.
    assert values["Strip"][1] > 1.3 * values["Strip"][0] and values["Old"][0] > 1.3 * values["Old"][1]


def test_lmrefine_samples_names_the_sample_folder_for_a_copy_of_python(tmp_path):
    """A bare copy of python/ (a baseline build for bench/compare_*.py) finds the scenes LMREFINE_SAMPLES names."""
    import os
    import shutil
    import sys

    copy = tmp_path / "python"
    shutil.copytree(ROOT / "python" / "lmrefine", copy / "lmrefine", ignore=shutil.ignore_patterns("__pycache__"))
    samples = tmp_path / "scenes"
    samples.mkdir()
    for name in ("plaza.npz", "plaza.blend"):
        shutil.copy(ROOT / "blend_samples" / name, samples)
    code = ("from lmrefine import sample_scenes as s; "
            "print(s.SAMPLES_DIR); print(s.sample_names()); print(len(s.load_sample('plaza').triangles))")

    def run(**env):
        return subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(copy), **env),
                              capture_output=True, text=True)

    found = run(LMREFINE_SAMPLES=str(samples))
    assert found.returncode == 0, found.stderr
    folder, names, triangles = found.stdout.split("\n")[:3]
    assert folder == str(samples) and names == "['plaza']" and int(triangles) > 0
    lost = run(LMREFINE_SAMPLES="")  # unset: the copy looks beside itself, where there are no scenes
    assert lost.returncode != 0 and "no sample scene 'plaza'" in lost.stderr


def test_scene_files_keep_the_face_of_each_triangle(tmp_path):
    scene = sample_scenes.load_sample("plaza")
    scene.save(tmp_path / "plaza.npz")
    np.testing.assert_array_equal(sample_scenes.load_sample(str(tmp_path / "plaza.npz")).polygons, scene.polygons)
    scene.polygons = scene.polygons[:-1]  # one short: not a face per triangle
    scene.save(tmp_path / "short.npz")
    with pytest.raises(ValueError, match="not one integer face id per triangle"):
        sample_scenes.load_sample(str(tmp_path / "short.npz"))
