"""The Blender add-on, driven through real headless Blender.

One Blender process runs every in-Blender check (tests/blender/addon_checks.py)
and writes facts as JSON; the tests below assert on them. The batch entry gets
its own processes because it is its own command line. Undo is tested in
background mode by pushing a step before the run (ed.undo_push with a window
in the context), calling the operator as a script with undo=True, then one
ed.undo: it must restore the scene, and no further step may remain, which
shows the whole run was a single undo step.
"""

import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

pytestmark = [pytest.mark.blender, pytest.mark.slow]  # each group starts Blender (~1.5 s)

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER = shutil.which("blender")
BATCH = os.path.join(REPO, "addon", "lmrefine_blender", "batch.py")

def exr_header(path):
    """Channel pixel types and compression of an OpenEXR file, from its header (OpenEXR file layout)."""
    data = path.read_bytes() if hasattr(path, "read_bytes") else open(path, "rb").read()
    assert data[:4] == b"\x76\x2f\x31\x01", "not an OpenEXR file"
    position, header = 8, {}
    while data[position] != 0:
        name_end = data.index(b"\0", position)
        type_end = data.index(b"\0", name_end + 1)
        kind = data[name_end + 1:type_end].decode()  # the attribute's type (its name is data[position:name_end])
        size = int.from_bytes(data[type_end + 1:type_end + 5], "little")
        value = data[type_end + 5:type_end + 5 + size]
        position = type_end + 5 + size
        if kind == "chlist":
            channels, at = {}, 0
            while value[at] != 0:
                end = value.index(b"\0", at)
                pixel_type = int.from_bytes(value[end + 1:end + 5], "little")
                channels[value[at:end].decode()] = ("UINT", "HALF", "FLOAT")[pixel_type]
                at = end + 1 + 16
            header["channels"] = channels
        elif kind == "compression":
            header["compression"] = ("NONE", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA",
                                     "DWAB")[value[0]]
    return header


def lmrefine_read(path):
    sys.path.insert(0, os.path.join(REPO, "python"))
    import lmrefine
    return lmrefine.read_image(str(path))


if BLENDER is None:
    pytest.skip("Blender is not installed", allow_module_level=True)


def run_blender(*args, timeout=600):
    return subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def work_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("blender_addon")


@pytest.fixture(scope="module")
def facts(work_dir):
    out = work_dir / "facts.json"
    process = run_blender("--python", os.path.join(REPO, "tests", "blender", "addon_checks.py"), "--",
                          REPO, str(out), str(work_dir))
    assert process.returncode == 0, process.stdout[-3000:] + process.stderr[-3000:]
    return json.loads(out.read_text())


def fact(facts, name):
    value = facts[name]
    if "exception" in value:
        pytest.fail(f"check {name} raised inside Blender:\n{value['exception']}")
    return value


def test_register_and_unregister(facts):
    value = fact(facts, "registration")
    registered, unregistered = value["registered"], value["unregistered"]
    assert len(registered["panels"]) == 6
    assert registered["category"] == "Lightmap" and registered["space"] == "VIEW_3D"
    assert registered["operators"] == [True, True] and registered["label"] == "Refine Lightmap UVs"
    assert registered["scene_property"]
    assert unregistered == {"panels": [], "scene_property": False, "operator": False}


# ------------------------------------------------------------ error cases

ERRORS = {
    "error_no_mesh": "No mesh selected",
    "error_only_light_selected": "No mesh selected",
    "error_no_uv_layer": "'Bare' has no UV map",
    "error_missing_source_layer": "has no UV map 'NoSuchMap'",
    "error_edit_mode": "works in Object Mode, not Edit Mesh",
    "error_only_bad_objects": "'Flat' has no area in 3-D",
    "error_linked_library": "is linked from",
    "error_hidden_object": "'Floor' is hidden",
    "error_image_not_found": "No lightmap image found for 'Floor'",
    "error_image_file_missing": "has no pixels",
    "error_image_wrong_size": "is 16x16 but Resolution is 64",
    "error_no_bake_pass": "No bake pass chosen",
    "error_image_from_refined_bake": "was baked with a refined UV map",
    "error_uvs_outside_unit_square": "has 1 UVs outside [0, 1], so it looks like a texture map (tiling)",
    "error_stacked_faces_in_the_source_map": "has faces stacked on each other (together they cover",
}


@pytest.mark.parametrize("name", sorted(ERRORS))
def test_error_is_reported_and_changes_nothing(facts, name):
    value = fact(facts, name)
    assert value["outcome"] == "CANCELLED"
    assert value["message"] is not None and ERRORS[name] in value["message"]
    assert value["changed"] == []


def test_refusals_of_several_objects_read_one_a_line(facts):
    """Every selected object refused: one message, each refusal a sentence on a line of its own (Blender's
    report popup and Info log show each line as a row); they used to run together."""
    message = fact(facts, "error_only_bad_objects")["message"]
    assert message.strip().removeprefix("Error: ").split("\n") == [
        "'Bare' has no UV map: add one for the lightmap (Object Data > UV Maps > +, then UV > Lightmap Pack).",
        "'Flat' has no area in 3-D (zero scale, or only degenerate faces): give it a non-zero scale or real faces."]
    value = fact(facts, "refusal_wording")
    assert value["one_per_line"] == ["'A' is hidden: show it.\n'B' has no UV map.", "'A' is hidden: show it"]


def test_messages_name_settings_as_their_reader_sets_them(facts):
    """The add-on's messages name a setting by its panel label (never a batch flag); the batch's, by its flag."""
    message = fact(facts, "error_missing_source_layer")["message"]
    assert message.strip().endswith("pick the lightmap UV map as Source (top of the panel)")
    refusal = fact(facts, "setting_wording")
    assert refusal["panel"].endswith("set Source (top of the panel) to the one to refine")
    assert refusal["batch"].endswith("pass the one to refine with --source-layer")


def test_a_noisy_first_lightmap_is_named_with_the_samples_it_needs(facts):
    """Noise the refiner would take for light changes (seed 317 from Lightmap Pack with First Map Cycles at
    the default 16 samples: noise 9.9% of the median light, texels at light changes 1.09x where Embree's
    first map, 1.0%, gave 6.98x): the warning gives the noise and the Samples that bring it under 2%."""
    from lmrefine.metrics import NOISY_FIRST_MAP
    value = fact(facts, "noisy_first_map_is_named")
    for key, samples, cycles in (("cycles_1", 1, True), ("embree_16", 16, False)):
        assert value[key]["error"] is None
        noisy = [w for w in value[key]["warnings"] if "the first lightmap is noisy" in w]
        assert len(noisy) == 1 and noisy[0].startswith("'Floor': the first lightmap is noisy (noise "), value[key]
        noise = float(re.search(r"noise ([\d.]+)% of its median light", noisy[0]).group(1)) / 100
        assert noise > NOISY_FIRST_MAP
        needed = int(re.search(r"raise Samples to (\d+) or more", noisy[0]).group(1))
        assert needed >= samples * (noise / NOISY_FIRST_MAP) ** 2 * 0.9 and needed & (needed - 1) == 0
        assert needed < 2 * samples * (noise / NOISY_FIRST_MAP) ** 2 * 1.1
        assert ("set First Map to Embree" in noisy[0]) == cycles and "--" not in noisy[0]
    assert value["cycles_64"]["error"] is None
    assert not any("noisy" in w for w in value["cycles_64"]["warnings"]), value["cycles_64"]


def test_bad_objects_are_skipped_with_their_fix_and_the_others_refined(facts):
    value = fact(facts, "skip_bad_objects_refines_the_others")
    assert value["error"] is None and value["objects"] == ["Floor"]
    skipped = value["skipped"]
    assert len(skipped) == 4
    twin = "share mesh 'FloorMesh': UV maps belong to the mesh, so only 'Floor' is refined; to give each its own"
    for name, advice in (("FloorTwin", twin), ("Bare", "has no UV map"),
                         ("Flat", "has no area in 3-D"), ("Broken", "1 vertices at NaN, Inf or beyond 1e9")):
        assert any(f"'{name}'" in w and advice in w for w in skipped), (name, skipped)
    # The broken mesh is left out of the bake as an occluder too (the baker refuses NaN), and says so.
    assert any(w.startswith("'Broken' casts no shadow in the bake") for w in value["warnings"])
    # Only the floor (its mesh, its material's preview) and the new images changed; the skipped meshes did not.
    assert value["changed"] == ["images", "material:FloorMaterial", "mesh:FloorMesh"]
    assert value["operator"] == "FINISHED", value["message"]


def test_objects_with_nothing_to_lightmap_are_skipped_with_their_cause(facts):
    value = fact(facts, "faceless_objects_are_named_with_their_cause")
    assert value["error"] is None and value["objects"] == ["Floor"]
    assert sorted(value["skipped"]) == [
        "Skipped: 'Collapsed': its modifiers (Weld) remove every face: disable the modifier that removes them",
        "Skipped: 'Emptied' is an empty mesh (no vertices): there is nothing to lightmap",
        "Skipped: 'Guide' is a mesh without faces (2 vertices, 1 edges): a lightmap needs faces: fill them in "
        "(Edit Mode > Face > Fill)"]


def test_zero_area_faces_are_skipped_and_counted(facts):
    value = fact(facts, "zero_area_faces_are_skipped_and_counted")
    assert value["error"] is None and value["objects"] == ["Sliver"] and value["refined"]
    assert any("1 triangles of zero area in 3-D were skipped" in w for w in value["warnings"])


def test_a_core_refusal_skips_only_that_object(facts):
    value = fact(facts, "core_refusal_skips_the_object")
    assert value["error"] is None and value["objects"] == ["Floor"] and value["floor_refined"]
    assert len(value["skipped"]) == 1 and "'Blocker' could not be refined: uvs: refused" in value["skipped"][0]
    assert value["box_unchanged"]
    # No C++ source location in what the user reads (the console keeps the full text).
    assert "cpp" not in value["skipped"][0] and value["skipped"][0].endswith("refused for the test")
    assert value["operator_messages"] == [
        "lmrefine: triangles[0] refers to UV 5",
        "Refinement failed (RuntimeError: Embree failed); the scene was left unchanged"]


def test_a_late_core_failure_leaves_the_scene_unchanged(facts):
    value = fact(facts, "core_failure_late_leaves_the_scene_unchanged")
    assert value["calls"] == 2 and value["outcome"] == "CANCELLED"
    assert "RuntimeError: baker failed for the test" in value["message"]
    assert value["changed"] == []


def test_refine_defaults_match_the_library(facts):
    value = fact(facts, "refine_defaults_match_the_library")
    assert value["missing"] == []
    for key, default in value["theirs"].items():
        assert value["ours"][key] == pytest.approx(default), key


# ----------------------------------------------------------------- bridge

def test_bridge_exports_world_space_geometry_and_lights(facts):
    value = fact(facts, "bridge_export")
    assert value["default_source"] == "Lightmap"
    # Floor: a 4 m grid moved to (1, 2, 3) and scaled 2x along x.
    assert value["x_range"] == pytest.approx([-3.0, 5.0], abs=1e-5)
    assert value["y_range"] == pytest.approx([0.0, 4.0], abs=1e-5)
    assert value["z_range"] == pytest.approx([3.0, 3.0], abs=1e-5)
    assert value["normal_mean"] == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)
    assert value["uvs_match_layout"] and value["triangles_match_layout"]
    assert value["triangle_count"] == 24 * 24 * 2
    assert value["base_color"] == pytest.approx([0.8, 0.8, 0.8], abs=1e-6)
    # The blocker (1 m cube at z = 1) is an occluder until it is hidden from render.
    assert value["occluders"] == ["Blocker"] and value["occluders_when_hidden"] == []
    assert value["blocker_z_range"] == pytest.approx([0.5, 1.5], abs=1e-5)
    assert value["light_kind"] == "sun"
    sun = value["sun"]
    assert sun["energy"] == 3.0 and sun["angle"] == pytest.approx(0.02)
    # Rotation (0.3, 0.2, 0) applied to -Z: where the sun points is the matrix's -Z column.
    assert (-np.array(sun["matrix"])[:3, 2]).tolist() == pytest.approx([-0.18980, 0.29552, -0.93629], abs=1e-4)
    assert value["world"] == [0.0, 0.0, 0.0]


def test_lights_in_blender_units_and_world_space(facts):
    value = fact(facts, "bridge_lights")
    assert value["count"] == 5  # the zero-energy light is left out
    # Each light is placed by its world matrix (rows). Rotated 90 degrees about
    # x, a light's -Z (where it points) becomes +Y and its X stays +X.
    for kind in ("point", "spot", "sun", "area"):
        matrix = np.array(value[kind]["matrix"])
        assert matrix[:3, 3] == pytest.approx([1.0, 2.0, 3.0], abs=1e-6)
        assert -matrix[:3, 2] / np.linalg.norm(matrix[:3, 2]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-6)
        assert matrix[:3, 0] / np.linalg.norm(matrix[:3, 0]) == pytest.approx([1.0, 0.0, 0.0], abs=1e-6)
    assert value["point"]["shadow_soft_size"] == pytest.approx(0.3)
    assert value["spot"]["spot_size"] == pytest.approx(0.8) and value["spot"]["spot_blend"] == pytest.approx(0.25)
    assert value["sun"]["angle"] == pytest.approx(0.1)
    area = value["area"]
    assert area["shape"] == "RECTANGLE"
    # Blender's own sizes; the object's scale (3, 2, 1) rides in the matrix,
    # and the baker stretches the light by it as Cycles does.
    assert area["size"] == pytest.approx(2.0) and area["size_y"] == pytest.approx(0.5)
    assert np.linalg.norm(np.array(area["matrix"])[:3, :3], axis=0) == pytest.approx([3.0, 2.0, 1.0])
    assert area["color"] == pytest.approx([1.0, 0.5, 0.25])
    assert area["energy"] == pytest.approx(10.0)  # Blender's default area light power, in W
    # A square scaled (1.5, 0.3, 1) and spun: lit as a 1.5 x 0.3 m rectangle along its own axes.
    from_bridge, explicit = (np.array(v) for v in value["strip_values"])
    assert explicit.min() > 0.05
    np.testing.assert_allclose(from_bridge, explicit, rtol=1e-5)


def test_layout_is_welded_within_blenders_connect_limit(facts):
    value = fact(facts, "bridge_welds_blender_layouts")
    # The premise: Blender's own grid reads as several bit-identical-UV charts, a few UVs past 1.
    assert value["raw_charts"] > 1 and value["raw_out_of_bounds"] > 0
    assert value["welded_charts"] == 1 and value["welded_in_bounds"]
    assert value["welded_max_shift"] < 1e-4
    assert value["raw_unchanged"]


def test_a_second_click_bakes_the_materials_not_the_preview(facts):
    # The first run's preview shows the lightmap through an Emission: read as the floor's colour it
    # doubled the indirect light, and in a Cycles bake it turned the first lightmap black.
    value = fact(facts, "second_click_bakes_the_materials_not_the_preview")
    for backend, run in value.items():
        assert run["outcomes"] == ["FINISHED", "FINISHED"], run["messages"]
        assert run["preview_output_active"] == [True, True]
        for name, difference in run["max_difference"].items():
            assert run["means"][0][name] > 0.01, (backend, name)
            assert difference < 1e-5, (backend, name, run["means"])


def test_undo_after_a_second_run_brings_back_the_first_runs_lightmap(facts):
    # Pixels written from Python are not in Blender's undo: the second run writes a new image (and a
    # new file) and the first run's stays as it was, so Ctrl+Z shows the first run's map, not garbage.
    value = fact(facts, "undo_after_a_second_run_brings_back_the_first_runs_lightmap")
    assert value["outcomes"] == ["FINISHED", "FINISHED"]
    assert value["runs_differ"] > 0.01  # the second run's map is another
    assert value["undone_difference"] == 0.0 and value["uvs_difference"] == 0.0
    assert value["reloaded_difference"] < 1e-3  # its file too (half-float EXR)
    assert value["files"] == ["Floor_lightmap_before.exr", "Floor_lightmap_before_2.exr",
                              "Floor_lightmap_direct.exr", "Floor_lightmap_direct_2.exr"]
    assert value["preview_images"] == ["Floor_lightmap_direct"]
    assert "Floor_lightmap_direct (earlier run)" not in value["images"]  # undone with the run


def test_default_source_layer(facts):
    assert fact(facts, "bridge_default_layers") == {
        "UVMap": "UVMap",
        "UVMap+UVMap.001": "UVMap.001",
        "UVMap+Detail+LightmapUV": "LightmapUV",
        "A+B+C": "B",
        "UVMap+UVMap.001+UVMap.001_refined": "UVMap.001",
        # A per-effect run's maps are outputs too, not the lightmap source.
        "UVMap+UVMap_refined_direct+UVMap_refined_indirect": "UVMap",
    }


def test_image_rows_are_flipped_once(facts):
    assert fact(facts, "bridge_image_roundtrip") == {"roundtrip_equal": True, "bottom_row_first": True}


def test_cycles_bake_matches_lambert_and_restores_scene(facts):
    value = fact(facts, "cycles_first_bake")
    assert value["shape"] == [64, 64, 4]
    assert value["covered_texels"] > 0.8 * 64 * 64
    # Diffuse direct with colour off is irradiance / pi: sun 3 W/m^2 at cos 0.93629.
    assert value["light_max"] == pytest.approx(3.0 * 0.93629 / 3.14159265, rel=0.03)
    assert value["light_min"] < 0.05  # the blocker's umbra
    assert 0.5 < value["lit_fraction"] < 0.98
    assert value["changed"] == [] and value["engine_restored"]


# ------------------------------------------------------------- end to end

@pytest.mark.parametrize("name", ["end_to_end_embree", "end_to_end_cycles", "end_to_end_existing_image"])
def test_operator_end_to_end(facts, name):
    value = fact(facts, name)
    assert value["outcome"] == "FINISHED", value.get("message")
    assert value["layers"] == ["UVMap", "Lightmap", "Lightmap_refined"]
    # The render UV map keeps its role (the preview makes the refined map the active one, for Solid
    # shading's Texture colour, until it is removed); source and mesh are bit-identical.
    assert value["active_layer"] == "Lightmap_refined" and value["render_layer"] == "UVMap"
    assert value["source_identical"] and value["texture_uvs_identical"] and value["geometry_identical"]
    assert value["check_layout"]["valid"] is True
    assert value["check_layout"]["min_gutter_texels"] >= 2
    assert value["uv_max_move"] > 0.5 / 64  # the shadow edge pulled UVs by more than half a texel
    changed = set(value["changed"])
    assert "mesh:FloorMesh" in changed and "mesh:Cube" not in changed
    for name_, stats in value["images"].items():
        assert stats is not None, f"no image for pass {name_}"
        assert stats["size"] == [64, 64] and stats["is_float"] and stats["packed"]
        assert stats["std"] > 0.01 and stats["max"] > 0.1, f"pass {name_} looks unbaked: {stats}"
        # The gutter is lmrefine.dilate's (to the stored image's half-float precision).
        assert stats["gutter_change"] <= 2e-3 * max(1.0, stats["max"]), f"pass {name_}: {stats}"
    assert ("ShaderNodeUVMap", "Lightmap_refined") in [tuple(node) for node in value["preview_nodes"]]
    assert value["result_valid"] and value["transition_widening"] > 1.0
    assert 0.0 < value["density_range"][0] <= value["density_range"][1]
    low, high = value["density_range"]
    assert f"a triangle's texels {low:.2g}x to {high:.3g}x" in value["message"], value["message"]
    # The panel's timings ("first bake 0.12s  refine 0.30s  ..."): every stage
    # that ran, in order; an existing image needs no first bake.
    stages = re.findall(r"([a-z ]+?) \d+\.\d\ds", value["timings"].replace("  ", " "))
    first = [] if name == "end_to_end_existing_image" else ["first bake"]
    assert [stage.strip() for stage in stages] == first + ["refine", "second bake"], value["timings"]


@pytest.mark.parametrize("name", ["end_to_end_embree", "end_to_end_cycles", "end_to_end_existing_image"])
def test_operator_is_one_undo_step(facts, name):
    value = fact(facts, name)
    assert value["can_undo"]
    assert value["changed_after_undo"] == []
    assert value["can_undo_further"] is False


def test_two_objects_in_one_run(facts):
    value = fact(facts, "end_to_end_two_objects")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["Floor"]["charts"] == 1 and value["Blocker"]["charts"] == 6
    for name in ("Floor", "Blocker"):
        assert value[name]["valid"] and value[name]["min_gutter_texels"] >= 2
        assert value[name]["image"] is not None and value[name]["image"]["max"] > 0.1
        assert value[name]["image"]["gutter_change"] <= 2e-3 * max(1.0, value[name]["image"]["max"])
    # The floor gets the box's shadow: dark and lit texels on the same map.
    assert value["Floor"]["image"]["min"] < 0.05 and value["Floor"]["image"]["max"] > 0.5


def test_a_cycles_bake_gets_the_bakers_gutter(facts):
    """Cycles' margin (EXTEND) averages the box's neighbouring charts into the gutter between them;
    the stored map's gutter is refilled as lmrefine's baker fills it (lmrefine.dilate)."""
    value = fact(facts, "end_to_end_two_objects_cycles")
    assert value["outcome"] == "FINISHED", value["message"]
    for name in ("Floor", "Blocker"):
        assert value[name]["image"] is not None and value[name]["image"]["max"] > 0.1
        image = value[name]["image"]
        assert image["gutter_change"] <= 2e-3 * max(1.0, image["max"]), (name, image)


ATLAS = ("Blocker", "Floor", "Post")


def test_a_shared_atlas_gets_one_image_per_pass_that_every_member_shows(facts):
    value = fact(facts, "shared_atlas_one_image_per_pass")
    assert value["outcome"] == "FINISHED", value["message"]
    # Two maps: the atlas of three (named after its largest member) and Lonely's own lightmap.
    shared = "Blocker, Floor, Post"
    assert value["images"] == {"Floor_atlas_lightmap_ao": shared, "Floor_atlas_lightmap_before": shared,
                               "Floor_atlas_lightmap_direct": shared, "Lonely_lightmap_ao": "Lonely",
                               "Lonely_lightmap_before": "Lonely", "Lonely_lightmap_direct": "Lonely"}
    assert value["result_images"] == 2
    assert "2 image(s) per pass for 4 object(s) (Floor_atlas_lightmap_*: Blocker, Floor, Post)" in value["message"]
    for name in ATLAS:
        member = value["objects"][name]
        assert member["preview_image"] == "Floor_atlas_lightmap_direct" and member["preview_uv"] == "Lightmap_refined"
        assert member["before_image"] == "Floor_atlas_lightmap_before"
        # The shared image holds this object's light where its refined charts lie.
        assert member["texels"] > 100 and member["light_max"] > 0.5
    assert value["objects"]["Lonely"]["preview_image"] == "Lonely_lightmap_direct"
    # One refinement of the joined layout: no two members' charts share a texel, gutters kept.
    assert value["shared_texels"] == {"Blocker/Floor": 0, "Blocker/Post": 0, "Floor/Post": 0}
    assert value["joined_check"]["valid"] and value["joined_check"]["min_gutter_texels"] >= 2
    assert value["joined_repacked"]
    assert value["changed_after_undo"] == [] and value["can_undo_further"] is False


@pytest.mark.parametrize("name", ["shared_atlas_cycles", "shared_atlas_stages_and_tessellation"])
def test_a_shared_atlas_with_cycles_and_with_stages(facts, name):
    value = fact(facts, name)
    assert value["outcome"] == "FINISHED", value["message"]
    assert sorted(value["images"]) == ["Floor_atlas_lightmap_before", "Floor_atlas_lightmap_direct",
                                       "Lonely_lightmap_before", "Lonely_lightmap_direct"]
    for name in ATLAS:
        member = value["objects"][name]
        assert member["preview_image"] == "Floor_atlas_lightmap_direct"
        # Its light is in the shared image, and every chart keeps texels of its own for bilinear lookup
        # (2 x 2): a flat box shrinks stage after stage (each stage's chart scales are bounded relative
        # to that stage's median chart, not to the first stage's layout).
        assert member["light_max"] > 0.5 and member["smallest_chart_texels"] >= 4, member
    assert set(value["shared_texels"].values()) == {0}
    assert value["joined_check"]["valid"] and value["joined_check"]["min_gutter_texels"] >= 2
    assert value["changed_after_undo"] == [] and value["can_undo_further"] is False
    # The panel's short line for each map that stopped early names the report's reason.
    for line in filter(None, value["stages_stopped"].split("; ")):
        map_name, why = line.split(": ", 1)
        reason = value["message"].split(f"{map_name}: ", 1)[1].split(":")[0]  # "stage N ... under X%"
        assert why.startswith(f"stage {reason.split()[1]} "), (line, reason)
        assert ("backed off" in why) == ("kept only" in reason), (line, reason)
        assert ("no edge gain" in why) == ("gave its light changes" in reason), (line, reason)


def test_a_shared_atlas_driven_by_an_existing_atlas_image(facts):
    value = fact(facts, "shared_atlas_from_an_existing_image")
    assert value["first"] == ["FINISHED", None]
    assert value["outcome"] == "FINISHED", value["message"]
    # The members' one image drove one refinement; it stays their "before", no new one is stored. The
    # first run's direct image stays as it was for Ctrl+Z, without its fake user (dropped on save).
    assert value["images"] == ["Floor_atlas_lightmap_before", "Floor_atlas_lightmap_direct",
                               "Floor_atlas_lightmap_direct (earlier run)"]
    assert value["earlier_fake_user"] is False
    assert set(value["before_images"].values()) == {"Floor_atlas_lightmap_before"}
    assert set(value["after_images"].values()) == {"Floor_atlas_lightmap_direct"}
    assert value["result_images"] == 1 and value["moved"]["Floor"] > 0.01


def test_removing_a_shared_atlas_preview_restores_every_member(facts):
    value = fact(facts, "shared_atlas_preview_removal")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["removed"] == ["FINISHED"] and value["previews_left"] == []
    # The meshes keep their new refined map, the images stay; every material is as it was.
    assert value["changed"] == ["images", "mesh:Cube", "mesh:Cube.001", "mesh:FloorMesh", "mesh:Plane", "result"]


def test_shared_atlas_off_gives_one_image_per_object(facts):
    value = fact(facts, "shared_atlas_off_one_image_per_object")
    assert value["outcome"] == "FINISHED", value["message"]
    assert sorted(value["images"]) == sorted(f"{name}_lightmap_{kind}" for name in ATLAS + ("Lonely",)
                                             for kind in ("ao", "before", "direct"))
    assert value["result_images"] == 4
    for name in ATLAS + ("Lonely",):
        assert value["objects"][name]["preview_image"] == f"{name}_lightmap_direct"
    # Each object refined on its own fills its own map: the members now cover the same texels.
    assert value["shared_texels"]["Blocker/Post"] > 0 and not value["joined_check"]["valid"]
    assert value["changed_after_undo"] == []


def test_atlas_groups_do_not_depend_on_the_selection_order(facts):
    groups = fact(facts, "shared_atlas_grouping_ignores_selection_order")["groups"]
    expected = [["Floor_atlas", ["Blocker", "Floor", "Post"]], ["Lonely", ["Lonely"]]]
    assert groups == [expected, expected]


def test_copies_made_by_modifiers_skip_the_object_and_inside_out_meshes_are_named(facts):
    value = fact(facts, "copies_and_inside_out_meshes_are_named")
    assert value["error"] is None and value["objects"] == ["Floor", "Blocker"]
    skipped = [w for w in value["warnings"] if w.startswith("Skipped: ")]
    assert len(skipped) == 1 and "'Arrayed': its modifiers (Row) copy faces with their UVs" in skipped[0]
    assert "Visual Geometry to Mesh" in skipped[0] and "Lightmap Pack" in skipped[0]
    assert value["arrayed_layers"] == ["UVMap", "Lightmap"]  # skipped: nothing written
    inside_out = [w for w in value["warnings"] if "inside out" in w]
    assert len(inside_out) == 1 and inside_out[0].startswith("'Blocker': it is inside out")
    assert "Recalculate Outside" in inside_out[0]
    black = [w for w in value["warnings"] if "first lightmap is black" in w]
    assert len(black) == 1 and "(its faces point inward)" in black[0]
    assert not any(w.startswith("'Floor'") for w in value["warnings"])


def test_a_modifier_that_folds_the_map_the_bake_reads_is_named_with_its_fix(facts):
    """A Subdivision Surface smooths the refined map's UVs inside the islands and folds them where the bake
    reads it, though the map on the mesh is clean: the run says so, with the setting that stops it."""
    value = fact(facts, "modifier_folds_are_named")
    assert value["error"] is None and value["objects"] == ["Monkey"]
    folds = [w for w in value["warnings"] if "where the bake reads" in w]
    assert len(folds) == 1 and folds[0].startswith(
        "'Monkey': its Subdivision Surface modifier 'Subdivision' smooths the UVs (UV Smooth: Keep Boundaries), so "
        "where the bake reads UV map 'Lightmap_refined', ")
    assert "set its UV Smooth to None (Modifier Properties > Subdivision > Advanced)" in folds[0]
    assert value["smoothed"].startswith("'Monkey': its Subdivision Surface modifier")
    assert " 10 of its 3936 triangles overlap and 9 flip (the map on the mesh: 0 and 0 of 968)" in value["smoothed"]
    assert value["none"] is None and value["off"] is None


def test_tight_source_gutters_the_refined_map_fixes_are_reported_as_fixed(facts):
    value = fact(facts, "tight_source_gutters_fixed_by_the_refined_map")
    assert value["error"] is None and value["source_gutter"] < 8 and value["refined_check"]["valid"]
    gutter = [w for w in value["warnings"] if "UV map 'Lightmap'" in w]
    assert len(gutter) == 1 and "was invalid at 64 texels (charts " in gutter[0]
    assert " texels apart where the padding asks for 8)" in gutter[0]
    assert "the refined map is valid" in gutter[0] and "only the first lightmap" in gutter[0]
    assert "no worse, but" not in gutter[0]


def test_an_inside_out_member_of_a_lit_shared_atlas_is_named(facts):
    value = fact(facts, "inside_out_member_of_a_shared_atlas_is_named")
    assert value["error"] is None and sorted(value["atlases"]["Floor_atlas"]) == ["Blocker", "Floor", "Post"]
    inside_out = [w for w in value["warnings"] if "inside out" in w]
    assert len(inside_out) == 1 and inside_out[0].startswith("'Post': it is inside out")
    assert not any("first lightmap is black" in w for w in value["warnings"])


def test_black_first_lightmap_warns_and_keeps_the_layout(facts):
    value = fact(facts, "black_first_lightmap_warns")
    assert len(value["warnings"]) == 1 and "the first lightmap is black" in value["warnings"][0]
    assert value["max_move"] < 1e-6


def test_modal_run_and_escape(facts):
    value = fact(facts, "modal_events")
    run, escape = value["run"], value["escape"]
    assert run["returned"] == ["FINISHED"] and run["result_valid"]
    assert run["reports"][-1][0] == ["INFO"] and "Refined 1 object(s)" in run["reports"][-1][1]
    assert "mesh:FloorMesh" in run["changed"]
    assert escape["returned"] == ["CANCELLED"] and not escape["result_valid"]
    assert escape["reports"] == [[["WARNING"], "Cancelled: the scene was left unchanged"]]
    assert escape["changed"] == []


def test_invoke_in_background_runs_blocking(facts):
    value = fact(facts, "invoke_in_background_runs_blocking")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["has_layer"]


def test_remove_preview_restores_materials(facts):
    value = fact(facts, "remove_preview_restores_materials")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["changed_by_run"] and value["restored"]
    assert value["removed"] == ["FINISHED"] and value["again"] == ["CANCELLED"]


def test_a_texture_map_as_source_is_named_with_the_fix(facts):
    value = fact(facts, "texture_map_as_source_warns")
    assert value["outcome"] == "FINISHED", value["message"]
    texture = [w for w in value["warnings"] if "looks like a texture map" in w]
    assert len(texture) == 1 and "'Blocker': UV map 'Tex'" in texture[0]
    assert "overlapping" in texture[0] and "UV > Lightmap Pack) and pick it as Source" in texture[0]
    assert value["panel_warnings"] == len(value["warnings"]) >= 1
    texture = [w for w in value["per_effect_warnings"] if "looks like a texture map" in w]
    assert [w.split(":")[0] for w in texture] == ["'Blocker' (direct)", "'Blocker' (indirect)"]
    # Gutters under the padding are said per effect too (judged at the user's padding, not the lowered one).
    tight = [w for w in value["per_effect_tight_warnings"] if "was already invalid" in w]
    assert [w.split(":")[0] for w in tight] == ["'Blocker' (direct)", "'Blocker' (indirect)"]
    assert all(" texels apart where the padding asks for 8)" in w for w in tight)
    # Charts closer than the padding: the repack's Margin is what to raise.
    assert all(w.endswith("repack the source map (UV > Lightmap Pack) with a larger Margin (in the operator's "
                          "Adjust Last Operation panel), so that its charts lie at least Padding (8 texels) apart")
               for w in tight), tight
    # The panel keeps the run's warnings, each wrapped to the sidebar, its first line marked.
    assert value["panel_warning_text"] == "\n".join(value["warnings"])
    starts = [text for text, icon in value["panel_warning_rows"] if icon == 'ERROR']
    assert len(starts) == len(value["warnings"]) and starts[0].startswith("'Blocker': UV map")
    assert " ".join(text for text, _ in value["panel_warning_rows"]) == " ".join(value["warnings"])


def test_repack_advice_names_the_margin_only_where_charts_are_too_close(facts):
    warnings = fact(facts, "repack_wording")
    assert warnings["tight"] == (
        "'Box': UV map 'Lightmap' was already invalid at 64 texels (charts 1.50 texels apart where the padding asks "
        "for 2); the refined map is no worse, but lightmap bleeding may show: repack the source map (UV > Lightmap "
        "Pack) with a larger Margin (in the operator's Adjust Last Operation panel), so that its charts lie at least "
        "Padding (2 texels) apart")
    assert warnings["flipped"].endswith("(2 flipped triangles); the refined map is no worse, but lightmap bleeding "
                                        "may show: repack the source map (UV > Lightmap Pack)")


def test_progress_moves_per_map_and_per_stage(facts):
    value = fact(facts, "progress_moves_per_map_and_stage")
    assert value["value"] == "done"
    fractions = value["fractions"]
    assert all(b >= a - 1e-9 for a, b in zip(fractions, fractions[1:])), "progress went back"
    assert fractions[0] == 0.0 and fractions[-1] == pytest.approx(1.0)
    # Each map of a bake ends at its share of the bake's span: not at the span's end after map 1.
    for m in range(1, 6):
        assert value["ends"][f"First bake {m}"] == pytest.approx(0.4 * m / 5)
        assert value["ends"][f"Second bake {m}"] == pytest.approx(0.6 + 0.4 * m / 5)
    # The refinement's three stages (gradient map, automaton, pack) fill its span one after another.
    assert max(f for f in fractions if 0.4 <= f <= 0.6) == pytest.approx(0.6)
    real = value["real_fractions"]
    assert all(b >= a - 1e-9 for a, b in zip(real, real[1:])) and real[-1] == pytest.approx(1.0)
    # Two objects, two passes: the second bake's maps are the last third, map 1 ends half way through it.
    at = value["real_at"]
    first_map_end = max(high for label, (low, high) in at.items()
                        if label.startswith("Second bake") and "object 1/2" in label)
    assert first_map_end == pytest.approx(2 / 3 + 1 / 6, abs=1e-6)
    assert any("object 2/2" in label for label in value["real_labels"] if label.startswith("First bake"))
    # The baker's count of its meshes reads as objects: "map" is the add-on's atlas group.
    assert not any("(map " in label for label in value["real_labels"] + value["atlas_labels"])
    assert any("(object 4/4)" in label for label in value["atlas_labels"] if label.startswith("Second bake"))
    # A shared atlas is one map: 4 objects in 2 maps give 6 units (first bake, refinement, second bake
    # 2 each), the atlas's one refinement the third unit, Lonely's the fourth.
    atlas = value["atlas_fractions"]
    assert all(b >= a - 1e-9 for a, b in zip(atlas, atlas[1:])) and atlas[-1] == pytest.approx(1.0)
    assert value["atlas_refining"] == {"Refining Floor_atlas": [pytest.approx(2 / 6), pytest.approx(3 / 6)],
                                       "Refining Lonely": [pytest.approx(3 / 6), pytest.approx(4 / 6)]}


def test_preview_is_wired_through_the_refined_map_in_every_viewport_mode(facts):
    value = fact(facts, "preview_wiring_toggle_and_removal")
    assert value["outcome"] == "FINISHED", value["message"]
    # Before the run the user's EEVEE output is what Material Preview draws.
    assert value["before"]["eevee"] == "UserEevee" and value["before"]["cycles"] == "Material Output"
    after = value["after"]
    for name in ("floor", "box"):
        wiring = after[name]
        assert wiring["roles"] == ["preview_emission", "preview_image", "preview_output", "preview_uv"]
        # Material Preview (EEVEE) and Rendered (Cycles) draw our output: emission <- image <- UV Map node.
        assert wiring["eevee_is_ours"] and wiring["cycles_is_ours"] and wiring["chain"] == [True, True, True]
        assert wiring["uv_map"] == "Lightmap_refined" and wiring["active_node_is_image"]
    assert after["floor"]["image"] == "Floor_lightmap_direct" and after["box"]["image"] == "Blocker_lightmap_direct"
    outputs = after["floor_outputs"]
    assert outputs["active_output"] == "lmrefine Output" and outputs["active_node"] == "lmrefine Lightmap"
    assert outputs["targets"]["UserEevee"] == "ALL"  # else it would win over any 'All' output in EEVEE
    # Solid shading (Texture colour) draws the active image node through the active UV map.
    assert after["floor_active_uv"] == "Lightmap_refined" and after["box_active_uv"] == "Lightmap_refined"
    assert after["floor_render_uv"] == "UVMap"
    assert after["box_material"] == "lmrefine preview"  # an object without material gets one
    assert "Floor_lightmap_before" in after["images"] and "Blocker_lightmap_before" in after["images"]


def test_before_after_toggle_swaps_image_and_uv_map(facts):
    value = fact(facts, "preview_wiring_toggle_and_removal")
    assert value["show_before"] == ["FINISHED"] and value["show_after"] == ["FINISHED"]
    shown = value["before_shown"]
    assert shown["floor"]["image"] == "Floor_lightmap_before" and shown["floor"]["uv_map"] == "Lightmap"
    assert shown["box"]["image"] == "Blocker_lightmap_before" and shown["box"]["uv_map"] == "Lightmap"
    assert shown["floor_active_uv"] == "Lightmap" and shown["box_active_uv"] == "Lightmap"
    assert shown["floor"]["eevee_is_ours"] and shown["floor"]["chain"] == [True, True, True]
    again = value["after_again"]
    assert again["floor"]["image"] == "Floor_lightmap_direct" and again["floor"]["uv_map"] == "Lightmap_refined"
    assert again["floor_active_uv"] == "Lightmap_refined"


def test_removing_the_preview_restores_outputs_nodes_and_uv_maps(facts):
    value = fact(facts, "preview_wiring_toggle_and_removal")
    assert value["removed"] == ["FINISHED"] and value["show_without_preview"] == ["CANCELLED"]
    restored = value["restored"]
    assert restored["outputs"] == value["before"]  # active output, targets, active node, what each engine draws
    assert restored["floor_active_uv"] == "UVMap" and restored["box_active_uv"] == "UVMap"
    # The box had no material slot: the preview added one with its own material and took both out again.
    assert value["box_slots"] == 0 and restored["box_slots"] == 0 and restored["materials"] == 0
    # The refined maps and images stay; every material is bit for bit as before.
    assert restored["changed"] == ["images", "mesh:Cube", "mesh:FloorMesh", "result"]


def test_preview_in_a_material_shared_by_two_objects(facts):
    value = fact(facts, "preview_in_a_shared_material")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["shown_after_run"]
    # Removing the box's preview shows the floor's, still wired.
    remaining = value["after_one_removed"]
    assert remaining["eevee_is_ours"] and remaining["chain"] == [True, True, True]
    assert remaining["image"] == "Floor_lightmap_direct" and remaining["active_node_is_image"]
    assert "material:FloorMaterial" not in value["changed"]


def test_menu_entries_and_stable_panels(facts):
    value = fact(facts, "menus_and_panel_rows")
    assert value["outcome"] == "FINISHED", value["message"]
    # F3 search finds operators through menus: 3D View > Object and UV Editor > UV.
    assert value["menus"] == {"VIEW3D_MT_object": ["object.lmrefine_refine_uvs"],
                              "IMAGE_MT_uvs": ["object.lmrefine_refine_uvs"]}
    assert value["menus_after_unregister"] == {"VIEW3D_MT_object": False, "IMAGE_MT_uvs": False}
    assert value["show_operator"]
    # Every panel draws as many rows before a run, after it and when nothing moved.
    rows = value["rows"]
    for panel, count in rows["after_run"].items():
        assert rows["nothing"][panel] == count, (panel, rows)
    assert rows["nothing_moved"]["LMREFINE_PT_refine_result"] == rows["after_run"]["LMREFINE_PT_refine_result"]
    labels = value["labels"]
    assert labels["nothing"][0] == "No run yet" and labels["nothing_moved"][1] == "Nothing moved"
    assert labels["after_run"][1] == "Moved: 1 object(s)" and labels["after_run"][2].startswith("Edges: ")
    # The default sidebar fits about 23 characters beside an icon: the objects are counted, not named.
    assert labels["after_run"][0] == "Objects: 1" and labels["nothing_moved"][0] == "Objects: 5"
    for state in ("nothing", "after_run", "nothing_moved", "staged"):
        assert all(len(text) <= 23 for text in labels[state]), (state, labels[state])
    staged = labels["staged"]
    at = staged.index("Stages kept: 2 of 3")
    assert staged[at + 1:at + 5] == ["Floor_atlas:", "stage 3 backed off", "Lonely:", "stage 2 moved 0.4%"], staged
    # A triangle's texel ratio (the repack scales charts beyond Max Growth), short enough for the sidebar.
    assert re.fullmatch(r"Triangles: [0-9.e+]+x-[0-9.e+]+x", labels["after_run"][3]) and len(labels["after_run"][3]) <= 24
    assert value["operators_after_run"] == ["object.lmrefine_show_preview"] * 2 + ["object.lmrefine_remove_preview"]
    assert len(value["icons_used"]) >= 8 and value["icons_missing"] == []
    # What held the refinement back, in words (settings by their labels), and what that means in the report.
    assert labels["after_run"][4] == "Limit: Max Growth/steps" and labels["warned"][4] == "Limit: flips +2"
    assert "; limits: Max Growth (some texels grew as much as it allows), steps (the automaton stopped at its " \
           "step limit before the texel densities settled within Delta); " in value["result_message"]
    # Warnings stay in the panel after the run: counted in Last Result, listed in its Warnings sub-panel.
    assert labels["warned"][5] == "Warnings: 7 (below)" and labels["nothing_moved"][3] == "The warnings say why"
    rows = value["warning_rows"]
    assert rows["nothing"] == [["No run yet", "INFO"]] and rows["after_run"] == [["No warnings", "INFO"]]
    warned = rows["warned"]
    assert warned[:4] == [["'Floor': nothing moved:", "ERROR"], ["strength is 0; the", "BLANK1"],
                          ["layout returned is the", "BLANK1"], ["input", "BLANK1"]]
    assert [text for text, icon in warned if icon == "ERROR"][1:] == [f"Skipped: 'Box{k}' has no" for k in range(4)]
    assert warned[-1] == ["2 more in the Info log", "INFO"] and all(len(text) <= 23 for text, _ in warned)


def test_limit_row_and_its_words(facts):
    value = fact(facts, "limit_wording")
    assert value["limits"] == {
        "": "Limit: none", "max_magnification, step_cap": "Limit: Max Growth/steps",
        "flipped, overlapping, step_cap": "Limit: flips +2", "min_shrink, max_magnification": "Limit: Max Growth +1",
        "original_gutter": "Limit: tight gaps", "aligned_steps": "Limit: texel-aligned",
        "degenerate, grid, gutter, out_of_bounds": "Limit: Padding +3", "something_new": "Limit: something new"}
    assert all(len(row) <= 23 for row in value["limits"].values())
    assert value["words"] == [
        ["Max Growth", "some texels grew as much as it allows"],
        ["flips", "the deformation was scaled back where UV triangles would turn over"],
        ["steps", "the automaton stopped at its step limit before the texel densities settled within Delta"]]


def test_a_few_overlapping_faces_are_no_texture_map(facts):
    """Smart UV Project leaves a few overlapping triangles where an island folds over itself (two on Suzanne):
    the map is named as a lightmap with a flaw, with the way to find them, not as a texture map; a map whose
    triangles overlap widely still is one, and charts that only touch get the gutter warning."""
    value = fact(facts, "few_overlaps_wording")
    assert not value["few"]["texture_like"] and value["many"]["texture_like"] and not value["touching"]["texture_like"]
    assert value["few"]["warning"] == (
        "'Floor_atlas': UV map 'Lightmap' has faces that share texels (2 overlapping triangles, charts 1.62 texels "
        "apart where the padding asks for 2): light bleeds between them whatever the refinement does; in the UV "
        "Editor, Select > Select Overlap finds them: move them apart, or unwrap the map again")
    assert "looks like a texture map" in value["many"]["warning"]
    assert "looks like a texture map" not in value["touching"]["warning"]
    assert "the refined map is valid" in value["touching"]["warning"]
    # A refined map that is valid (re-charted from the mesh): only the first lightmap bleeds.
    assert value["recharted"] == (
        "'Floor_atlas': UV map 'Lightmap' has faces that share texels (2 overlapping triangles, charts 1.62 texels "
        "apart where the padding asks for 2); the refined map, re-charted from the mesh, has none, so only the "
        "first lightmap, baked with the source map, may show bleeding")


def test_maps_not_recharted_are_explained_in_the_panels_words(facts):
    """A map Re-chart if Better tried and kept on its source map's charts gets an Info line saying why it was
    tried and why it was not kept (docs/blender.md promises it), in the panel's words; none where the route was
    not tried or was taken."""
    sentences = fact(facts, "not_recharted_wording")
    assert sentences["refused"] == (
        "not re-charted, though its source map gives the refiner no room (60 charts for 120 triangles, 0% of its "
        "area in triangles with a UV inside their chart: a UV on a chart's border keeps its place): re-charting was "
        "predicted to give 0.97x the source map's lightmap error (blur at the light changes) and refining the source "
        "map 0.94x; re-charting needs below 0.95x and below the other. The source map's charts were refined instead")
    failed = ("not re-charted, though its source map's charts fold over 12 creases sharper than 20 degrees (8.5 world "
              "units), which hold 31% of its light changes: the re-charted map had overlapping triangles, charts "
              "closer than Padding, which the source map has not. The source map's charts were refined instead")
    assert sentences["failed"] == failed and sentences["per_effect"] == "indirect: " + failed
    assert sentences["strength_0"] == ("not re-charted, though its source map's charts fold over sharp edges: "
                                       "strength is 0. The source map's charts were refined instead")
    assert sentences["not_tried"] is None and sentences["recharted"] is None


def test_recharted_maps_are_explained_in_the_panels_words(facts):
    """The Info line of a re-charted map: why, what it is predicted to give, and the setting that turns it
    off; never refine_uvs' keywords (rechart='always') nor its error model's name."""
    sentences = fact(facts, "rechart_wording")
    tail = ("Predicted lightmap error (blur at the light changes): 0.64x the source map's (0.80x refining the "
            "source map instead). To keep the source map's charts, turn off Re-chart if Better (Refinement)")
    assert sentences["no_room"] == (
        "re-charted from the mesh (25 charts of faces within 20 degrees) and refined, because its source map gives "
        "the refiner no room (60 charts for 120 triangles, 0% of its area in triangles with a UV inside their "
        "chart: a UV on a chart's border keeps its place). " + tail)
    assert sentences["always"] == (
        "re-charted from the mesh (25 charts of faces within 20 degrees, packed half a texel farther apart than "
        "Padding so that their edge texels could shrink) and refined, because its source map's 60 charts were one "
        "face each before Tessellate split their triangles. " + tail)
    folds = ("re-charted from the mesh (25 charts of faces within 20 degrees) and refined, because its source map's "
             "charts fold over 672 creases sharper than 20 degrees (188 world units, 3 of them smooth-shaded), which "
             "hold 20% of its light changes. Predicted lightmap error (blur at the light changes): 0.64x the source "
             "map's (refining the source map instead: at least 0.90x, so it was not finished). To keep the source "
             "map's charts, turn off Re-chart if Better (Refinement)")
    assert sentences["folds"] == folds and sentences["per_effect"] == "indirect: " + folds
    for name in ("rechart_lightmap_pack_source", "rechart_folded_source"):
        value = fact(facts, name)
        value = value.get("rechart_True", value)
        lines = [text for kind, text in value["reports"] if kind == "INFO" and "re-charted from the mesh (" in text]
        assert len(lines) == 1, value["reports"]
        assert lines[0].endswith("To keep the source map's charts, turn off Re-chart if Better (Refinement)")
        assert "rechart=" not in lines[0] and "error model" not in lines[0]
    line = next(text for kind, text in fact(facts, "rechart_lightmap_pack_source")["rechart_True"]["reports"]
                if "re-charted from the mesh (" in text)
    assert line.startswith("'Floor': re-charted from the mesh (1 charts of faces within 20 degrees) and refined, "
                           "because its source map gives the refiner no room (64 charts for 128 triangles"), line
    # With Re-chart if Better off the route is not tried: nothing to explain either way.
    assert not any("re-charted" in text
                   for _, text in fact(facts, "rechart_lightmap_pack_source")["rechart_False"]["reports"])


def test_failed_rerun_restores_the_previous_result(facts):
    value = fact(facts, "rerun_failure_restores_previous_run")
    assert value["first_outcome"] == "FINISHED", value["message"]
    assert value["raised"] == "RuntimeError"  # Blender could not write the EXR
    assert value["changed"] == [] and value["refined_restored"] and value["pixels_restored"]


def test_failure_mid_run_rolls_back(facts):
    value = fact(facts, "rollback_on_failure")
    assert value["outcome"] == "CANCELLED"
    assert "does not use nodes" in value["message"]
    assert value["changed"] == []


def test_cancel_mid_run_rolls_back(facts):
    value = fact(facts, "rollback_on_cancel")
    assert value["raised"] == "Cancelled"
    assert value["changed"] == []


def test_threaded_driver_runs_and_cancels(facts):
    value = fact(facts, "threaded_driver_runs_and_cancels")
    run, cancel = value["run"], value["cancel"]
    assert run["kind"] == "done" and run["value"] == "Outcome" and run["has_layer"]
    assert "Refining Floor" in run["labels"]
    # Cancelled while refining: either the native call saw the stop (CancelledError) or the
    # job stopped before its next step (Cancelled); the scene is untouched either way.
    assert cancel["kind"] == "error" and cancel["value"] in ("Cancelled", "CancelledError")
    assert cancel["changed"] == [] and not cancel["has_layer"]
    # Layouts: Per Effect, Esc while the indirect map is refined: the direct map, written by then, goes too.
    per_effect = value["per_effect_cancel"]
    assert value["per_effect_cancel_layers_at_cancel"] == ["UVMap", "Lightmap", "Lightmap_refined_direct"]
    assert per_effect["kind"] == "error" and per_effect["value"] in ("Cancelled", "CancelledError")
    assert per_effect["changed"] == [] and per_effect["layers"] == ["UVMap", "Lightmap"]


# --------------------------------------------------- tessellation and stages

def test_tessellation_adds_vertices_within_the_budget_and_keeps_every_attribute(facts):
    value = fact(facts, "tessellation_writes_the_split_into_the_mesh")
    assert value["outcome"] == "FINISHED", value["message"]
    # 25 vertices, budget 0.25: at most 6 more; the shadow edge crosses enough large triangles to use them all.
    assert value["vertices_before"] == 25 and value["vertices_after"] == 31
    assert value["panel_tessellated"] and value["panel_vertices_added"] == 6
    assert "tessellation added 6 vertices" in value["result_message"]
    assert value["triangles_after"] > 0  # split quads became triangles
    assert value["largest_height"] == 0.0  # every new vertex lies on the floor
    # Linear attributes stay linear: UVMap and the colour over the floor, Lightmap per original quad (seams).
    assert value["uvmap_residual"] < 1e-6 and value["lightmap_residual"] < 1e-6
    assert value["tint_residual"] < 1e-6
    assert value["refined_triangles"] > 32  # the refinement ran on the tessellated layout (32 before)
    # Its quads were one chart each before the split (the split put vertices inside them): the route stays
    # open ('always'), and the error model chooses between the re-charted layout and the split quads' own
    # refinement.
    calls = value["rechart_calls"]
    assert calls and all(call["rechart"] == "always" and call["always"] for call in calls), calls
    assert value["panel_recharted"] == sum(call["used"] for call in calls)
    assert all(call["used"] or "the error model predicts" in call["reason"] for call in calls), calls
    # Re-charted, the Info line says why in the panel's words (no 'rechart=' keyword).
    lines = [text for kind, text in value["reports"] if "re-charted from the mesh (" in text]
    assert len(lines) == value["panel_recharted"]
    assert all("were one face each before Tessellate split their triangles" in text for text in lines), lines
    assert value["leftover_meshes"] == ["Cube", "FloorMesh"]  # the rollback copy is gone after success
    # Ctrl+Z: one step back restores the original mesh exactly.
    assert value["undo_vertices"] == 25 and value["undo_coordinates_equal"]
    assert value["undo_layers"] == ["UVMap", "Lightmap"] and value["can_undo_further"] is False


def test_tessellation_rolls_back_exactly(facts):
    value = fact(facts, "tessellation_rolls_back_exactly")
    assert value["raised"] == "CancelledError"
    assert value["vertices_when_stopped"] == 50  # budget 1.0: tessellated when the run was cancelled
    assert value["vertices"] == value["vertices_before"] == 25 and value["coordinates_equal"]
    assert value["mesh_name"] == "FloorMesh" and value["meshes"] == value["meshes_before"]
    assert value["changed"] == []


@pytest.mark.parametrize("case, reason, fix", [
    ("shared", "'Floor' (its mesh 'FloorMesh', shared with 1 other object(s)", "to split it, make it single-user"),
    ("modifier", "'Floor' (its modifiers (Bevel), which would", "to split it, apply or remove them (Object > Apply)"),
])
def test_tessellation_refines_without_splitting_where_a_split_would_change_more(facts, case, reason, fix):
    """Such an object used to be skipped, so turning Tessellate on left every object under a modifier
    unrefined (5 of 8 on a scene drawn at random); now it is refined as it is, and told why."""
    value = fact(facts, "tessellation_leaves_meshes_it_would_change_more")[case]
    assert value["outcome"] == "FINISHED" and value["message"] is None
    assert value["refined"] and value["mesh_unchanged"] and value["tessellated"]
    prefix = "Not tessellated, refined without splitting: "
    warnings = [text for text in value["warnings"] if text.startswith(prefix)]
    assert len(warnings) == 1 and reason in warnings[0] and fix in warnings[0], value["warnings"]


def test_objects_refined_without_splitting_for_one_reason_share_one_warning(facts):
    value = fact(facts, "tessellation_leaves_meshes_it_would_change_more")["both"]
    assert value["error"] is None
    warnings = [text for text in value["warnings"] if text.startswith("Not tessellated")]
    assert warnings == ["Not tessellated, refined without splitting: 'Floor' and 'Blocker' (their modifiers "
                        "(Bevel), which would change the split mesh again): to split them, apply or remove them "
                        "(Object > Apply)"], value["warnings"]
    reason = "modifiers (Bevel), which would change the split mesh again"
    assert value["not_split"] == {"Blocker": reason, "Floor": reason}


def test_charts_stretched_across_stripes_are_reported_and_in_the_map(facts):
    value = fact(facts, "stretch_across_stripes")["2.0"]
    assert value["outcome"] == "FINISHED" and value["valid"]
    assert value["panel_stretched"] >= 2  # the two striped tiles
    assert f"{value['panel_stretched']} chart(s) stretched across their light changes" in value["result_message"]
    # Measured on the refined map: across the stripes (x) the texels gained more than along them (y).
    assert value["gains"]["x"] > 1.5 * value["gains"]["y"], value["gains"]
    off = fact(facts, "stretch_across_stripes")["1.0"]  # Max Stretch 1: no chart stretched, and the map shows it
    assert off["outcome"] == "FINISHED" and off["valid"] and off["panel_stretched"] == 0
    assert "stretched across" not in off["result_message"]
    assert off["gains"]["x"] < 1.3 * off["gains"]["y"], off["gains"]
    assert off["panel_stretched_triangles"] == 0
    # Triangle Stretch (the chart stretch off): triangles stretched, said so, and the map shows it.
    local = fact(facts, "stretch_across_stripes")["triangle"]
    assert local["outcome"] == "FINISHED" and local["valid"] and local["panel_stretched"] == 0
    assert local["panel_stretched_triangles"] > 0
    assert f"{local['panel_stretched_triangles']} triangle(s) stretched across their light changes" in \
        local["result_message"]
    assert local["gains"]["x"] > 1.2 * local["gains"]["y"], local["gains"]
    assert re.search(r"texels at light changes [0-9.]+x their area \([0-9.]+x across them\)", local["result_message"])


def test_stages_refine_again_and_report_the_stages_kept(facts):
    value = fact(facts, "stages_refine_the_layout_again")
    one, two = value["1"], value["2"]
    assert one["outcome"] == two["outcome"] == "FINISHED"
    assert one["stages"] == 1 and one["stages_kept"] == 1 and "stages kept" not in one["result_message"]
    assert two["stages"] == 2 and two["stages_kept"] == 2
    assert "stages kept: 2 of 2 (Floor: 2 stages done)" in two["result_message"] and two["stopped"] == ""
    assert value["layout_change"] >= value["stage_min_change"]  # stage 2 moved the layout again
    assert one["valid"] and two["valid"]
    still = value["still"]
    assert still["outcome"] == "FINISHED" and still["stages_kept"] == 1
    assert still["stopped"] == "Floor: stage 2 did not move"  # the panel's line
    assert "stage 2 changed the layout by 0.0% (median texel density), under 5%: stage 1 kept" in \
        still["result_message"]


# ------------------------------------------------------------------ batch

def run_batch(blend, *flags):
    return run_blender(str(blend), "--python", BATCH, "--", *flags)


def test_batch_help_documents_flags():
    process = run_blender("--python", BATCH, "--", "--help")
    assert process.returncode == 0, process.stderr[-2000:]
    for flag in ("--objects", "--resolution", "--out", "--backend", "--bake-passes", "--first-lightmap",
                 "--max-stretch"):
        assert flag in process.stdout


def test_batch_fails_with_message_and_report(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    out = work_dir / "batch_fail"
    process = run_batch(blend, "--objects", "Floor,NoSuchObject", "--resolution", "64", "--out", str(out))
    assert process.returncode == 1
    assert "no object(s) named NoSuchObject" in process.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["ok"] is False and "NoSuchObject" in report["error"]


def test_batch_never_overwrites_its_input(facts):
    blend = fact(facts, "save_scene_for_batch")["path"]
    before = os.path.getmtime(blend)
    process = run_batch(blend, "--objects", "Floor", "--out", os.path.dirname(blend))
    assert process.returncode == 1
    assert "would overwrite it" in process.stderr
    assert os.path.getmtime(blend) == before


def test_batch_refuses_objects_that_are_not_meshes(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    process = run_batch(blend, "--objects", "Floor,Sun", "--out", str(work_dir / "not_mesh"))
    assert process.returncode == 1
    assert "not meshes: 'Sun' (light)" in process.stderr


def test_batch_rejects_bad_flags(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    process = run_batch(blend, "--objects", "Floor", "--out", str(work_dir / "bad"), "--bake-passes", "glow")
    assert process.returncode == 2
    assert "unknown pass" in process.stderr


def test_batch_refuses_numbers_out_of_range_instead_of_clamping(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    out = work_dir / "range"
    process = run_batch(blend, "--objects", "Floor", "--out", str(out), "--resolution", "8")
    assert process.returncode == 1
    assert "--resolution 8 is outside 16 to 16384" in process.stderr
    # A setting without an upper bound (a float's 3.4e38) names only its lower one.
    process = run_batch(blend, "--objects", "Floor", "--out", str(out), "--strength", "-1")
    assert process.returncode == 1 and "--strength -1 is below 0: pass 0 or more" in process.stderr
    assert "e+38" not in process.stderr
    process = run_batch(blend, "--objects", "Floor", "--out", str(out), "--source-layer", "Nope")
    assert process.returncode == 1 and "pass the lightmap UV map with --source-layer" in process.stderr
    assert "top of the panel" not in process.stderr


def readme_command(prefix):
    """The README's shell example that starts with `prefix`, its continuation lines joined, as argv."""
    import shlex
    text = open(os.path.join(REPO, "README.md"), encoding="utf-8").read().replace("\\\n", " ")
    line = next(line.strip() for line in text.splitlines() if line.strip().startswith(prefix))
    return shlex.split(line)


def test_the_readme_batch_example_runs_as_written(tmp_path):
    """README, "One level from the command line": the command as printed, from the checkout's root, on the
    bundled courtyard (only --out goes to a temporary folder)."""
    argv = readme_command("blender -b blend_samples/courtyard.blend --python addon/lmrefine_blender/batch.py")
    assert argv[argv.index("--objects") + 1] == "all" and "--out" in argv
    argv[argv.index("--out") + 1] = str(tmp_path / "courtyard")
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the README sets none: batch.py finds the package in the checkout
    process = subprocess.run([BLENDER, *argv[1:]], cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert process.returncode == 0, process.stdout[-2000:] + process.stderr[-2000:]
    report = json.loads((tmp_path / "courtyard" / "report.json").read_text())
    assert report["ok"] and report["summary"]["objects"] == 5 and report["summary"]["moved"] == 5
    assert (tmp_path / "courtyard" / "courtyard.blend").exists()
    assert all(os.path.exists(path) for path in report["atlases"][next(iter(report["atlases"]))]["images"].values())


def test_batch_objects_all_selected_and_collection():
    """--objects all | selected | collection:NAME on a bundled sample, judged in one Blender process."""
    probe = (
        "import bpy, importlib.util, json\n"
        f"spec = importlib.util.spec_from_file_location('lmrefine_batch', {BATCH!r})\n"
        "batch = importlib.util.module_from_spec(spec); spec.loader.exec_module(batch)\n"
        "scene = bpy.context.scene\n"
        "group = bpy.data.collections.new('Walls'); scene.collection.children.link(group)\n"
        "inner = bpy.data.collections.new('Inner'); group.children.link(inner)\n"
        "group.objects.link(bpy.data.objects['LowWall']); inner.objects.link(bpy.data.objects['Well'])\n"
        "ghost = bpy.data.objects.new('Ghost', bpy.data.objects['Well'].data.copy()); ghost.hide_render = True\n"
        "inner.objects.link(ghost)\n"
        "for obj in scene.objects: obj.select_set(obj.name in ('Floor', 'Well'))\n"
        "out = {}\n"
        "for spec_text in ('all', 'selected', 'collection:Walls', 'Floor,Well', 'collection:Nope', 'Nope'):\n"
        "    try:\n"
        "        names = batch.object_names(batch._csv(spec_text), scene)\n"
        "        out[spec_text] = names; out[spec_text + ' left out'] = names.left_out\n"
        "    except batch.pipeline.UserError as error: out[spec_text] = 'error: ' + str(error)\n"
        "print('PROBE', json.dumps(out))\n"
    )
    process = run_blender(os.path.join(REPO, "blend_samples", "courtyard.blend"), "--python-expr", probe)
    assert process.returncode == 0, process.stderr[-2000:]
    names = json.loads(next(line for line in process.stdout.splitlines() if line.startswith("PROBE"))[6:])
    assert names["all"] == ["ArcadeNorth", "ArcadeWest", "Floor", "LowWall", "Well"]
    assert names["selected"] == ["Floor", "Well"]
    assert names["collection:Walls"] == ["LowWall", "Well"]  # child collections count
    # A mesh the bake does not see (disabled for render) is left out of all and collections, and listed.
    assert names["all left out"] == names["collection:Walls left out"] == ["Ghost"]
    assert names["selected left out"] == names["Floor,Well left out"] == []
    assert names["Floor,Well"] == ["Floor", "Well"]
    assert names["collection:Nope"].startswith("error: --objects collection:Nope: no such collection")
    assert "Walls" in names["collection:Nope"]
    assert names["Nope"].startswith("error: no object(s) named Nope") and "--objects all" in names["Nope"]


def test_batch_refines_bakes_and_reports(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    out = work_dir / "batch_ok"
    process = run_batch(blend, "--objects", "Floor", "--resolution", "64", "--samples", "4",
                        "--bake-passes", "direct,ao", "--out", str(out))
    assert process.returncode == 0, process.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert report["ok"] is True
    floor = report["objects"]["Floor"]
    assert floor["refined_layer"] == "Lightmap_refined"
    assert floor["report"]["check_layout"]["valid"] is True
    for pass_name in ("direct", "ao"):
        path = floor["images"][pass_name]
        assert os.path.dirname(path) == str(out) and os.path.getsize(path) > 0
    assert os.path.isfile(report["blend"]) and os.path.dirname(report["blend"]) == str(out)
    # The first lightmap is kept as the preview's "before" image.
    assert sorted(os.listdir(out)) == ["Floor_lightmap_ao.exr", "Floor_lightmap_before.exr",
                                       "Floor_lightmap_direct.exr", "report.json", os.path.basename(blend)]
    # Half float, ZIP-compressed by default; --float32 asks for 32-bit floats.
    for name in ("ao", "before", "direct"):
        header = exr_header(out / f"Floor_lightmap_{name}.exr")
        assert header["compression"] == "ZIP" and set(header["channels"].values()) == {"HALF"}, header
    assert lmrefine_read(out / "Floor_lightmap_direct.exr").max() > 0.1
    # The saved copy opens with the refined map and finds its lightmaps through relative paths.
    probe = (
        "import bpy, json\n"
        "mesh = bpy.data.objects['Floor'].data\n"
        "images = {i.name: [i.filepath, i.size[0], i.has_data] for i in bpy.data.images if i.get('lmrefine_object')}\n"
        "print('PROBE', json.dumps({'layers': [l.name for l in mesh.uv_layers], 'images': images}))\n"
    )
    process = run_blender(report["blend"], "--python-expr", probe)
    assert process.returncode == 0, process.stderr[-2000:]
    saved = json.loads(next(line for line in process.stdout.splitlines() if line.startswith("PROBE"))[6:])
    assert saved["layers"] == ["UVMap", "Lightmap", "Lightmap_refined"]
    assert saved["images"] == {
        "Floor_lightmap_direct": ["//Floor_lightmap_direct.exr", 64, True],
        "Floor_lightmap_ao": ["//Floor_lightmap_ao.exr", 64, True],
        "Floor_lightmap_before": ["//Floor_lightmap_before.exr", 64, True],
    }


def test_batch_writes_one_image_per_shared_atlas_and_reports_who_shares_it(facts, work_dir):
    blend = fact(facts, "save_atlas_scene_for_batch")["path"]
    out = work_dir / "batch_atlas"
    process = run_batch(blend, "--objects", "all", "--resolution", "64", "--samples", "4", "--out", str(out))
    assert process.returncode == 0, process.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert sorted(os.listdir(out)) == ["Floor_atlas_lightmap_before.exr", "Floor_atlas_lightmap_direct.exr",
                                       "Lonely_lightmap_before.exr", "Lonely_lightmap_direct.exr", "atlas.blend",
                                       "report.json"]
    atlas = report["atlases"]["Floor_atlas"]
    assert atlas["objects"] == ["Blocker", "Floor", "Post"]
    assert atlas["images"]["direct"] == str(out / "Floor_atlas_lightmap_direct.exr")
    assert report["atlases"]["Lonely"]["objects"] == ["Lonely"]
    for name in ("Blocker", "Floor", "Post"):
        assert report["objects"][name]["atlas"] == "Floor_atlas"
        assert report["objects"][name]["images"] == atlas["images"]
        assert "report" not in report["objects"][name]  # the one refinement's report is the atlas's
    assert atlas["report"]["check_layout"]["valid"] is True
    assert report["objects"]["Lonely"]["report"] == report["atlases"]["Lonely"]["report"]
    assert report["summary"]["images_per_pass"] == 2 and report["summary"]["objects"] == 4
    assert report["summary"]["shared_images"] == {"Floor_atlas": ["Blocker", "Floor", "Post"]}
    out_off = work_dir / "batch_atlas_off"
    process = run_batch(blend, "--objects", "all", "--resolution", "64", "--samples", "4", "--no-preview",
                        "--no-shared-atlas", "--out", str(out_off))
    assert process.returncode == 0, process.stderr[-3000:]
    assert sorted(name for name in os.listdir(out_off) if name.endswith(".exr")) == [
        f"{name}_lightmap_direct.exr" for name in ("Blocker", "Floor", "Lonely", "Post")]


def test_batch_float32_writes_32_bit_exrs(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    out = work_dir / "batch_float32"
    process = run_batch(blend, "--objects", "Floor", "--resolution", "64", "--samples", "4",
                        "--bake-passes", "direct", "--no-preview", "--float32", "--out", str(out))
    assert process.returncode == 0, process.stderr[-3000:]
    header = exr_header(out / "Floor_lightmap_direct.exr")
    assert header["compression"] == "ZIP" and set(header["channels"].values()) == {"FLOAT"}, header
    assert not (out / "Floor_lightmap_before.exr").exists()  # no preview, no "before" image


def test_batch_stages_and_tessellate(facts, work_dir):
    blend = fact(facts, "save_coarse_scene_for_batch")["path"]
    out = work_dir / "batch_tessellate"
    process = run_batch(blend, "--objects", "Floor", "--resolution", "64", "--samples", "4", "--stages", "3",
                        "--tessellate", "0.5", "--out", str(out))
    assert process.returncode == 0, process.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    floor = report["objects"]["Floor"]
    assert floor["tessellation"]["vertices_before"] == 25
    assert floor["tessellation"]["vertices_added"] == report["summary"]["vertices_added"] == 12  # floor(0.5 x 25)
    stages = floor["report"]["stages"]
    assert [entry["stage"] for entry in stages["stages"]][0] == 1 and len(stages["stages"]) >= 2
    kept = sum(entry["kept"] for entry in stages["stages"])
    assert report["summary"]["stages_kept"] == kept and stages["stopped"]
    assert report["settings"]["stages"] == 3 and report["settings"]["tessellate"] == 0.5
    probe = "import bpy; print('PROBE', len(bpy.data.objects['Floor'].data.vertices))"
    process = run_blender(report["blend"], "--python-expr", probe)
    saved = next(line for line in process.stdout.splitlines() if line.startswith("PROBE"))
    assert saved == "PROBE 37"  # the saved copy holds the tessellated mesh
    process = run_batch(blend, "--objects", "Floor", "--tessellate", "--no-tessellate", "--out", str(out))
    assert process.returncode == 1 and "contradict" in process.stderr


def test_batch_rechart_flag(facts, work_dir):
    """The coarse floor's Lightmap map has one chart per quad: the route re-charts it and lets the model
    choose by default, and never re-charts with --no-rechart. A second stage refines inside the charts
    of the first (lmrefine.metrics.further_stage_options)."""
    blend = fact(facts, "save_coarse_scene_for_batch")["path"]
    used = {}
    for flag, stages in (("--rechart", "2"), ("--no-rechart", "1")):
        out = work_dir / f"batch{flag}"
        process = run_batch(blend, "--objects", "Floor", "--resolution", "64", "--samples", "4",
                            "--bake-passes", "direct", "--no-preview", flag, "--stages", stages,
                            "--max-stretch", "1" if stages == "1" else "2", "--out", str(out))
        assert process.returncode == 0, process.stderr[-3000:]
        report = json.loads((out / "report.json").read_text())
        floor = report["objects"]["Floor"]["report"]
        assert floor["check_layout"]["valid"] is True
        used[flag] = floor["rechart"].get("predicted_error") is not None  # a re-charted layout was made
        assert floor["rechart"]["used"] in ((False,) if flag == "--no-rechart" else (True, False))
        assert ("re-charting is off" in floor["rechart"].get("reason", "")) == (flag == "--no-rechart")
        assert floor["rechart"]["room"]["no_room"] is True
        assert floor.get("stages", {}).get("repack") is (False if stages == "2" else None)
        if stages == "1":  # --max-stretch 1: no stretch is even tried
            assert (floor.get("repack") or {}).get("stretch") is None
    assert used == {"--rechart": True, "--no-rechart": False}


# -------------------------------------------------------------- packaging

def test_zip_installs_enables_and_carries_the_core(tmp_path):
    """The release zip installs like a user would (Preferences operators), in a throwaway user folder."""
    archive = tmp_path / "lmrefine_blender.zip"
    built = subprocess.run([sys.executable, os.path.join(REPO, "addon", "build_zip.py"), "--out", str(archive)],
                           capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    env = dict(os.environ, BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"),
               BLENDER_USER_CONFIG=str(tmp_path / "config"))
    env.pop("PYTHONPATH", None)
    install = (
        "import bpy\n"
        f"bpy.ops.preferences.addon_install(filepath={str(archive)!r})\n"
        "bpy.ops.preferences.addon_enable(module='lmrefine_blender')\n"
        "bpy.ops.wm.save_userpref()\n"
    )
    process = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1",
                              "--python-expr", install], capture_output=True, text=True, env=env, timeout=120)
    assert process.returncode == 0, process.stderr[-2000:]
    # A later session (user preferences read) has the add-on enabled, and the core loads from the zip's copy.
    probe = (
        "import bpy, lmrefine\n"
        "print('PROBE', hasattr(bpy.types.Scene, 'lmrefine'), lmrefine.__file__, "
        "bpy.ops.object.lmrefine_refine_uvs.idname())\n"
    )
    process = subprocess.run([BLENDER, "-b", "--python-exit-code", "1", "--python-expr", probe],
                             capture_output=True, text=True, env=env, timeout=120)
    assert process.returncode == 0, process.stderr[-2000:]
    line = next(line for line in process.stdout.splitlines() if line.startswith("PROBE"))
    enabled, location, idname = line.split()[1:]
    assert enabled == "True" and idname == "OBJECT_OT_lmrefine_refine_uvs"
    assert location.startswith(str(tmp_path / "scripts" / "addons" / "lmrefine_blender" / "lib"))


# ------------------------------------------------------ per-effect layouts

EFFECTS = ("direct", "indirect")


def _assert_adds_effects(wiring, images, uv_maps, owner):
    """The preview of `owner`: its own output, an Emission fed by one Add of the effects' images, each
    image sampled through its own UV node set to its own UV map."""
    assert wiring["output_is_ours"] and wiring["emission"] == "EMISSION"
    assert wiring["adds"] == ["ADD"]
    assert wiring["terms"] == [[image, uv, owner, owner] for image, uv in zip(images, uv_maps)]


def test_per_effect_writes_a_map_and_an_image_per_effect_at_the_split_resolutions(facts):
    value = fact(facts, "per_effect_layouts_images_and_preview")
    assert value["outcome"] == "FINISHED", value["message"]
    for name in ("Floor", "Blocker"):
        assert value["layers"][name] == ["UVMap", "Lightmap", "Lightmap_refined_direct", "Lightmap_refined_indirect"]
        sides = {effect: value["images"][f"{name}_lightmap_{effect}_effect"]["size"] for effect in EFFECTS}
        for effect in EFFECTS:
            side = value["checks"][f"{name}/{effect}"]["side"]
            assert sides[effect] == [side, side]
            # The first bake on the source map at the same side is the preview's Before.
            assert value["images"][f"{name}_lightmap_before_{effect}"]["size"] == [side, side]
            assert value["checks"][f"{name}/{effect}"]["overlapping"] == 0
            assert value["checks"][f"{name}/{effect}"]["moved"] > 0.0
        # Together the effects hold at most the texels of one 64 x 64 map, and nearly all of them.
        texels = sum(side[0] * side[1] for side in sides.values())
        assert 0.9 * 64 * 64 <= texels <= 64 * 64
    # AO is no effect here (it multiplies the light): not baked, and the run says so.
    assert not any("_ao" in image for image in value["images"])
    effects = value["result_effects"].split("; ")
    assert [entry.split()[0] for entry in effects] == list(EFFECTS)
    assert all(re.fullmatch(r"\w+ \d+px \d+\.\d\dx", entry) for entry in effects)


def test_per_effect_resolutions_follow_the_split_rule(facts):
    value = fact(facts, "per_effect_split_matches_the_rule")
    assert value["rule"] == "energy"
    assert value["sides"] == value["expected"]
    assert value["sides"]["direct"] != value["sides"]["indirect"]  # the energies differ: so do the maps
    for effect in EFFECTS:
        side = value["sides"][effect]
        assert value["image_sizes"][effect] == [side, side]
        assert value["summary_effects"][effect]["resolution"] == side
        assert value["summary_effects"][effect]["transition_widening"] > 1.0
    assert value["report_effects"] == list(EFFECTS)


def test_per_effect_preview_adds_the_effects_through_their_own_maps_and_toggles(facts):
    value = fact(facts, "per_effect_layouts_images_and_preview")
    for name in ("Floor", "Blocker"):
        _assert_adds_effects(value["wiring"][name], [f"{name}_lightmap_{e}_effect" for e in EFFECTS],
                             [f"Lightmap_refined_{e}" for e in EFFECTS], name)
        assert value["active_uv"][name] == "Lightmap_refined_direct"  # Solid draws the first term
    _assert_adds_effects(value["before_wiring"], [f"Floor_lightmap_before_{e}" for e in EFFECTS],
                         ["Lightmap", "Lightmap"], "Floor")
    assert value["before_active_uv"] == "Lightmap"
    assert value["after_again"] == value["wiring"]["Floor"]
    assert value["show_before"] == value["show_after"] == value["removed"] == ["FINISHED"]
    # Remove Preview put back the materials and the active UV map: only the new maps and images stay.
    assert value["restored_active_uv"] == "UVMap"
    assert value["changed"] == ["images", "mesh:Cube", "mesh:FloorMesh", "result"]


def test_per_effect_run_is_one_undo_step(facts):
    value = fact(facts, "per_effect_is_one_undo_step")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["layers"] == ["UVMap", "Lightmap", "Lightmap_refined_direct", "Lightmap_refined_indirect"]
    assert value["can_undo"] and value["changed_after_undo"] == [] and not value["can_undo_further"]


def test_per_effect_with_a_shared_atlas_one_image_per_effect_per_group(facts):
    value = fact(facts, "per_effect_shared_atlas")
    assert value["outcome"] == "FINISHED", value.get("message")
    assert sorted(value["images"]) == sorted(f"{group}_lightmap_{kind}" for group in ("Floor_atlas", "Lonely")
                                             for kind in ("direct_effect", "indirect_effect", "before_direct",
                                                          "before_indirect"))
    for effect in EFFECTS:
        assert value["images"][f"Floor_atlas_lightmap_{effect}_effect"]["objects"] == "Blocker, Floor, Post"
        assert value["checks"][f"Floor_atlas/{effect}"]["overlapping"] == 0  # the members' joined layout
    for name in ("Blocker", "Floor", "Post"):
        _assert_adds_effects(value["wiring"][name], [f"Floor_atlas_lightmap_{e}_effect" for e in EFFECTS],
                             [f"Lightmap_refined_{e}" for e in EFFECTS], name)
    _assert_adds_effects(value["wiring"]["Lonely"], [f"Lonely_lightmap_{e}_effect" for e in EFFECTS],
                         [f"Lightmap_refined_{e}" for e in EFFECTS], "Lonely")
    assert value["removed"] == ["FINISHED"]
    assert value["changed"] == ["images", "mesh:Cube", "mesh:Cube.001", "mesh:FloorMesh", "mesh:Plane", "result"]


def test_per_effect_refuses_an_existing_first_image(facts):
    value = fact(facts, "per_effect_refuses_an_existing_image")
    assert value["outcome"] == "CANCELLED" and "Layouts: Per Effect bakes each effect's first map" in value["message"]
    assert value["changed"] == []


def test_batch_per_effect(facts, work_dir):
    blend = fact(facts, "save_scene_for_batch")["path"]
    out = work_dir / "batch_per_effect"
    process = run_batch(blend, "--objects", "Floor", "--resolution", "64", "--samples", "4", "--per-effect",
                        "equal", "--out", str(out))
    assert process.returncode == 0, process.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["per_effect"] == "equal"
    floor = report["objects"]["Floor"]
    assert floor["refined_layers"] == {e: f"Lightmap_refined_{e}" for e in EFFECTS}
    effects = floor["report"]["effects"]
    # equal: half the texels each, 45 x 45 (2 x 45^2 <= 64^2).
    assert [effects[e]["resolution"] for e in EFFECTS] == [45, 45]
    for effect in EFFECTS:
        path = floor["images"][effect]
        assert path == str(out / f"Floor_lightmap_{effect}_effect.exr")
        assert lmrefine_read(path).shape[:2] == (45, 45)


def test_per_effect_progress_counts_each_effect_map(facts):
    value = fact(facts, "per_effect_split_matches_the_rule")
    fractions = value["fractions"]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] > 0.95
    at = value["at"]
    # One map, seven units, one after another: the split bake; per effect its first bake and its
    # refinement; per effect its second bake.
    order = ["First bake (effects", "First bake (direct", "Refining Floor (direct)", "First bake (indirect",
             "Refining Floor (indirect)", "Second bake (direct", "Second bake (indirect"]
    assert [at[label][0] for label in order] == pytest.approx([unit / 7 for unit in range(7)])
    for label, following in zip(order, order[1:]):
        assert at[label][1] <= at[following][0] + 1e-9, (label, at)


def test_per_effect_cancel_rolls_back(facts):
    value = fact(facts, "per_effect_cancel_rolls_back")
    assert value["raised"] == "Cancelled"
    assert value["layers_when_cancelled"] == ["UVMap", "Lightmap", "Lightmap_refined_direct",
                                              "Lightmap_refined_indirect"]
    assert value["changed"] == []


def test_per_effect_panel_rows(facts):
    value = fact(facts, "menus_and_panel_rows")
    assert value["per_effect_outcome"][0] == "FINISHED", value["per_effect_outcome"]
    assert value["per_effect_props"][:2] == ["layouts", "per_effect_rule"]
    labels = value["labels"]["per_effect"]
    effects = [label for label in labels if label.startswith(("Direct: ", "Indirect: "))]
    assert len(effects) == 2
    assert all(re.fullmatch(r"(Direct|Indirect): \d+px, \d+\.\d\dx", label) for label in effects)
    assert all(len(label) <= 23 for label in labels), labels  # the default sidebar's width beside an icon
    # One image per effect for the one map (the bake passes do not count here); the report says so too.
    assert "Images: 1 per effect" in labels and not any("per pass" in label for label in labels)
    assert "; 2 image(s) for 1 object(s), 1 per effect (direct, indirect); " in value["per_effect_message"]
    assert fact(facts, "images_wording") == {
        "one": "2 image(s) per pass for 3 object(s)",
        "per_effect": "4 image(s) for 3 object(s), 2 per effect (direct, indirect)"}


def test_per_effect_maps_add_up_to_the_combined_light(facts):
    """Each effect's image through its own refined map, added, is the combined light of a bake at R with
    the source map, within the bakes' noise (32 samples), at the floor's triangle centroids."""
    value = fact(facts, "per_effect_adds_up_to_the_combined_light")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["points"] > 1000
    for key in ("after", "before"):
        assert abs(value[key]["mean"]) < 0.02, value
        assert value[key]["rmse"] < 0.06, value
    assert value["wrong_map"]["rmse"] > 0.2, value  # the lookup sees a wrong wiring


def test_per_effect_map_that_did_not_move_warns(facts):
    value = fact(facts, "per_effect_nothing_moved_warns")
    assert value["moved"] == 0
    for effect in EFFECTS:
        assert any(w.startswith(f"'Floor' ({effect}): nothing moved") for w in value["warnings"]), value


def test_addon_recharts_a_lightmap_pack_source(facts):
    value = fact(facts, "rechart_lightmap_pack_source")
    on, off = value["rechart_True"], value["rechart_False"]
    for run in (on, off):
        assert run["outcome"] == "FINISHED", run["message"]
        assert run["valid"] and run["min_gutter_texels"] >= 2.0 - 1e-3
        assert run["source_identical"] and run["geometry_identical"]
        assert run["image"] is not None and run["image"]["std"] > 0
    # 64 quads, one chart each: the flat floor re-charts to one chart.
    assert on["source_charts"] == 64
    assert on["panel_recharted"] == 1 and on["refined_charts"] == 1
    assert "re-charted from the mesh: Floor" in on["result_message"]
    assert off["panel_recharted"] == 0 and off["refined_charts"] == 64
    assert "re-charted" not in off["result_message"]
    # The panel's texel figures are measured on the re-charted map against the source, whichever way
    # either winds its faces (they read 1.00x when the two wound differently).
    np.testing.assert_allclose(on["panel_density"], on["area_ratio"], rtol=1e-3)
    assert on["area_ratio"][1] > 1.05
    # Progress through the re-chart route: the source layout's two stages (one chart per quad: no
    # automaton) fill 2/7 of the refinement's share, the route's five the rest, so it keeps moving (it
    # used to stand at the share's end from the first pack on). The source layout's pack comes after
    # the route, and only when a bound does not rule it out (docs/refiner.md).
    progress = value["rechart_progress"]
    stages = [stage for _, stage in progress]
    first = stages.index("rechart: unwrap charts")
    assert stages[:first] and set(stages[:first]) == {"gradient map"}
    assert progress[0][0] < progress[first][0] < progress[-1][0]  # it moved before and after the route began
    assert [stage for stage in dict.fromkeys(stages[first:])] == ["rechart: unwrap charts", "pack", "gradient map",
                                                                   "automaton"]
    fractions = [f for f, _ in progress]
    assert all(b >= a for a, b in zip(fractions, fractions[1:]))


def test_addon_recharts_a_source_folded_over_a_lit_ridge(facts):
    value = fact(facts, "rechart_folded_source")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["valid"] and value["source_identical"]
    assert value["source_charts"] == 1 and value["refined_charts"] == 2  # cut at the ridge
    assert value["panel_recharted"] == 1
    assert "re-charted from the mesh: Roof" in value["result_message"]
    assert "folded over sharp edges" in value["result_message"]
    # The slopes' charts leave the atlas room: the repack's fill grows one or more, and the message says so
    # (with the charts the triangle stretch's packing grew, when it did).
    fill, stretch_fill = value["fill"], value["stretch_fill"]
    assert fill["repack_used"] and fill["charts_grown"] >= 1 and fill["ratio"] <= 0.99, fill
    # Counted once per chart of the output: both fills name a chart by its lowest triangle.
    named = set(fill["grown_chart_triangles"])
    if value["stretch_used"] and stretch_fill.get("used"):
        named |= set(stretch_fill["grown_chart_triangles"])
    charts_of = value["refined_chart_ids"]
    assert len({charts_of[t] for t in named}) == len(named) <= value["refined_charts"]
    assert all(min(t for t, c in enumerate(charts_of) if c == charts_of[n]) == n for n in named)
    assert f"{len(named)} chart(s) grown into the space the packing left" in value["result_message"]
    # The progress counts the route's stages for a folded source too: it moves through them, never back.
    stages = [stage for _, stage in value["progress"]]
    assert "rechart: unwrap charts" in stages and stages.index("rechart: unwrap charts") > 0
    fractions = [f for f, _ in value["progress"]]
    assert all(b >= a for a, b in zip(fractions, fractions[1:]))
    first = stages.index("rechart: unwrap charts")
    assert fractions[first] < fractions[-1]


def test_addon_recharts_a_hilly_floor_of_quads(facts):
    # Found on the bundled hillside in a window: the re-charting cut quads along their diagonals,
    # which one UV per loop cannot hold, and the route gave up ("corners that share a UV"); on this
    # floor it did so too without the polygons (measured: the same check with polygons=None).
    value = fact(facts, "rechart_hilly_quads")
    assert "error" not in value, value.get("error")
    assert value["source_charts"] == 144 and value["largest_angle"] > 45.0  # steep enough to cut quads
    assert value["rechart"]["used"], value["rechart"]
    assert 1 < value["rechart"]["charts"] < 144 and value["valid"]


def test_addon_tells_the_core_a_ridge_is_smooth_shaded(facts):
    value = fact(facts, "rechart_smooth_shaded_ridge")
    assert value["outcome"] == "FINISHED", value["message"]
    # Shade Smooth: the ridge's loops share one normal per vertex (up), read from the split normals.
    assert len(value["ridge_normals"]) == 1 and value["ridge_normals"][0][2] > 0.99
    assert value["valid"]
    # The core was given the normals: the ridge still folds inside the chart (the route is tried), but
    # smooth-shaded, so its light changes are not credited to a cut.
    folds = value["rechart"]["folds"]
    assert folds["count"] == 8 and folds["smooth"] == 8 and folds["energy_fraction"] == 0.0, value["rechart"]
    assert "predicted_error" in value["rechart"] and "rechart: unwrap charts" in value["stages"]
    assert value["panel_recharted"] == int(value["rechart"]["used"])
    assert value["refined_charts"] == (2 if value["rechart"]["used"] else 1)
    assert not value["custom_normals"] and not value["auto_smooth"]


def test_addon_recharts_a_shared_lightmap_pack_atlas(facts):
    value = fact(facts, "rechart_shared_lightmap_pack_atlas")
    assert value["outcome"] == "FINISHED", value["message"]
    assert value["images"] == 1  # one atlas, one image per pass
    assert value["panel_recharted"] == 2  # both objects, counted as objects
    assert "re-charted from the mesh:" in value["result_message"]
    # 64 floor quads + 6 box faces, one chart each, became a few charts (the floor one, the box's sides).
    assert value["refined_charts"] < 20
    assert value["valid"] and value["shared_texels"] == 0 and value["source_identical"]


def test_addon_leaves_a_flat_sphere_on_its_own_grid_map_as_it_is(facts):
    value = fact(facts, "flat_sphere_on_its_own_map_is_left_as_it_is")
    assert value["error"] is None and value["source_map"] == "UVMap"
    assert value["moved"] is False and value["limited_by"] == ["aligned_steps"]
    assert value["aligned_steps"] >= 0.5, value["aligned_steps"]
    said = [w for w in value["warnings"] if "lie on texel boundaries" in w]
    assert len(said) == 1 and said[0].startswith("'Sphere': nothing moved: ")
    assert not any("Tessellate" in w for w in value["warnings"]), value["warnings"]
    split = value["tessellate"]
    assert split["error"] is None and split["vertices_after"] == split["vertices_before"]
    assert split["report"]["vertices_added"] == 0 and split["report"]["aligned_steps"] >= 0.5
    assert any(w.startswith("'Sphere': not tessellated: ") for w in split["warnings"]), split["warnings"]


def test_addon_says_tessellate_when_large_triangles_hold_the_light_changes(facts):
    value = fact(facts, "coarse_floor_suggests_tessellation")
    off, on = value["tessellate_False"], value["tessellate_True"]
    assert off["error"] is None and on["error"] is None
    hint = [w for w in off["warnings"] if "turn on Tessellate" in w]
    assert len(hint) == 1 and hint[0].startswith("'Floor': light changes cross ")
    # The size given is that of the triangles the warning counts (more than 8 texels each).
    assert float(re.search(r"those triangles cover (\d+) texels each on average", hint[0]).group(1)) > 8
    assert off["widening"] < 1.25
    assert not any("turn on Tessellate" in w for w in on["warnings"])
    # A floor of 9 vertices: the default budget adds 2, and the hint gives the budget at which the split
    # ends by itself, from a trial of the same split (the budget-64 run below makes it for real).
    assert off["vertices_before"] == 9
    large = value["tessellate_True_budget_64"]
    added = large["tessellation"]["vertices_added"]
    needed = re.search(r"with a Vertex Budget of ([\d.]+) or more \(the split of 'Floor' ends by itself at "
                       r"\+(\d+) to its 9 vertices; at 0.25 it stops short\)", hint[0])
    assert needed, hint[0]
    assert int(needed.group(2)) == added and added / 9 <= float(needed.group(1)) <= 1.1 * added / 9
    # On a map too large to try the split, the rough figure from the count of crossed triangles.
    rough = fact(value, "too_large_to_try")
    assert rough["error"] is None
    # In an atlas of two objects, how many of the triangles counted lie on the one holding the most.
    both = value["with_the_box"]
    assert both["error"] is None and [sorted(a) for a in both["atlases"].values()] == [["Blocker", "Floor"]], both
    hint = [w for w in both["warnings"] if "turn on Tessellate" in w]
    assert len(hint) == 1, both["warnings"]
    counted = re.search(r"light changes cross (\d+) triangle\(s\) of more than 8 texels, (\d+) of them on 'Floor',",
                        hint[0])
    assert counted and 0 < int(counted.group(2)) <= int(counted.group(1)), hint[0]
    # Each object's triangles are counted with the map's transition strength, so the shares add up to
    # the count (with each object's own strength, a random scene said "24 triangle(s) ..., 28 of them on").
    total, held = int(counted.group(1)), int(counted.group(2))
    assert both["counted"] == [{"Floor": held, "Blocker": total - held}]
    assert any("with a Vertex Budget well above 0.25 (at 0.25 it adds at most 2 to its 9 vertices)" in w
               for w in rough["warnings"]), rough["warnings"]
    # With Tessellate on at the default budget, the run says the budget ran out with triangles left to split.
    spent = [w for w in on["warnings"] if "Tessellate spent its Vertex Budget" in w]
    assert on["tessellation"]["vertices_added"] == 2 and on["tessellation"]["candidates_left"] > 0
    assert len(spent) == 1 and spent[0].startswith("'Floor': Tessellate spent its Vertex Budget (0.25x its 9 "
                                                   "vertices: 2 added) with ")
    assert f"with {on['tessellation']['coarse_left']} triangle(s) of more than 8 texels still crossed" in spent[0]
    # Spent with only small triangles left (the split goes on to 1 texel; a warp serves these): no warning.
    fine = value["tessellate_True_budget_16"]
    assert fine["error"] is None and fine["tessellation"]["stopped"] == "the vertex budget is spent"
    assert fine["tessellation"]["candidates_left"] > 0 and fine["tessellation"]["coarse_left"] == 0
    assert not any("Tessellate spent" in w or "turn on Tessellate" in w for w in fine["warnings"])
    # A budget large for 9 vertices: the split ends by itself, no warning, and the edges gain far more.
    assert large["error"] is None and large["tessellation"]["candidates_left"] == 0
    assert 2 < large["tessellation"]["vertices_added"] <= 64 * 9
    assert not any("Tessellate spent" in w or "turn on Tessellate" in w for w in large["warnings"])
    assert large["widening"] > on["widening"] + 0.2, (large["widening"], on["widening"])
    # A point light's falloff over the same coarse floor: the refinement's figures would call it coarse
    # (its triangles at light changes are large), but the light hardly steps: no advice.
    falloff = value["falloff"]
    assert falloff["error"] is None, falloff
    assert falloff["report"]["transition_triangle_texels"] >= 64, falloff["report"]
    assert not any("Tessellate" in w for w in falloff["warnings"]), falloff["warnings"]
    # Strength 0 moves nothing whatever the triangles: the run says so, and does not send the user to Tessellate.
    still = value["tessellate_False_strength_0"]
    assert still["error"] is None and any("nothing moved: strength is 0" in w for w in still["warnings"])
    assert not any("Tessellate" in w for w in still["warnings"]), still["warnings"]
