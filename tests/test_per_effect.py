"""Separate layouts for separate effects (lmrefine.per_effect, evaluate
--per-effect): the effects add up to the combined light, the texels are
split within R^2, every effect's layout is valid, bad options are refused."""

import json

import numpy as np
import pytest

import lmrefine
from lmrefine import cli, metrics
from lmrefine.evaluation import EvaluationOptions, evaluate_sample
from lmrefine.per_effect import (EFFECTS, MIN_FRACTION, gradient_energy, parse_rules, split_fractions,
                                 split_resolutions)
from test_evaluation import tiny_scene


def test_direct_and_indirect_baked_apart_add_up_to_the_combined_light_at_the_points():
    scene = tiny_scene(12)
    uvs, _ = scene.layout("smart")
    lit = scene.to_scene(uvs)
    points = metrics.sample_surface(scene.positions, scene.triangles, 2000, normals=scene.normals, seed=0)
    at = metrics.interpolate_corners(uvs, points.triangle, points.bary)

    def lookup(passes, seed):
        return metrics.bilinear_lookup(lmrefine.bake(lit, 40, passes=passes, samples=64, seed=seed)[0][..., :3], at)

    direct, indirect = lookup("direct", 1), lookup("indirect", 2)
    combined, combined_again = lookup("combined", 3), lookup("combined", 4)
    assert indirect.mean() > 0.02 * direct.mean()  # the floor does get bounce light (from the slab)
    noise = np.sqrt(((combined - combined_again) ** 2).mean())  # two combined bakes, different seeds
    apart = np.sqrt(((direct + indirect - combined) ** 2).mean())
    assert apart < 1.5 * noise
    # No bias: far below the indirect light itself, which a sum missing it would lack.
    assert abs((direct + indirect).mean() - combined.mean()) < 0.1 * indirect.mean()
    # The ground truth at the points too: traced per effect, it adds up to the combined pass.
    truth = lmrefine.evaluate(lit, points.points, points.normals, passes=("direct", "indirect", "combined"),
                              samples=64, seed=5)
    assert np.abs(truth["direct"] + truth["indirect"] - truth["combined"]).max() < 1e-4


def test_gradient_energy_counts_covered_neighbours_only():
    image = np.zeros((4, 6, 4), np.float32)
    image[..., 3] = 1.0
    assert gradient_energy(image) == 0.0
    image[:, 3:, :3] = 0.5                      # a vertical step: 4 rows x 3 channels x 0.25
    assert gradient_energy(image) == pytest.approx(3.0)
    image[:, 3, 3] = 0.0                        # the step's right side in the gutter: no pair across it
    assert gradient_energy(image) == pytest.approx(0.0)


def test_gradient_energy_of_two_independent_bakes_leaves_the_noise_out():
    rng = np.random.default_rng(0)
    clean = np.ones((64, 64, 4))
    clean[:, 32:, :3] = 0.2                     # a vertical step: 64 rows x 3 channels x 0.64
    first, second = clean.copy(), clean.copy()
    first[..., :3] += rng.normal(0, 0.1, (64, 64, 3))
    second[..., :3] += rng.normal(0, 0.1, (64, 64, 3))
    assert gradient_energy(clean) == pytest.approx(122.88)
    assert gradient_energy(first) > 2 * 122.88              # the noise's own energy: 2 x 63 x 64 x 2 x 3 x 0.01
    assert gradient_energy(first, second) == pytest.approx(122.88, rel=0.2)
    with pytest.raises(ValueError, match="same map"):
        gradient_energy(first, second[:32])


def test_the_split_rules_share_out_at_most_r_squared_texels():
    energies = {"direct": 90.0, "indirect": 10.0}
    assert split_fractions("equal", energies) == {"direct": 0.5, "indirect": 0.5}
    assert split_fractions("energy", energies) == pytest.approx({"direct": 0.9, "indirect": 0.1})
    assert split_fractions("sqrt", energies) == pytest.approx({"direct": 0.75, "indirect": 0.25})
    starved = split_fractions("energy", {"direct": 1.0, "indirect": 0.0})
    assert starved["indirect"] == pytest.approx(MIN_FRACTION) and sum(starved.values()) == pytest.approx(1.0)
    for resolution in (32, 48, 100, 256, 1000):
        for fractions in ({"direct": 0.5, "indirect": 0.5}, {"direct": 0.9, "indirect": 0.1},
                          {"direct": 0.3, "indirect": 0.7}):
            sides = split_resolutions(resolution, fractions)
            total = sum(r * r for r in sides.values())
            # Square maps cannot always hit R^2 exactly; never above, and within one row and column each.
            assert total <= resolution ** 2
            assert total > resolution ** 2 - sum(2 * r + 1 for r in sides.values())
    with pytest.raises(ValueError, match="too small to split"):
        split_resolutions(10, {"direct": 0.5, "indirect": 0.5})


def test_per_effect_layouts_are_valid_and_their_sum_is_measured_against_one_combined_map(tmp_path):
    scene = tiny_scene(24)
    options = EvaluationOptions(resolution=40, points=1500, samples=8, truth_samples=32, multipliers=(1.0, 2.0, 4.0),
                                view_width=0, per_effect="equal,sqrt")
    report = evaluate_sample(scene, options, out_dir=str(tmp_path / "pe"))
    assert report["pass"] == "combined"  # the scene's own pass is direct: per-effect evaluates the sum
    per_effect = report["per_effect"]
    assert per_effect["effects"] == list(EFFECTS) and per_effect["combined_texels"] == 40 * 40
    assert [rule["rule"] for rule in per_effect["rules"]] == ["equal", "sqrt"]
    for rule in per_effect["rules"]:
        effects = rule["effects"]
        assert rule["texels"] == sum(e["texels"] for e in effects.values())
        assert 0.95 * 40 * 40 <= rule["texels"] <= 40 * 40
        for name, effect in effects.items():
            assert effect["layout_valid"] and effect["moved"]
            layout = np.load(tmp_path / "pe" / f"per_effect_{rule['rule']}_{name}_layout.npz")
            assert lmrefine.check_layout(layout["uvs"], layout["triangles"], effect["resolution"], 1.0)["valid"]
            assert not np.array_equal(layout["uvs"], layout["original_uvs"])
        # The sun's hard shadow edge makes the direct light's energy the larger; sqrt gives it more texels.
        assert effects["direct"]["energy"] > 10 * max(effects["indirect"]["energy"], 0.0)
        # Refining each effect from its own bake lowers the error of their sum.
        assert rule["transition_rmse_refined"] < 0.8 * rule["transition_rmse_plain"]
        assert effects["direct"]["transition_rmse_refined"] < 0.8 * effects["direct"]["transition_rmse_plain"]
    equal, sqrt = (rule["effects"] for rule in per_effect["rules"])
    assert equal["direct"]["resolution"] in (28, 29) and sqrt["direct"]["resolution"] > sqrt["indirect"]["resolution"]
    text = (tmp_path / "pe" / "report.md").read_text()
    assert "Separate layouts for separate effects" in text and "| sqrt | direct " in text
    assert json.loads((tmp_path / "pe" / "report.json").read_text())["per_effect"]["rules"][1]["rule"] == "sqrt"


def test_bad_per_effect_options_are_refused_with_the_fix(tmp_path, capsys):
    assert parse_rules("sqrt") == ("sqrt",) and parse_rules(["equal", "energy"]) == ("equal", "energy")
    with pytest.raises(ValueError, match="unknown per-effect split rule 'area'.*equal, energy, sqrt"):
        parse_rules("equal,area")
    with pytest.raises(ValueError, match="twice"):
        parse_rules("sqrt,sqrt")
    with pytest.raises(TypeError, match="split rule"):
        parse_rules(3)
    with pytest.raises(ValueError, match=r"leave the pass \(--pass\) unset or use 'combined'"):
        EvaluationOptions(per_effect="sqrt", bake_pass="direct").check()
    with pytest.raises(ValueError, match="stages=1 \\(--stages 1\\)"):
        EvaluationOptions(per_effect="sqrt", stages=2).check()
    assert cli.main(["evaluate", "courtyard", "--per-effect", "bright", "--out", str(tmp_path)]) == 2
    assert "unknown per-effect split rule 'bright'" in capsys.readouterr().err


@pytest.mark.parametrize("auto_rechart", [True, False])
def test_each_effect_is_refined_with_the_mesh_as_the_add_on_does(monkeypatch, auto_rechart):
    # The add-on's per-effect maps go through refine_uvs' re-chart route (positions and split normals);
    # the evaluation's must too, or it measures a different refinement.
    from lmrefine import evaluation
    calls = []

    def recording(*args, **kwargs):
        calls.append((kwargs.get("positions"), kwargs.get("normals")))
        return lmrefine.refine_uvs(*args, **kwargs)

    monkeypatch.setattr(evaluation, "refine_uvs", recording)
    scene = tiny_scene(12)
    options = EvaluationOptions(resolution=32, points=300, samples=4, truth_samples=8, multipliers=(1.0, 2.0),
                                view_width=0, per_effect="sqrt", auto_rechart=auto_rechart)
    evaluate_sample(scene, options)
    assert len(calls) == 1 + len(EFFECTS)  # the combined map, then one per effect
    for positions, normals in calls:
        if auto_rechart:
            assert positions.shape == normals.shape == (3 * len(scene.triangles), 3)
        else:
            assert positions is None and normals is None
