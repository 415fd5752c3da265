"""Charts folded over creases (lmrefine.folds) and the re-chart route they
open on a layout with room (docs/refiner.md "The re-chart route"): the
creases found, the folds' light changes measured in their band, the error
model counting them only where a layout keeps them inside a chart."""

import numpy as np
import pytest

import lmrefine
from lmrefine import folds as folds_module, rechart_route
from layouts import grid_chart

CELLS = 12
RESOLUTION = 128


def _roof(cells=CELLS):
    """A ridge roof: cells x cells quads over [-1, 1]^2 with z = -|x| (two
    slopes 90 degrees apart), per-corner positions (3T, 3), and one
    unfolded chart of it (Smart UV Project's kind: one chart over the
    ridge), per-corner UVs (3T, 2) and triangles (T, 3)."""
    uvs, triangles = grid_chart(cells, (0.05, 0.05), (0.95, 0.95))
    planar = (uvs.astype(np.float64) - 0.5) / 0.45  # [-1, 1]^2
    # The chart is the roof unfolded: arc length along x, so texels have the same world size.
    x = planar[:, 0] / np.sqrt(2.0)
    positions = np.column_stack([x, planar[:, 1], -np.abs(x)])
    return positions, uvs, triangles


def _cut(uvs):
    """The same chart cut at the ridge: the half with u > 0.5 moved right."""
    out = uvs.copy()
    tri_u = out.reshape(-1, 3, 2)[:, :, 0].mean(axis=1)
    right = np.repeat(tri_u > 0.5, 3)
    out[right, 0] = np.minimum(out[right, 0] + 0.02, 0.99)
    return out


def _sunlit(positions, uvs, triangles):
    scene = lmrefine.Scene()
    scene.add_mesh(positions.astype(np.float32), triangles, uvs=uvs)
    scene.add_light("sun", energy=3.0, angle=0.01, direction=(0.8, 0.0, -1.0))  # lights one slope more
    return np.ascontiguousarray(lmrefine.bake(scene, RESOLUTION, passes=("direct",), samples=8, seed=0)[0][..., :3])


@pytest.fixture(scope="module")
def roof_case():
    positions, uvs, triangles = _roof()
    return positions, uvs, triangles, _sunlit(positions, uvs, triangles)


def _energy(lightmap, uvs, triangles):
    mask = lmrefine.coverage_mask(uvs, triangles, RESOLUTION)
    return lmrefine.gradient_map(lightmap, mask).sum(axis=2), mask


def test_creases_finds_the_ridge_only():
    positions, _, triangles = _roof()
    faces, corner, length = folds_module.creases(positions, triangles, 20.0)
    assert len(faces) == CELLS  # one edge per row of quads along the ridge
    assert length.sum() == pytest.approx(2.0, rel=1e-6)  # the ridge spans y in [-1, 1]
    corners = positions[triangles]
    start = corners[faces[:, 0], corner]
    assert np.allclose(start[:, 0], 0.0)  # on x = 0
    # A flat floor has none; an angle above the fold's finds none either.
    flat = positions.copy()
    flat[:, 2] = 0.0
    assert len(folds_module.creases(flat, triangles, 20.0)[0]) == 0
    assert len(folds_module.creases(positions, triangles, 95.0)[0]) == 0


def test_creases_survive_degenerate_and_huge_faces():
    positions, _, triangles = _roof()
    positions = positions.copy()
    positions[triangles[0]] = positions[triangles[0][0]]  # a face with no area
    positions[triangles[-1, 2]] = (1e300, -1e300, 1e300)  # overflows its normal
    faces, _, length = folds_module.creases(positions, triangles, 20.0)
    assert np.isfinite(length).all()
    assert not np.isin(faces, [0, len(triangles) - 1]).any()
    assert len(folds_module.creases(np.zeros((0, 3)), np.zeros((0, 3), np.int32), 20.0)[0]) == 0


def test_folds_inside_a_chart_and_their_light(roof_case):
    positions, uvs, triangles, lightmap = roof_case
    energy, mask = _energy(lightmap, uvs, triangles)
    found = folds_module.find_folds(uvs, triangles, positions, 20.0, energy, mask)
    assert len(found.faces) == CELLS
    # The two slopes differ in light, so the ridge's band holds most of the light changes.
    assert found.band.sum() > 0 and found.energy_fraction > 0.5
    assert found.energy.sum() == pytest.approx(energy[found.band & mask].sum(), rel=1e-5)
    # Cut at the ridge, the layout holds no fold; the uncut one gives back nothing.
    cut = _cut(uvs)
    assert found.energy_removed(uvs, triangles).sum() == 0.0
    assert found.energy_removed(cut, triangles).sum() == pytest.approx(found.energy.sum())
    again = folds_module.find_folds(cut, triangles, positions, 20.0, energy, mask)
    assert len(again.faces) == 0 and again.energy_fraction == 0.0


def test_model_counts_folds_only_inside_charts(roof_case):
    positions, uvs, triangles, lightmap = roof_case
    energy, mask = _energy(lightmap, uvs, triangles)
    found = folds_module.find_folds(uvs, triangles, positions, 20.0, energy, mask)
    cut = _cut(uvs)
    keep = rechart_route.predicted_error(uvs, uvs, triangles, energy, positions, lightmap, folds=found)
    assert keep == pytest.approx(1.0)
    with_folds = rechart_route.predicted_error(uvs, cut, triangles, energy, positions, lightmap, folds=found)
    without = rechart_route.predicted_error(uvs, cut, triangles, energy, positions, lightmap)
    # Cutting the fold removes its light changes from the error: well below the same layout judged blind.
    assert with_folds < 0.6 * without


def test_route_recharts_a_folded_layout_with_room(roof_case):
    positions, uvs, triangles, lightmap = roof_case
    copies = [a.copy() for a in (positions, uvs, triangles, lightmap)]
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    for before, after in zip(copies, (positions, uvs, triangles, lightmap)):
        assert np.array_equal(before, after)
    info = result.report["rechart"]
    assert not info["room"]["no_room"]
    assert info["folds"]["count"] == CELLS and info["folds"]["energy_fraction"] > 0.5
    assert info["used"], info
    # The source layout's refinement predicts more, or could not predict less (its repack not made).
    source = info["predicted_error_source_route"] or info["source_route_bound"]
    assert info["predicted_error"] < min(rechart_route.REQUIRED_GAIN, source)
    assert result.report["notes"][0].startswith("re-charted: the source layout's charts fold over 12 creases")
    charts = lmrefine.find_charts(result.uvs, triangles, lmrefine.CHART_TOLERANCE)
    assert len(np.unique(charts)) == 2  # the two slopes
    check = lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)
    assert check["valid"], check
    again = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    assert np.array_equal(again.uvs, result.uvs)
    off = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions, rechart=False)
    assert not off.report["rechart"]["used"]
    assert len(np.unique(lmrefine.find_charts(off.uvs, triangles, lmrefine.CHART_TOLERANCE))) == 1


def test_route_on_a_folded_layout_equals_its_plain_pieces(roof_case, monkeypatch):
    # The route's fast pieces (the native carried map, one error model shared
    # by both predictions) give the same bits as the plain ones: the numpy
    # resampling and a fresh model per prediction.
    from test_rechart_route import _resample_numpy

    positions, uvs, triangles, lightmap = roof_case
    fast = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    model = rechart_route.ErrorModel
    monkeypatch.setattr(rechart_route, "resample_lightmap", _resample_numpy)
    monkeypatch.setattr(rechart_route, "ErrorModel", lambda *args, **kwargs: type("Fresh", (), {
        "relative": staticmethod(lambda layout: model(*args, **kwargs).relative(layout)),
        "lowest_packed": staticmethod(lambda *bound: model(*args, **kwargs).lowest_packed(*bound))})())
    plain = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    assert fast.report["rechart"]["used"] and plain.report["rechart"]["used"]
    assert np.array_equal(fast.uvs, plain.uvs) and np.array_equal(fast.grid, plain.grid)
    for key in ("predicted_error", "predicted_error_source_route", "source_route_bound"):
        assert fast.report["rechart"][key] == plain.report["rechart"][key]
    assert fast.report["notes"] == plain.report["notes"]


def test_the_folded_source_is_bounded_after_its_automaton(roof_case, monkeypatch):
    # The source refinement moved UVs inside its one chart: the bound starts from that layout, and
    # the route picks what the full comparison picks, with or without the source's repack made.
    from lmrefine import refine

    positions, uvs, triangles, lightmap = roof_case
    bounded = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    monkeypatch.setattr(refine, "_source_lowest", lambda stage: None)
    full = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    info, made = bounded.report["rechart"], full.report["rechart"]
    assert np.array_equal(bounded.uvs, full.uvs) and info["used"] == made["used"]
    assert info["source_route_bound"] is not None and made["source_route_bound"] is None
    assert info["source_route_bound"] <= made["predicted_error_source_route"] * (1 + 1e-9)
    if info["predicted_error_source_route"] is None:  # not made: the bound ruled it out
        assert info["predicted_error"] < info["source_route_bound"]


def test_route_without_folds_is_not_tried_and_says_why():
    # The same roof flattened: one chart, no crease, so the route is not tried (a crease search only).
    positions, uvs, triangles = _roof()
    positions = positions.copy()
    positions[:, 2] = 0.0
    lightmap = _sunlit(positions, uvs, triangles)
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    info = result.report["rechart"]
    assert not info["used"] and info["folds"]["count"] == 0
    assert "fold over no crease sharper than 20 degrees" in info["reason"]
    assert "charts" not in info  # not re-charted at all
    plain = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2)
    assert np.array_equal(plain.uvs, result.uvs)


def test_route_over_folds_in_flat_light_is_decided_by_the_model():
    # The sun straight down the ridge's plane of symmetry: both slopes equally lit, the fold holds
    # (almost) no light change. The route is tried; whatever the model decides, it says so and the
    # result is valid.
    positions, uvs, triangles = _roof()
    scene = lmrefine.Scene()
    scene.add_mesh(positions.astype(np.float32), triangles, uvs=uvs)
    scene.add_light("sun", energy=3.0, angle=0.01, direction=(0.0, 0.0, -1.0))
    lightmap = np.ascontiguousarray(lmrefine.bake(scene, RESOLUTION, passes=("direct",), samples=8,
                                                  seed=0)[0][..., :3])
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    info = result.report["rechart"]
    assert info["folds"]["count"] == CELLS and info["folds"]["energy_fraction"] < 0.05
    assert "predicted_error" in info and "predicted_error_source_route" in info
    source = info["predicted_error_source_route"] or info["source_route_bound"]  # made, or its bound
    assert info["used"] == (info["predicted_error"] < min(rechart_route.REQUIRED_GAIN, source + 1e-12))
    assert lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)["valid"]


def test_folds_of_a_self_overlapping_layout_are_not_searched_at_length(monkeypatch):
    # Every triangle over the whole atlas (a texture-like layout): the band search would read each
    # fold's whole bounding box; past MAX_SEARCH_TEXELS atlases the folds count as holding nothing.
    positions, uvs, triangles = _roof(4)
    spread = np.tile(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
                              np.float32), (len(triangles) // 2, 1))
    energy = np.ones((32, 32), np.float32)
    found = folds_module.find_folds(spread, triangles, positions, 20.0, energy)
    assert len(found.faces) > 0 and found.energy_fraction > 0
    monkeypatch.setattr(folds_module, "MAX_SEARCH_TEXELS", 0.1)
    capped = folds_module.find_folds(spread, triangles, positions, 20.0, energy)
    assert len(capped.faces) == len(found.faces) and capped.energy_fraction == 0.0


def test_fold_faces_need_no_bake():
    positions, uvs, triangles = _roof()
    faces, _, length = folds_module.fold_faces(uvs, triangles, positions, 20.0)
    assert len(faces) == CELLS and length.sum() == pytest.approx(2.0, rel=1e-6)
    assert len(folds_module.fold_faces(_cut(uvs), triangles, positions, 20.0)[0]) == 0


def _shading_normals(positions, triangles, smooth_ridge):
    """Per-corner shading normals (3T, 3) of the roof: each face's own
    (flat-shaded), or at the ridge's corners the mean of the two slopes'
    (smooth-shaded across the ridge, as Shade Smooth makes it)."""
    corners = positions[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    normals = np.repeat(face, 3, axis=0)
    if smooth_ridge:
        up = np.array([0.0, 0.0, 1.0]) * np.sign(face[:, 2].mean())
        normals[np.isclose(positions[triangles.ravel(), 0], 0.0)] = up
    return normals


def test_smooth_shaded_folds_are_told_apart():
    positions, _, triangles = _roof()
    faces, corner, _ = folds_module.creases(positions, triangles, 20.0)
    flat = _shading_normals(positions, triangles, smooth_ridge=False)
    smooth = _shading_normals(positions, triangles, smooth_ridge=True)
    assert not folds_module.smooth_shaded(positions, triangles, flat, faces, corner).any()
    assert folds_module.smooth_shaded(positions, triangles, smooth, faces, corner).all()
    # Smooth at one end of an edge only: still a step in the light there.
    half = smooth.copy()
    top = positions[triangles.ravel(), 1] > 0.5
    half[top] = flat[top]
    assert 0 < folds_module.smooth_shaded(positions, triangles, half, faces, corner).sum() < CELLS
    # A zero or non-finite normal agrees with nothing: its edges stay hard.
    for bad in (0.0, np.nan, np.inf, 1e308):
        broken = smooth.copy()
        broken[np.isclose(positions[triangles.ravel(), 0], 0.0)] = bad
        assert not folds_module.smooth_shaded(positions, triangles, broken, faces, corner).any()


def test_a_smooth_shaded_fold_holds_no_light_step(roof_case):
    positions, uvs, triangles, lightmap = roof_case
    energy, mask = _energy(lightmap, uvs, triangles)
    smooth = _shading_normals(positions, triangles, smooth_ridge=True)
    hard = folds_module.find_folds(uvs, triangles, positions, 20.0, energy, mask)
    soft = folds_module.find_folds(uvs, triangles, positions, 20.0, energy, mask, normals=smooth)
    assert len(soft.faces) == len(hard.faces) == CELLS  # still folds: they open the route
    assert soft.smooth.all() and not hard.smooth.any()
    assert hard.energy_fraction > 0.5 and soft.energy_fraction == 0.0 and not soft.band.any()
    # The model then credits a cut with nothing at the ridge.
    cut = _cut(uvs)
    assert not soft.energy_removed(cut, triangles).any() and hard.energy_removed(cut, triangles).sum() > 0


def test_route_reads_shading_normals(roof_case):
    positions, uvs, triangles, lightmap = roof_case
    smooth = _shading_normals(positions, triangles, smooth_ridge=True)
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions,
                                 normals=smooth)
    info = result.report["rechart"]
    assert info["folds"]["count"] == CELLS and info["folds"]["smooth"] == CELLS
    assert info["folds"]["energy_fraction"] == 0.0
    assert "predicted_error" in info  # tried, the model decided
    assert lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)["valid"]
    # Flat-shaded normals: the same as no normals (every crease a step).
    flat = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions,
                               normals=_shading_normals(positions, triangles, smooth_ridge=False))
    assert flat.report["rechart"]["used"] and flat.report["rechart"]["folds"]["smooth"] == 0
    none = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=positions)
    assert np.array_equal(flat.uvs, none.uvs)


def test_normals_are_checked():
    positions, uvs, triangles = _roof(2)
    lightmap = np.ones((32, 32, 3), np.float32)
    with pytest.raises(ValueError, match=r"normals= is read only with positions="):
        lmrefine.refine_uvs(lightmap, uvs, triangles, 32, normals=np.ones((len(uvs), 3)))
    with pytest.raises(ValueError, match=r"normals must have shape \(24, 3\)"):
        lmrefine.refine_uvs(lightmap, uvs, triangles, 32, positions=positions, normals=np.ones((3, 3)))
    with pytest.raises(TypeError, match="normals must hold real numbers"):
        lmrefine.refine_uvs(lightmap, uvs, triangles, 32, positions=positions,
                            normals=np.full((len(uvs), 3), "x"))
