"""bench/random_scenes.py builds, in headless Blender, the scene its draw
says: the lit objects with both lightmap maps, the casters with none, the
modifiers left as a user leaves them (docs/evaluation.md, "Scenes drawn at
random")."""

import json
import os
import shutil
import subprocess

import pytest

BLENDER = shutil.which("blender")
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Prints each mesh object's UV maps, modifiers and vertex count as JSON.
INSPECT = """
import bpy, json
print("SCENE " + json.dumps({o.name: {"uv": [l.name for l in o.data.uv_layers],
                                      "modifiers": [m.type for m in o.modifiers],
                                      "vertices": len(o.data.vertices)}
                             for o in bpy.data.objects if o.type == 'MESH'}))
print("LIGHTS " + json.dumps(sorted(o.data.type for o in bpy.data.objects if o.type == 'LIGHT')))
"""


@pytest.mark.skipif(BLENDER is None, reason="Blender is not installed")
def test_a_drawn_scene_is_built_as_its_draw_says(tmp_path):
    seed = 106  # a one-quad floor, two cubes, Suzanne, a pergola, a sun and two point lights
    subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                    os.path.join(REPO, "bench", "random_scenes.py"), "--", str(tmp_path), str(seed)],
                   check=True, capture_output=True, timeout=300)
    draw = json.loads((tmp_path / f"random_{seed}.json").read_text())["draw"]
    shown = subprocess.run([BLENDER, "-b", "--factory-startup", str(tmp_path / f"random_{seed}.blend"),
                            "--python-exit-code", "1", "--python-expr", INSPECT],
                           check=True, capture_output=True, text=True, timeout=300).stdout
    meshes = json.loads(next(line[6:] for line in shown.splitlines() if line.startswith("SCENE ")))
    lights = json.loads(next(line[7:] for line in shown.splitlines() if line.startswith("LIGHTS ")))
    props = [entry for entry in draw if "name" in entry]
    floor = draw[0]
    assert floor["kind"] == "floor" and floor["cuts"] == 0 and meshes["Floor"]["vertices"] == 4
    for name in ["Floor"] + [entry["name"] for entry in props]:
        assert meshes[name]["uv"] == ["UVMap", "Lightmap", "LightmapPack"], name
    for entry in props:
        if entry["kind"] == "suzanne":
            assert meshes[entry["name"]]["modifiers"] == ["SUBSURF"]
        if entry["kind"] == "cube":
            assert meshes[entry["name"]]["modifiers"] == (["SUBSURF"] if entry["simple_levels"] else [])
    casters = [entry["kind"] for entry in draw if entry.get("casts_only")]
    assert casters == ["pergola"] and meshes["Pergola"]["uv"] == []
    assert set(meshes) == {"Floor", "Pergola"} | {entry["name"] for entry in props}
    assert lights == sorted(entry["kind"].upper() for entry in draw if entry["kind"] in ("sun", "point", "spot",
                                                                                          "area"))
