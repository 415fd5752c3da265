"""The evaluation pipeline end to end on a tiny scene (bake, refine, re-bake,
ground truth, metrics, report), and its CLI."""

import json
import re
from dataclasses import replace

import numpy as np
import pytest

import lmrefine
from lmrefine import cli, metrics
from lmrefine.sample_scenes import SampleScene, load_sample
from layouts import floor_grid

FIGURES = ("resolution", "rmse_baseline", "rmse_refined", "transition_rmse_baseline", "transition_rmse_refined",
           "transition_widening", "equal_error_resolution_ratio", "timings")


def tiny_scene(cells=24):
    """A 3 x 3 m floor of cells x cells quads (two objects: west and east
    halves) under a sun, a floating slab casting a hard shadow across it; the
    floor is one chart filling [0.05, 0.95]^2 of the atlas."""
    positions, triangles = floor_grid(cells, 1.5)
    corners = positions[triangles.reshape(-1)]
    uvs = (0.05 + 0.9 * (corners[:, :2] + 1.5) / 3.0).astype(np.float32)
    east = (positions[triangles].mean(axis=1)[:, 0] > 0).astype(np.int32)
    slab = np.array([(-0.6, -0.5, 1.0), (0.5, -0.5, 1.0), (0.5, 0.6, 1.0), (-0.6, 0.6, 1.0)], np.float32)
    return SampleScene(
        name="tiny", positions=positions, triangles=triangles,
        normals=np.tile(np.array([0, 0, 1], np.float32), (3 * len(triangles), 1)),
        uvs={"smart": uvs, "lightmap": uvs.copy()},
        base_color=np.full((len(triangles), 3), 0.7, np.float32), object_id=east, objects=["West", "East"],
        lights=[{"name": "Sun", "kind": "sun", "energy": 3.0, "color": [1, 1, 1],
                 "direction": [0.3, 0.2, -1.0], "angle": 0.01}],
        world=(0.05, 0.05, 0.05), passes=("direct",),
        occluder_positions=slab, occluder_triangles=np.array([(0, 1, 2), (0, 2, 3)], np.int32),
        description="a floor and a floating slab")


def test_evaluate_flags_reach_refine_uvs():
    args = cli.build_parser().parse_args(["evaluate", "courtyard", "--no-stretch", "--no-repack"])
    assert cli.evaluation_options(args).refine_options == {"repack": False, "max_stretch": 1.0}
    assert cli.evaluation_options(cli.build_parser().parse_args(["evaluate", "courtyard"])).refine_options == {}


def test_a_saved_scene_loads_back(tmp_path):
    scene = tiny_scene(4)
    scene.save(tmp_path / "tiny.npz")
    loaded = load_sample(str(tmp_path / "tiny.npz"))
    for key in ("positions", "triangles", "normals", "base_color", "object_id", "occluder_triangles"):
        np.testing.assert_array_equal(getattr(loaded, key), getattr(scene, key))
    np.testing.assert_array_equal(loaded.uvs["smart"], scene.uvs["smart"])
    assert loaded.lights == scene.lights and loaded.objects == ["West", "East"] and loaded.passes == ("direct",)


@pytest.mark.slow
def test_the_pipeline_reports_every_figure_with_sensible_values(tmp_path):
    scene = tiny_scene()
    scene.save(tmp_path / "tiny.npz")
    out = tmp_path / "out"
    assert cli.main(["evaluate", str(tmp_path / "tiny.npz"), "--resolution", "48", "--points", "3000",
                     "--samples", "8", "--truth-samples", "64", "--multipliers", "1,1.5,2,3,4",
                     "--out", str(out)]) == 0
    summary = json.loads((out / "report.json").read_text())
    assert summary["resolution"] == 48 and len(summary["scenes"]) == 1
    report = json.loads((out / "tiny_smart" / "report.json").read_text())
    assert report == summary["scenes"][0]
    for key in FIGURES:
        assert report[key] is not None, key
    assert report["resolution"] == 48
    # Errors are positive; the shadow edge is where the error is.
    for key in ("rmse_baseline", "rmse_refined", "transition_rmse_baseline", "transition_rmse_refined"):
        assert 0 < report[key] < 1, key
    assert report["transition_rmse_baseline"] > 2 * report["rmse_baseline"]
    # A top decile of the points are transitions, all on the edge of the shadow.
    assert 0.05 * 3000 < report["transition_points"] <= 0.1 * 3000 + 1
    # More texels, less error: the uniform baseline improves with resolution.
    sweep = [s["rmse"] for s in report["resolution_sweep"]]
    assert [s["resolution"] for s in report["resolution_sweep"]] == [48, 72, 96, 144, 192]
    assert sweep[-1] < 0.7 * sweep[0]
    # The refiner gave the transitions more texels, and the equal-error
    # search places the refined map where its error says.
    assert report["transition_widening"] > 1.05
    # Texels across the edges, measured along the light's gradient: more than none, and bounded by
    # what the area gain allows a stretch of at most 2 (2 x its square root).
    assert 1.0 < report["transition_widening_linear"] <= 2 * report["transition_widening"] ** 0.5
    stretch = report["refine"]["repack"]["stretch"]
    if stretch is not None:
        text = (out / "tiny_smart" / "report.md").read_text()
        assert "Chart stretch:" in text and stretch["charts_stretched"] >= 1
        assert (f"{stretch['charts_turned']} of them turned to their smallest boxes" in text) == \
            bool(stretch["charts_turned"])
    ratio, status = report["equal_error_resolution_ratio"], report["equal_error_status"]
    # The baseline is limited by resolution here, not noise: a ratio exists.
    assert status in ("within", "below", "above") and ratio > 0
    if report["rmse_refined"] < report["rmse_baseline"]:
        assert ratio > 1
    # The ground truth is much less noisy than the errors it measures.
    assert 0 <= report["truth_noise_rmse"] < 0.2 * report["rmse_baseline"]
    assert set(report["timings"]) == {"bake baseline", "refine", "bake refined", "ground truth",
                                      "bake resolution sweep", "uniform repack", "metrics", "pictures",
                                      "surface pictures", "total"}
    # The second baseline: the same charts packed at one scale, no signal.
    uniform = report["uniform_repack"]
    assert uniform["utilisation_after"] > uniform["utilisation_before"] > 0.5
    assert uniform["equal_error_resolution_ratio"] > 0 and uniform["rmse"] > 0
    assert uniform["signal_gain"] == pytest.approx(report["equal_error_resolution_ratio"]
                                                   / uniform["equal_error_resolution_ratio"])
    assert "Second baseline" in (out / "tiny_smart" / "report.md").read_text()
    assert report["timings"]["total"] == pytest.approx(sum(v for k, v in report["timings"].items() if k != "total"))
    # Per object: both halves, each with the same figures.
    assert [o["object"] for o in report["objects"]] == ["West", "East"]
    assert sum(o["points"] for o in report["objects"]) == 3000
    for o in report["objects"]:
        assert o["rmse_baseline"] > 0 and "transition_widening" in o and "equal_error_resolution_ratio" in o
    # Each half's share of the map's texels, refined against plain: together they keep the map's texels.
    assert all(o["texels"] > 0 for o in report["objects"])
    assert "texels, refined / plain" in (out / "tiny_smart" / "report.md").read_text()
    if not report["gain"]:
        assert report["notes"]
    for name in ("report.md", "lightmaps.png", "layout.png", "density.png", "error.png", "error_vs_resolution.png",
                 "baseline.exr", "refined.exr", "refined_layout.npz", "surface.png", "surface_crops.png",
                 "surface_density.png"):
        assert (out / "tiny_smart" / name).stat().st_size > 0, name
    layout = np.load(out / "tiny_smart" / "refined_layout.npz")
    assert lmrefine.check_layout(layout["uvs"], layout["triangles"], 48)["valid"]
    text = (out / "report.md").read_text()
    assert "tiny" in text and "equal-error" in text
    # The lit surface: the default camera sees the floor, the refined map is
    # closer to the ground truth there too, and both reports show the pictures.
    surface = report["surface"]
    assert surface["camera"] == "default" and surface["width"] == 480
    assert surface["receiver_pixels"] > 0.2 * surface["width"] * surface["height"]
    assert 0 < surface["rmse_refined"] < surface["rmse_plain"]
    assert surface["crops"] and all(c["rmse_plain"] > 0 for c in surface["crops"])
    assert "tiny_smart/surface.png" in text
    assert "![surface](surface.png)" in (out / "tiny_smart" / "report.md").read_text()


@pytest.mark.slow
def test_demo_runs_the_pipeline_on_the_bundled_courtyard(tmp_path, capsys):
    assert cli.main(["demo", "--resolution", "64", "--points", "2000", "--samples", "4", "--truth-samples", "32",
                     "--multipliers", "1,2", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "| courtyard | smart | 64 |" in printed
    report = json.loads((tmp_path / "courtyard_smart" / "report.json").read_text())
    assert report["scene"] == "courtyard" and all(report[key] is not None for key in FIGURES)
    assert {o["object"] for o in report["objects"]} >= {"Floor", "ArcadeNorth"}
    # The pictures of the lit surface (plain / refined / ground truth, the close-ups, the texel density),
    # rendered with lmrefine's own ray tracer, in the demo's output and linked from its report.md.
    pictures = ("surface.png", "surface_crops.png", "surface_density.png")
    assert all((tmp_path / "courtyard_smart" / name).stat().st_size > 0 for name in pictures)
    markdown = (tmp_path / "report.md").read_text()
    assert all(f"courtyard_smart/{name}" in markdown for name in pictures)
    # Stage 1 pictures: the gradient map of the baseline bake.
    assert (tmp_path / "gradient" / "gradient_direction.png").exists()
    summary = json.loads((tmp_path / "gradient" / "summary.json").read_text())
    assert summary["width"] == 64 and summary["channels"]["r"]["max"] > 0


def test_the_first_bake_can_have_samples_of_its_own():
    """--first-samples changes only the map the refinement reads: at the
    other bakes' count it is the same run, at another count the plain map and
    the uniform sweep stay what they were and the refined layout follows the
    first map."""
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample

    common = dict(resolution=48, points=1000, samples=4, truth_samples=16, multipliers=(1.0, 2.0), view_width=0)
    plain = evaluate_sample(tiny_scene(6), EvaluationOptions(**common))
    same = evaluate_sample(tiny_scene(6), EvaluationOptions(**common, first_samples=4))
    other = evaluate_sample(tiny_scene(6), EvaluationOptions(**common, first_samples=1))
    assert same["rmse_refined"] == plain["rmse_refined"] and same["first_samples"] == 4
    assert "bake first map" not in same["timings"] and "bake first map" in other["timings"]
    assert other["rmse_baseline"] == plain["rmse_baseline"]
    assert [s["rmse"] for s in other["resolution_sweep"]] == [s["rmse"] for s in plain["resolution_sweep"]]
    assert other["rmse_refined"] != plain["rmse_refined"] and other["first_samples"] == 1
    with pytest.raises(ValueError, match="first_samples"):
        EvaluationOptions(**common, first_samples=0).check()
    with pytest.raises(ValueError, match="first_samples"):
        EvaluationOptions(**common, per_effect="sqrt", first_samples=2).check()
    args = cli.build_parser().parse_args(["evaluate", "courtyard", "--first-samples", "8"])
    assert cli.evaluation_options(args).first_samples == 8


def test_evaluate_rejects_bad_arguments(tmp_path, capsys):
    assert cli.main(["evaluate", "no_such_scene", "--out", str(tmp_path)]) == 2
    assert "no sample scene" in capsys.readouterr().err
    assert cli.main(["evaluate", "courtyard", "--multipliers", "2,1", "--out", str(tmp_path)]) == 2
    assert "multipliers" in capsys.readouterr().err
    assert cli.main(["evaluate", "courtyard", "--view-width", "5000", "--out", str(tmp_path)]) == 2
    assert "view width must be 0 (no surface pictures) or 16 to 2048 pixels" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["evaluate", "--multipliers", "a,b"])


@pytest.mark.slow
def test_evaluate_rechart_replaces_the_layout_and_compares_with_the_scene_s_own(tmp_path):
    scene = tiny_scene(12)
    scene.save(tmp_path / "tiny.npz")
    out = tmp_path / "out"
    assert cli.main(["evaluate", str(tmp_path / "tiny.npz"), "--rechart", "30", "--compare", "--resolution", "48",
                     "--points", "2000", "--samples", "4", "--truth-samples", "32", "--multipliers", "1,2",
                     "--out", str(out)]) == 0
    report = json.loads((out / "tiny_rechart30" / "report.json").read_text())
    assert report["variant"] == "rechart30"
    layout = report["layout"]
    assert layout["source"] == "rechart" and layout["angle"] == 30 and layout["charts"] == 1
    assert layout["layout"]["valid"]
    # The maps were baked on the re-charted layout, not the scene's UVs.
    saved = np.load(out / "tiny_rechart30" / "refined_layout.npz")
    recharted = lmrefine.rechart(scene.positions, scene.triangles, 30.0, 48, 2.0).uvs
    np.testing.assert_array_equal(saved["original_uvs"], recharted)
    assert not np.array_equal(saved["original_uvs"], scene.uvs["smart"])
    # Against the scene's own layout: one row, both maps, a sweep of two.
    [compared] = report["layout_comparison"]
    assert compared["variant"] == "smart" and len(compared["resolution_sweep"]) == 2
    assert compared["equal_error_status_refined"] in ("within", "below", "above", "flat")
    text = (out / "tiny_rechart30" / "report.md").read_text()
    assert "re-charted from the mesh" in text and "Against the scene's own layouts" in text
    assert "against the scene's `smart` layout" in (out / "report.md").read_text()


def test_evaluate_rejects_a_bad_rechart_angle(tmp_path, capsys):
    assert cli.main(["evaluate", "courtyard", "--rechart", "95", "--out", str(tmp_path)]) == 2
    assert "rechart" in capsys.readouterr().err


def test_tessellation_lets_a_coarse_floor_gather_texels_at_the_shadow_edge(tmp_path):
    """3 x 3 quads: every triangle under the shadow edge covers ~100 texels at
    48^2, so the plain refinement cannot move texels towards the edge; the
    tessellated one can (docs/refiner.md, Tessellation)."""
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample

    scene = tiny_scene(3)
    common = dict(resolution=48, points=2000, samples=8, truth_samples=32, multipliers=(1.0, 2.0, 4.0))
    plain = evaluate_sample(scene, EvaluationOptions(**common))
    split = evaluate_sample(scene, EvaluationOptions(**common, tessellate=4.0), out_dir=str(tmp_path / "t"))
    t = split["tessellation"]
    assert t["vertices_before"] == 16 and 0 < t["vertices_added"] <= 64
    assert t["triangles_after"] > t["triangles_before"] == 18
    assert "tessellation" not in plain
    # The plain run gains, and says a larger gain is within reach (the add-on's Tessellate rule).
    assert plain["gain"] and plain["texels_per_transition_triangle"] >= 64
    # The note gives the budget at which the split ends by itself (a trial of evaluate --tessellate's split).
    from lmrefine.tessellation import budget_to_end
    advice = [re.search(r"split them with --tessellate ([\d.]+) \(the split of '(.+)' ends by itself there, "
                        r"at \+(\d+) to its 16 vertices\)", note) for note in plain["notes"]]
    advice = [found for found in advice if found]
    assert len(advice) == 1, plain["notes"]
    budget, added = float(advice[0].group(1)), int(advice[0].group(3))
    assert added >= t["vertices_added"] and budget == budget_to_end(added, 16) >= added / 16
    assert not any("--tessellate" in note for note in split["notes"])
    assert split["texels_per_transition_triangle"] < 0.5 * plain["texels_per_transition_triangle"]
    assert split["transition_widening"] > plain["transition_widening"] + 0.2
    # Each run compares with its own uniform baseline at the same points: the ratio rose (1.42x -> 1.99x).
    assert split["equal_error_resolution_ratio"] > plain["equal_error_resolution_ratio"] + 0.3
    # The split run measures the plain refinement itself, at the plain run's own points (found in the
    # pieces) against the same truth and uniform bakes: the plain run's figures, to rounding.
    assert t["plain_rmse"] == pytest.approx(plain["rmse_refined"], rel=1e-5)
    assert split["rmse_baseline"] == pytest.approx(plain["rmse_baseline"], rel=1e-5)
    assert t["plain_equal_error_resolution_ratio"] == pytest.approx(plain["equal_error_resolution_ratio"], abs=1e-4)
    assert t["gain_over_plain"] == pytest.approx(split["equal_error_resolution_ratio"]
                                                 / t["plain_equal_error_resolution_ratio"])
    assert t["gain_over_plain"] > 1.2
    layout = np.load(tmp_path / "t" / "refined_layout.npz")
    assert lmrefine.check_layout(layout["uvs"], layout["triangles"], 48)["valid"]
    text = (tmp_path / "t" / "report.md").read_text()
    assert "Tessellated along transitions" in text and "ratio over it" in text


def test_the_tessellation_budget_holds_per_object_and_points_map_to_their_input_triangle():
    """evaluate's tessellation gives each object its own budget (as the
    add-on does), keeps the scene's vertices and maps every output corner
    back into its input triangle."""
    from lmrefine.evaluation import _tessellated

    scene = tiny_scene(6)
    # Apart: the east half gets its own vertices (tiny_scene's halves share the middle column).
    middle = np.unique(scene.triangles[scene.object_id == 1])
    middle = middle[np.isin(middle, scene.triangles[scene.object_id == 0])]
    copies = {int(v): 49 + i for i, v in enumerate(middle)}
    east = scene.object_id == 1
    triangles = scene.triangles.copy()
    triangles[east] = np.vectorize(lambda v: copies.get(int(v), v))(triangles[east])
    scene = replace(scene, positions=np.concatenate([scene.positions, scene.positions[middle]]), triangles=triangles)
    # A light step across both halves (u = 0.3 and u = 0.7 in the atlas): both objects want splits.
    u = (np.arange(64) + 0.5) / 64
    baseline = np.repeat(np.where((u < 0.3) | (u > 0.7), 1.0, 0.1)[None, :, None], 64, axis=0).repeat(3, axis=2)
    split, report, (parent, parent_bary) = _tessellated(scene, "smart", baseline.astype(np.float32), 0.25)
    assert [o["objects"] for o in report["objects"]] == [["West"], ["East"]]
    for entry, index in zip(report["objects"], (0, 1)):
        own = len(np.unique(scene.triangles[scene.object_id == index]))
        assert entry["vertices_before"] == own and 0 < entry["vertices_added"] <= int(0.25 * own)
    assert report["vertices_before"] == len(scene.positions) == 56
    assert report["vertices_after"] == len(split.positions) == 56 + report["vertices_added"]
    np.testing.assert_array_equal(split.positions[:56], scene.positions)
    # Every output corner is its input triangle's point at the carried barycentric coordinates.
    expected = np.einsum("ck,ckd->cd", parent_bary, scene.positions[scene.triangles[np.repeat(parent, 3)]])
    np.testing.assert_allclose(split.positions[split.triangles.reshape(-1)], expected, atol=1e-5)
    np.testing.assert_array_equal(split.object_id, scene.object_id[parent])
    # The input mesh's surface points, found in the pieces: the same places, each in a piece of its triangle.
    from lmrefine.evaluation import into_pieces
    points = metrics.sample_surface(scene.positions, scene.triangles, 3000, seed=4)
    pieces = into_pieces((parent, parent_bary), points)
    assert (parent[pieces.triangle] == points.triangle).all() and (pieces.bary >= 0).all()
    assert len(np.unique(pieces.triangle)) > len(np.unique(points.triangle))  # split triangles' points spread
    at = np.einsum("pk,pkd->pd", pieces.bary, split.positions[split.triangles[pieces.triangle]])
    np.testing.assert_allclose(at, points.points, atol=1e-5)
    np.testing.assert_array_equal(pieces.normals, points.normals)


def test_the_summary_gives_the_tessellation_gain_over_plain(tmp_path):
    tiny_scene(3).save(tmp_path / "tiny.npz")
    out = tmp_path / "out"
    assert cli.main(["evaluate", str(tmp_path / "tiny.npz"), "--resolution", "48", "--points", "1000", "--samples",
                     "4", "--truth-samples", "16", "--multipliers", "1,2", "--tessellate", "2", "--view-width", "0",
                     "--out", str(out)]) == 0
    scene = json.loads((out / "report.json").read_text())["scenes"][0]
    line = next(row for row in (out / "report.md").read_text().splitlines() if "over plain" in row)
    assert f"+{scene['tessellation']['vertices_added']} vertices" in line
    assert f"**{scene['tessellation']['gain_over_plain']:.2f}x** over plain" in line


def test_welded_joins_one_objects_corners_at_one_position():
    from lmrefine.evaluation import welded

    # Two quads of object 0 with a vertex per corner (as export-scene writes them), a triangle of
    # object 1 on their shared edge, and an unused vertex.
    quad = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], np.float32)
    positions = np.concatenate([quad, quad + (1, 0, 0), [(1, 0, 0), (1, 1, 0), (2, 2, 0)], [(0, 0, 0)]])
    triangles = np.array([(0, 1, 2), (0, 2, 3), (4, 5, 6), (4, 6, 7), (8, 9, 10)], np.int32)
    welded_positions, welded_triangles = welded(positions, triangles, np.array([0, 0, 0, 0, 1]))
    # The quads share their edge now; object 1's corners and the unused vertex keep their own.
    assert len(welded_positions) == len(positions) - 2
    np.testing.assert_array_equal(welded_positions[welded_triangles], positions[triangles])
    assert len(np.intersect1d(welded_triangles[:2], welded_triangles[2:4])) == 2
    assert not np.intersect1d(welded_triangles[4], welded_triangles[:4]).size
    assert welded_triangles.dtype == triangles.dtype
    # Nothing to join: the same arrays back.
    scene = tiny_scene(3)
    same = welded(scene.positions, scene.triangles, scene.object_id)
    assert same[0] is scene.positions and same[1] is scene.triangles


def test_tessellating_a_scene_with_a_vertex_per_corner_keeps_its_faces_joined():
    """A scene file exported from Blender has a vertex per face corner: the
    split must still be conforming (an edge split in both faces), or the
    re-chart route finds T-junctions and refuses the split layout."""
    from lmrefine.evaluation import _tessellated

    scene = tiny_scene(4)
    corners = scene.triangles.reshape(-1)
    loose = replace(scene, positions=scene.positions[corners], object_id=np.zeros(len(scene.triangles), np.int32),
                    triangles=np.arange(len(corners), dtype=np.int32).reshape(-1, 3))
    u = (np.arange(64) + 0.5) / 64
    baseline = np.repeat(np.where(u < 0.45, 1.0, 0.1)[None, :, None], 64, axis=0).repeat(3, axis=2)
    split, report, _ = _tessellated(loose, "smart", baseline.astype(np.float32), 1.0)
    assert report["vertices_before"] == 25 and report["vertices_added"] > 0  # the budget of the real vertices
    assert report["triangles_after"] > report["triangles_before"]
    # No T-junction: every edge of the flat floor is in two triangles or on its outline.
    edges = np.sort(np.stack([split.triangles, np.roll(split.triangles, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    outline = 4 * 4  # the floor's border: 4 cells a side, split edges counted once more each
    assert (uses == 1).sum() <= outline + report["vertices_added"]
    assert lmrefine.rechart(split.positions, split.triangles, 20.0, 64).report["charts"] == 1


def test_objects_that_share_vertices_are_split_together():
    from lmrefine.evaluation import _connected_objects

    triangles = np.array([(0, 1, 2), (2, 3, 4), (5, 6, 7), (7, 8, 9), (10, 11, 12)])
    assert _connected_objects(triangles, np.array([0, 3, 1, 2, 4])) == [[0, 3], [1, 2], [4]]
    assert _connected_objects(triangles, np.array([2, 2, 0, 1, 2])) == [[0, 1], [2]]


def test_tessellation_without_splits_measures_the_plain_refinement_itself(tmp_path):
    """Budget 0 splits nothing: the plain refinement measured beside the
    tessellated one is the same refinement at the same points."""
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample

    report = evaluate_sample(tiny_scene(3), EvaluationOptions(resolution=48, points=1000, samples=4, truth_samples=16,
                                                              multipliers=(1.0, 2.0), tessellate=0.0, view_width=0))
    t = report["tessellation"]
    assert t["vertices_added"] == 0
    assert t["plain_rmse"] == pytest.approx(report["rmse_refined"], rel=1e-9)
    assert t["plain_transition_rmse"] == pytest.approx(report["transition_rmse_refined"], rel=1e-9)
    assert t["gain_over_plain"] == pytest.approx(1.0)
    assert t["plain_refine"]["backoff"] == report["refine"]["backoff"]


def test_rechart_and_tessellation_combine(tmp_path):
    """The re-charted layout is a UV variant of the scene: the tessellation
    carries it, and the refined layout is valid on the split triangles."""
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample

    scene = tiny_scene(3)
    options = EvaluationOptions(resolution=48, points=1000, samples=4, truth_samples=16, multipliers=(1.0, 2.0),
                                rechart=30.0, tessellate=1.0, view_width=0)
    report = evaluate_sample(scene, options, out_dir=str(tmp_path / "r"))
    assert report["variant"] == "rechart30" and report["layout"]["source"] == "rechart"
    assert report["tessellation"]["triangles_after"] > report["tessellation"]["triangles_before"] == 18
    layout = np.load(tmp_path / "r" / "refined_layout.npz")
    assert len(layout["triangles"]) == report["tessellation"]["triangles_after"]
    assert lmrefine.check_layout(layout["uvs"], layout["triangles"], 48)["valid"]
@pytest.mark.slow
def test_multi_stage_refinement_reports_every_stage_and_stops_when_a_stage_backs_off_or_settles():
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample

    scene = tiny_scene(24)
    common = dict(resolution=48, points=2000, samples=8, truth_samples=32, multipliers=(1.0, 2.0, 4.0))
    one = evaluate_sample(scene, EvaluationOptions(**common))
    many = evaluate_sample(scene, EvaluationOptions(**common, stages=4))
    history = many["stages"]["stages"]
    assert [e["stage"] for e in history] == [1, 2, 3] and "stages" not in one
    # Stage 3 flipped triangles and backed off to under a tenth of its deformation: it ends the stages.
    assert [e["kept"] for e in history] == [True, True, False]
    assert history[2]["backoff"] < metrics.STAGE_MIN_BACKOFF <= history[1]["backoff"]
    assert "stage 2 kept" in many["stages"]["stopped"] and "backed off" in many["stages"]["stopped"]
    assert many["stages"]["repack"] is True  # not re-charted from a layout with no room: repacked again
    assert history[0]["rmse"] == pytest.approx(one["rmse_refined"])  # stage 1 is the plain refinement
    # Stage 2, refined from stage 1's sharper bake, has a lower world-space error.
    assert history[1]["rmse"] < 0.8 * history[0]["rmse"] and history[1]["layout_change"] > 0.05
    kept = [e for e in history if e["kept"]]
    assert many["rmse_refined"] == pytest.approx(kept[-1]["rmse"])  # the report is the last kept stage's
    assert many["equal_error_resolution_ratio"] > one["equal_error_resolution_ratio"]
    # A stage whose layout hardly changes ends the stages, and is not used (strength 0: nothing moves).
    still = evaluate_sample(scene, EvaluationOptions(**common, stages=3, refine_options={"strength": 0.0}))
    assert [(e["stage"], e["kept"]) for e in still["stages"]["stages"]] == [(1, True), (2, False)]
    assert "stage 1 kept" in still["stages"]["stopped"]
    with pytest.raises(ValueError, match="stages must be an integer from 1 to 16"):
        evaluate_sample(scene, EvaluationOptions(**common, stages=0))


def test_evaluate_recharts_a_source_with_no_room_and_measures_against_it(tmp_path):
    """A Lightmap Pack-like source (a chart per quad): refine_uvs re-charts the floor (the route the add-on
    takes); the baseline and the sweep stay the source layout baked plain; --no-rechart refines the source."""
    from layouts import lightmap_pack
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample

    scene = tiny_scene(6)
    per_quad, _ = lightmap_pack(charts_across=6, margin_texels=3, resolution=48)
    scene.uvs["lightmap"] = per_quad.astype(np.float32)
    common = dict(resolution=48, points=1000, samples=4, truth_samples=16, multipliers=(1.0, 2.0),
                  variant="lightmap", view_width=0)
    report = evaluate_sample(scene, EvaluationOptions(**common), out_dir=str(tmp_path / "on"))
    rechart = report["refine"]["rechart"]
    assert rechart["used"] and rechart["room"]["no_room"] and rechart["charts"] == 1  # the flat floor
    assert report["layout"] == {"source": "scene", "variant": "lightmap"}
    layout = np.load(tmp_path / "on" / "refined_layout.npz")
    np.testing.assert_array_equal(layout["original_uvs"], per_quad)  # the baseline's layout: the source
    assert lmrefine.check_layout(layout["uvs"], layout["triangles"], 48)["valid"]
    assert "re-charted from the mesh** by refine_uvs" in (tmp_path / "on" / "report.md").read_text()
    off = evaluate_sample(scene, EvaluationOptions(**common, auto_rechart=False))
    assert off["refine"]["rechart"] is None
    # A second stage refines inside the re-charted charts (metrics.further_stage_options), and says so.
    two = evaluate_sample(scene, EvaluationOptions(**common, stages=2), out_dir=str(tmp_path / "two"))
    assert two["stages"]["repack"] is False
    assert "later stages refined inside the charts only" in (tmp_path / "two" / "report.md").read_text()


def test_the_report_says_when_the_repack_or_the_stretch_was_taken_at_square_roots():
    from lmrefine.evaluation_report import repack_lines
    assert repack_lines(None) == []
    stretch = {"used": True, "kind": "half", "charts_stretched": 2, "largest_stretch": 2 ** 0.5, "charts_turned": 0,
               "candidates": [{"largest_stretch": 2.0}, {"largest_stretch": 2 ** 0.5}]}
    softened = {"used": True, "refused": {"predicted_error": 0.6, "padded_utilisation_before": 0.93,
                                          "padded_utilisation_after": 0.81}}
    scales, stretched = repack_lines({"softened": softened, "stretch": stretch})
    assert "81% full" in scales and "input 93%" in scales and "square roots were packed and kept" in scales
    assert "up to 1.41x; kept (each at the square root of its factor: stretched fully, up to 2.00x" in stretched
    # The full stretch kept, or the repack not softened: no such words.
    full = dict(stretch, kind="main", largest_stretch=2.0, candidates=[{"largest_stretch": 2.0}])
    (line,) = repack_lines({"softened": dict(softened, used=False), "stretch": full})
    assert "square root" not in line and "up to 2.00x; kept." in line
    # Along the charts' axes (a smaller stretch than the full one, not its square root).
    axes = dict(stretch, kind="axes", largest_stretch=1.6, candidates=[{"largest_stretch": 2.0},
                                                                       {"largest_stretch": 1.6}])
    (line,) = repack_lines({"stretch": axes})
    assert "up to 1.60x; kept, each along its chart's u or v axis" in line and "square root" not in line
    refused = dict(stretch, used=False, reason="the stretched charts do not fit")
    (line,) = repack_lines({"stretch": refused})
    assert "not kept (the stretched charts do not fit)" in line and "square root" not in line


def test_a_note_names_the_objects_the_refined_map_serves_worse():
    from lmrefine.evaluation import _objects_served_worse

    def row(name, before, after, points=1000, texels=1.0):
        return {"object": name, "points": points, "rmse_baseline": before, "rmse_refined": after, "texels": texels}

    objects = [row("Shell", 0.0132, 0.0049, texels=1.1), row("Cabinet", 0.0011, 0.0031, texels=0.31),
               row("Lamp", 0.0100, 0.0120),                 # 20% worse: within OBJECT_WORSE
               row("Vase", 0.0010, 0.0016),                  # 60% worse, but by the truth's noise alone
               row("Cup", 0.001, 0.005, points=50)]          # too few points to say
    note = _objects_served_worse(objects, truth_noise=0.0004)
    assert note.startswith("objects the refined map serves worse than the plain bake: Cabinet (RMSE 0.0011 -> "
                           "0.0031, 0.31x its texels);")
    assert "Shell" not in note and "Lamp" not in note and "Vase" not in note and "Cup" not in note
    assert _objects_served_worse(objects[:1], truth_noise=0.0004) is None


def test_a_tight_input_is_refined_at_the_users_padding_as_the_add_on_refines_it(monkeypatch):
    """The input's charts overlap (the east half of the floor slid onto the
    west half: a gutter of 0, as a Subdivision Surface modifier leaves
    Suzanne's islands): evaluate still asks refine_uvs for the padding, as the add-on
    does (it keeps the touching pair's own distance and packs no closer
    than a texel), and the uniform repack packs as refine_uvs's repack does."""
    from lmrefine import evaluation
    from lmrefine.evaluation import EvaluationOptions, evaluate_sample
    from lmrefine.refine import pack_padding

    scene = tiny_scene(6)
    uvs = scene.uvs["smart"].reshape(-1, 3, 2).copy()
    east = scene.object_id == 1
    uvs[east, :, 0] -= 0.02
    scene.uvs = {"smart": uvs.reshape(-1, 2), "lightmap": uvs.reshape(-1, 2).copy()}
    assert lmrefine.check_layout(scene.uvs["smart"], scene.layout("smart")[1], 48, 2.0)["min_gutter_texels"] == 0.0
    seen = {}

    def refine_spy(*args, **kwargs):
        seen["refine"] = kwargs["padding"]
        return lmrefine.refine_uvs(*args, **kwargs)

    def pack_spy(uvs, triangles, charts, scales, resolution, padding, **kwargs):
        seen["pack"] = padding
        return lmrefine.pack_charts(uvs, triangles, charts, scales, resolution, padding, **kwargs)

    monkeypatch.setattr(evaluation, "refine_uvs", refine_spy)
    monkeypatch.setattr(evaluation, "pack_charts", pack_spy)
    evaluate_sample(scene, EvaluationOptions(resolution=48, points=500, samples=2, truth_samples=8,
                                             multipliers=(1.0, 2.0), view_width=0))
    assert seen == {"refine": 2.0, "pack": 1.0}
    assert pack_padding(2.0, {"min_gutter_texels": 0.0}) == 1.0
    assert pack_padding(2.0, {"min_gutter_texels": 1.03}) == 1.03
    assert pack_padding(2.0, {"min_gutter_texels": 5.0}) == 2.0
    assert pack_padding(0.5, {"min_gutter_texels": 0.0}) == 0.5
