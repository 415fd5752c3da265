import json
import subprocess
import sys
from pathlib import Path

import numpy as np

import lmrefine
from lmrefine import cli

ROOT = Path(__file__).resolve().parents[1]


def test_gradient_map_of_the_bundled_sample(tmp_path):
    sample = ROOT / "blend_samples"
    assert cli.main(["gradient-map", str(sample / "courtyard_lightmap.exr"), "--layout",
                     str(sample / "courtyard_layout.npz"), "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["width"] == summary["height"] == 256
    assert 0.5 < summary["covered_fraction"] < 1.0
    for letter in "rgba":
        assert (tmp_path / f"gradient_{letter}.png").exists()
        channel = summary["channels"][letter]
        # The sample has sharp sun shadows: every direction sees some edges, and
        # only a minority of texels is on an edge.
        assert channel["max"] > 0.05
        assert 0.0 < channel["active_fraction"] < 0.5
    gradient = lmrefine.read_image(tmp_path / "gradient_map.exr")
    assert gradient.shape == (256, 256, 4)
    layout = np.load(sample / "courtyard_layout.npz")
    mask = lmrefine.coverage_mask(layout["uvs"], layout["triangles"], 256)
    assert np.all(gradient[~mask] == 0)
    assert "Gradient map summary" in (tmp_path / "summary.md").read_text()


def test_gradient_map_command_with_mask_image_and_errors(tmp_path):
    image = np.zeros((32, 32), np.float32)
    image[:, 16:] = 1.0
    lmrefine.write_image(tmp_path / "lm.exr", image)
    mask = np.ones((32, 32), np.float32)
    lmrefine.write_image(tmp_path / "mask.png", mask)
    out = tmp_path / "out"
    assert cli.main(["gradient-map", str(tmp_path / "lm.exr"), "--mask", str(tmp_path / "mask.png"),
                     "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    # A vertical edge: light changes along x only.
    assert summary["channels"]["g"]["max"] > 0.1 and summary["channels"]["r"]["max"] == 0.0
    assert cli.main(["gradient-map", str(tmp_path / "missing.exr"), "--out", str(out)]) == 2


def test_module_entry_point_help():
    result = subprocess.run([sys.executable, "-m", "lmrefine", "--help"], capture_output=True, text=True,
                            env={"PYTHONPATH": str(ROOT / "python")})
    assert result.returncode == 0
    assert "gradient-map" in result.stdout and "demo" in result.stdout and "evaluate" in result.stdout
    result = subprocess.run([sys.executable, "-m", "lmrefine", "evaluate", "--help"], capture_output=True, text=True,
                            env={"PYTHONPATH": str(ROOT / "python")})
    assert result.returncode == 0 and "--resolution" in result.stdout and "--multipliers" in result.stdout
