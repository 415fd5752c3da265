"""Chart stretch (lmrefine.stretch): more texels across a chart's light changes, fewer along them."""

import numpy as np
import pytest

import lmrefine
from lmrefine import metrics, stretch
from layouts import SCALES_WITHIN_2, grid_chart, merge

RESOLUTION = 128


def _two_charts():
    """Two charts of 8 x 8 quads side by side."""
    return merge(grid_chart(8, (0.05, 0.1), (0.45, 0.9)), grid_chart(8, (0.55, 0.1), (0.95, 0.9)))


def _stripes(period_texels=8.0, along_u=True):
    """Hard stripes that change along u (constant along v), or the other way round."""
    i, j = np.mgrid[0:RESOLUTION, 0:RESOLUTION]
    coordinate = j if along_u else i
    light = np.where((coordinate // (period_texels / 2)) % 2 == 0, 1.0, 0.2).astype(np.float32)
    light[:, RESOLUTION // 2:] = 0.6  # the right chart is flat
    return np.repeat(light[..., None], 3, axis=2)


def _rotated(uvs, triangles, charts, chart):
    """`uvs` with chart `chart` turned by 90 degrees about its centre (orientation kept)."""
    out = uvs.astype(np.float64).copy()
    index = np.unique(triangles[charts == chart])
    centre = out[index].mean(axis=0)
    offset = out[index] - centre
    out[index] = centre + np.stack([-offset[:, 1], offset[:, 0]], axis=1)
    return out.astype(np.float32)


def test_stretch_charts_keeps_area_and_orientation_and_moves_only_stretched_charts():
    uvs, triangles = _two_charts()
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    direction = np.array([(1.0, 0.0), (0.0, 1.0)])
    out = stretch.stretch_charts(uvs, triangles, charts, np.array([1.5, 1.0]), direction)
    before, after = (lmrefine.allocation.signed_areas(u, triangles) for u in (uvs, out))
    np.testing.assert_allclose(after, before, rtol=1e-5)  # determinant 1: area and winding kept
    left = np.unique(triangles[charts == 0])
    right = np.unique(triangles[charts == 1])
    assert np.array_equal(out[right], uvs[right])
    # Reference: the map diag(1.5, 1 / 1.5) about the chart's mean UV.
    centre = uvs[left].astype(np.float64).mean(axis=0)
    expected = centre + (uvs[left] - centre) * np.array([1.5, 1 / 1.5])
    np.testing.assert_allclose(out[left], expected, atol=1e-6)
    # A diagonal direction: the same map turned by 45 degrees.
    diagonal = np.array([(np.sqrt(0.5), np.sqrt(0.5)), (1.0, 0.0)])
    turned = stretch.stretch_charts(uvs, triangles, charts, np.array([2.0, 1.0]), diagonal)
    e1, e2 = diagonal[0], np.array([-diagonal[0][1], diagonal[0][0]])
    offset = uvs[left] - centre
    expected = centre + np.outer(offset @ e1 * 2.0, e1) + np.outer(offset @ e2 / 2.0, e2)
    np.testing.assert_allclose(turned[left], expected, atol=1e-6)


def test_tensor_finds_the_stripes_direction_in_the_layout_being_stretched():
    uvs, triangles = _two_charts()
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    mask = lmrefine.coverage_mask(uvs, triangles, RESOLUTION)
    for along_u in (True, False):
        lightmap = _stripes(along_u=along_u)
        tensors = stretch.chart_tensors(lightmap, mask, uvs, uvs, triangles, charts)
        factor, direction, share, weight = stretch.stretch_factors(tensors, uvs, triangles, charts,
                                                                   (RESOLUTION, RESOLUTION), 2.0)
        axis = 0 if along_u else 1
        assert abs(direction[0][axis]) == pytest.approx(1.0, abs=1e-3)  # across the stripes
        assert factor[0] == pytest.approx(2.0) and share[0] > 0.99      # all the light changes run one way
        assert factor[1] == 1.0 and weight[1] == 0.0                    # the flat chart stays
    # The same source bake seen through a layout whose left chart is turned by 90 degrees: the direction turns.
    lightmap = _stripes(along_u=True)
    turned = _rotated(uvs, triangles, charts, 0)
    tensors = stretch.chart_tensors(lightmap, mask, uvs, turned, triangles, charts)
    _, direction, _, _ = stretch.stretch_factors(tensors, turned, triangles, charts, (RESOLUTION, RESOLUTION), 2.0)
    assert abs(direction[0][1]) == pytest.approx(1.0, abs=1e-3)


def test_stretch_factor_is_the_models_optimum_and_respects_its_bounds():
    # l1 / l2 = 16: the edge factor w1 / a + w2 a is least at a = (l1 / l2)^(1/4) = 2.
    tensors = np.array([[[16.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]], [[0.0, 0.0], [0.0, 0.0]]])
    uvs, triangles = merge(grid_chart(2, (0.0, 0.0), (0.3, 0.3)), grid_chart(2, (0.4, 0.0), (0.7, 0.3)),
                           grid_chart(2, (0.0, 0.4), (0.02, 0.7)))
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    factor, _, share, weight = stretch.stretch_factors(tensors, uvs, triangles, charts, (100, 100), 4.0)
    assert factor[0] == pytest.approx(2.0)
    grid = np.linspace(1.0, 4.0, 301)
    assert grid[np.argmin(stretch.edge_factor(grid, share[0]))] == pytest.approx(2.0, abs=0.01)
    assert factor[1] == 1.0           # isotropic light changes: no direction to stretch across
    assert factor[2] == 1.0           # no light changes (and below the mean chart's)
    assert weight.tolist() == pytest.approx([5.0, 2.0, 0.0])
    assert stretch.stretch_factors(tensors, uvs, triangles, charts, (100, 100), 1.5)[0][0] == pytest.approx(1.5)
    # A chart 2 texels wide across the squeezed direction is never squeezed below MIN_WIDTH_TEXELS.
    thin = np.array([[[1.0, 0.0], [0.0, 16.0]], [[0.0, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]]])
    factor, direction, _, _ = stretch.stretch_factors(thin, uvs, triangles, charts, (100, 100), 4.0)
    assert abs(direction[0][1]) == pytest.approx(1.0)  # stretched along v, squeezed along u
    assert factor[0] == pytest.approx(2.0)  # the chart is 30 texels wide along u: room to squeeze
    narrow = thin[[2, 1, 0]]  # the 2-texel-wide third chart gets the stripes
    factor, _, _, _ = stretch.stretch_factors(narrow, uvs, triangles, charts, (100, 100), 4.0)
    assert factor[2] == 1.0


def test_tensor_edge_factor_is_the_trace_of_the_stretched_tensors_root():
    # tr sqrt(J') / tr sqrt(J), J' the tensor in the stretched frame, read from its eigenvalues.
    rng = np.random.default_rng(0)
    shape = rng.normal(size=(6, 2, 2))
    tensors = shape @ shape.transpose(0, 2, 1)
    factor = np.array([1.0, 1.2, 1.5, 2.0, 3.0, 0.7])
    angle = rng.uniform(0, np.pi, 6)
    direction = np.stack([np.cos(angle), np.sin(angle)], -1)
    for k in range(6):
        e1, e2 = direction[k], np.array([-direction[k, 1], direction[k, 0]])
        frame = np.stack([e1 / factor[k], e2 * factor[k]])  # a gradient's parts along e1, e2 after the stretch
        stretched = frame @ tensors[k] @ frame.T
        expected = np.sqrt(np.linalg.eigvalsh(stretched).clip(0)).sum() / np.sqrt(np.linalg.eigvalsh(tensors[k])).sum()
        assert stretch.tensor_edge_factor(tensors[k:k + 1], factor[k:k + 1], direction[k:k + 1])[0] == \
            pytest.approx(expected, rel=1e-9)
    # Along the main direction it is the model's edge_factor.
    values, vectors = np.linalg.eigh(tensors)
    share = np.sqrt(values[:, 1]) / np.sqrt(values).sum(axis=1)
    np.testing.assert_allclose(stretch.tensor_edge_factor(tensors, factor, vectors[:, :, 1]),
                               stretch.edge_factor(factor, share), rtol=1e-9)


def test_axis_stretch_is_the_models_optimum_along_the_axis_the_light_changes_cross_more():
    # Stripes at 30 degrees to u: their light changes cross u three times as much as v (cos^2 : sin^2).
    across = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    tensors = np.array([16.0 * np.outer(across, across) + np.eye(2), np.eye(2) * 0.5, np.eye(2) * 0.01])
    uvs, triangles = merge(grid_chart(2, (0.0, 0.0), (0.3, 0.3)), grid_chart(2, (0.4, 0.0), (0.7, 0.3)),
                           grid_chart(2, (0.0, 0.4), (0.3, 0.7)))
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    main, _, share, roots = stretch.stretch_factors(tensors, uvs, triangles, charts, (100, 100), 4.0)
    factor, direction, edge = stretch.axis_stretch_factors(tensors, roots, uvs, triangles, charts, (100, 100), 4.0)
    uu, vv = tensors[0, 0, 0], tensors[0, 1, 1]
    assert direction[0].tolist() == [1.0, 0.0] and factor[0] == pytest.approx((uu / vv) ** 0.25)
    grid = np.linspace(1.0, 4.0, 3001)
    along_u = stretch.tensor_edge_factor(np.repeat(tensors[:1], len(grid), 0), grid,
                                         np.tile([1.0, 0.0], (len(grid), 1)))
    assert grid[np.argmin(along_u)] == pytest.approx(factor[0], abs=1e-3)
    assert edge[0] == pytest.approx(along_u.min(), rel=1e-6) and edge[0] < 1.0
    # Its gain is less than the stretch along the stripes' own direction gives.
    assert stretch.edge_factor(main[0], share[0]) < edge[0]
    assert factor[1] == factor[2] == 1.0 and edge[1] == edge[2] == 1.0  # isotropic; below the mean chart
    assert stretch.axis_stretch_factors(tensors, roots, uvs, triangles, charts, (100, 100), 1.2)[0][0] == \
        pytest.approx(1.2)
    # Light changes crossing v more: stretched along v.
    turned = tensors[:, ::-1, ::-1]  # the same eigenvalues, so the same roots
    assert stretch.axis_stretch_factors(turned, roots, uvs, triangles, charts, (100, 100), 4.0)[1][0].tolist() == \
        [0.0, 1.0]


def _nine_charts():
    """3 x 3 square charts; hard stripes along u over the two top-left ones, flat light elsewhere."""
    uvs, triangles = merge(*[grid_chart(4, (0.02 + a / 3, 0.02 + b / 3), (0.31 + a / 3, 0.31 + b / 3))
                             for b in range(3) for a in range(3)])
    j = np.arange(RESOLUTION)
    light = np.full((RESOLUTION, RESOLUTION), 0.6, np.float32)
    light[:RESOLUTION // 3, :2 * RESOLUTION // 3] = np.where((j[:2 * RESOLUTION // 3] // 4) % 2 == 0, 1.0, 0.2)
    return uvs, triangles, np.repeat(light[..., None], 3, axis=2)


def test_refine_uvs_stretches_striped_charts_across_their_stripes():
    uvs, triangles, lightmap = _nine_charts()
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, **SCALES_WITHIN_2)
    report = result.report["repack"]["stretch"]
    assert result.report["repack"]["used"] and report["used"], report
    assert report["charts_stretched"] == 2 and report["largest_stretch"] == pytest.approx(2.0)
    assert report["predicted_error"] < report["predicted_error_unstretched"]
    assert lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)["valid"]
    # Measured on the output: the striped charts' texels across the stripes (u in the source) gained
    # more than their texels along them, whatever turn the packer gave each chart.
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    striped = np.isin(charts, np.flatnonzero(report["chart_stretch"] > 1))
    world = np.concatenate([uvs, np.zeros((len(uvs), 1), np.float32)], axis=1)[triangles[striped]]
    point_triangle = np.arange(int(striped.sum()))
    gains = []
    for direction in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        d = np.tile(direction, (len(point_triangle), 1))
        before = metrics.texels_across(world, uvs[triangles[striped]], point_triangle, d, RESOLUTION)
        after = metrics.texels_across(world, result.uvs[triangles[striped]], point_triangle, d, RESOLUTION)
        gains.append(np.median(after / before))
    assert gains[0] > 3.0 * gains[1]  # a stretch of 2: 4x the ratio across over along
    # Off: no stretch is tried, and the layout differs.
    off = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, max_stretch=1.0, **SCALES_WITHIN_2)
    assert off.report["repack"]["stretch"] is None and off.report["repack"]["used"]
    assert not np.array_equal(off.uvs, result.uvs)
    # The input's density, which both packings must keep, does not depend on the stretch chosen.
    assert result.report["repack"]["padded_utilisation_before"] == \
        pytest.approx(off.report["repack"]["padded_utilisation_before"])
    again = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, **SCALES_WITHIN_2)
    assert np.array_equal(again.uvs, result.uvs)  # deterministic
    for bad in (0.5, float("inf"), float("nan"), True, "2"):
        with pytest.raises(ValueError, match="max_stretch"):
            lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, max_stretch=bad)


def _four_charts_one_striped(gap):
    """2 x 2 square charts, `gap` UV inside each quarter of the atlas; hard stripes along u over the
    top-left one, flat light elsewhere. Returns (uvs, triangles, lightmap)."""
    uvs, triangles = merge(*[grid_chart(6, (gap + 0.5 * a, gap + 0.5 * b), (0.5 - gap + 0.5 * a, 0.5 - gap + 0.5 * b))
                             for b in (0, 1) for a in (0, 1)])
    half = RESOLUTION // 2
    j = np.arange(half)
    light = np.full((RESOLUTION, RESOLUTION), 0.6, np.float32)
    light[:half, :half] = np.where((j // 4) % 2 == 0, 1.0, 0.2)
    return uvs, triangles, np.repeat(light[..., None], 3, axis=2)


def test_a_stretch_that_packs_less_densely_than_the_input_is_not_kept():
    """Four charts: stretching the striped one would leave the atlas emptier than the input."""
    uvs, triangles, lightmap = _four_charts_one_striped(gap=0.03)
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2)
    report = result.report["repack"]["stretch"]
    assert result.report["repack"]["used"] and not report["used"]
    assert report["predicted_error"] < report["predicted_error_unstretched"]  # the model alone would take it
    assert "pack less densely" in report["reason"]


def test_a_stretch_too_loose_at_its_factor_is_kept_at_its_square_root():
    """Four charts with more room around them: stretched by 2 the striped chart still leaves the
    atlas emptier than the input; stretched by its square root (half the stretch in log scale) it
    packs densely enough, and that is kept, with the report's factors the ones used."""
    uvs, triangles, lightmap = _four_charts_one_striped(gap=0.04)
    # The chart stretch alone (the triangle stretch would stretch the striped chart's triangles further).
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, triangle_stretch=1.0,
                                 **SCALES_WITHIN_2)
    report = result.report["repack"]["stretch"]
    full, root = report["candidates"]  # the stripes run along an axis: no sheared chart to turn
    assert full["largest_stretch"] == pytest.approx(2.0) and not full["dense"]
    assert root["largest_stretch"] == pytest.approx(np.sqrt(2.0)) and root["dense"]
    assert report["used"] and report["largest_stretch"] == pytest.approx(np.sqrt(2.0))
    assert report["predicted_error"] == root["predicted_error"] < report["predicted_error_unstretched"]
    assert lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)["valid"]
    # Measured on the output: the striped chart's texels across its stripes over along them, 2 for a
    # stretch of sqrt(2) whatever turn the packer gave it, 1 for the flat charts (medians: the
    # automaton moves the triangles inside the charts too).
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    world = np.concatenate([uvs, np.zeros((len(uvs), 1), np.float32)], axis=1)[triangles]
    point_triangle = np.arange(len(triangles))
    gains = []
    for direction in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        d = np.tile(direction, (len(triangles), 1))
        gains.append(metrics.texels_across(world, result.uvs[triangles], point_triangle, d, RESOLUTION)
                     / metrics.texels_across(world, uvs[triangles], point_triangle, d, RESOLUTION))
    ratio = gains[0] / gains[1]
    striped = charts == int(np.argmax(report["chart_stretch"]))
    assert np.median(ratio[striped]) == pytest.approx(2.0, rel=0.03)
    assert np.median(ratio[~striped]) == pytest.approx(1.0, rel=0.03)


def test_texels_across_reads_the_layouts_map_along_a_surface_direction():
    # One triangle in the world's xy plane, mapped to UV at 2 UV units per metre along x, 1 along y.
    world = np.array([[(0, 0, 0), (1, 0, 0), (0, 1, 0)]], np.float64)
    uv = np.array([[(0, 0), (0.02, 0), (0, 0.01)]], np.float64)
    directions = np.array([(1, 0, 0), (0, 1, 0), (np.sqrt(0.5), np.sqrt(0.5), 0)], np.float64)
    across = metrics.texels_across(world, uv, np.zeros(3, np.int64), directions, 100)
    np.testing.assert_allclose(across, [2.0, 1.0, np.sqrt(2.5)])
    # The gradient direction from a stencil: light rising along +y.
    points = np.zeros((1, 3))
    stencil = np.array([(0.1, 0, 0), (0, 0.1, 0)], np.float64)
    truth = np.full((1, 3), 0.5)
    neighbours = np.array([(0.5, 0.5, 0.5), (0.9, 0.9, 0.9)])
    np.testing.assert_allclose(metrics.surface_gradient_direction(points, truth, stencil, neighbours),
                               [(0, 1, 0)], atol=1e-12)
    # An isotropic layout change: across-edge gain = sqrt of the area gain.
    gain = metrics.transition_widening_across(world, uv, uv * 3, np.zeros(2, np.int64), directions[:2],
                                              np.ones(2, bool), 100)
    assert gain == pytest.approx(3.0)


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_the_stretch_does_not_depend_on_the_lights_scale():
    """Huge or tiny light (HDR bakes, wrong units): the same charts stretch by the same factors, no overflow."""
    uvs, triangles, lightmap = _nine_charts()
    reports = [lmrefine.refine_uvs((lightmap * scale).astype(np.float32), uvs, triangles, RESOLUTION,
                                   padding=2).report["repack"]["stretch"] for scale in (1.0, 1e30, 1e-30)]
    for report in reports[1:]:
        assert report["used"] == reports[0]["used"]
        np.testing.assert_allclose(report["chart_stretch"], reports[0]["chart_stretch"], rtol=1e-6)
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    mask = lmrefine.coverage_mask(uvs, triangles, RESOLUTION)
    flat = np.full_like(lightmap, 0.5)
    assert not stretch.chart_tensors(flat, mask, uvs, uvs, triangles, charts).any()  # no light change: no tensor


def _smallest_box_reference(points, steps=3600):
    """The smallest axis-aligned box area over turns in [0, 90) degrees, by trying them all (plain reference)."""
    best = np.inf
    for angle in np.linspace(0.0, np.pi / 2, steps, endpoint=False):
        c, s = np.cos(angle), np.sin(angle)
        turned = points @ np.array([[c, s], [-s, c]])
        best = min(best, np.ptp(turned[:, 0]) * np.ptp(turned[:, 1]))
    return best


def _box_area(points):
    return np.ptp(points[:, 0]) * np.ptp(points[:, 1])


def test_smallest_box_turns_match_a_search_over_all_turns():
    rng = np.random.default_rng(3)
    uvs, triangles, charts = [], [], []
    for chart in range(6):
        points = rng.normal(size=(12, 2)) * rng.uniform(0.02, 0.1, size=2) + 0.5
        base = sum(len(p) for p in uvs)
        uvs.append(points)
        triangles.append(base + np.array([(0, k, k + 1) for k in range(1, 11)]))
        charts += [chart] * 10
    uvs, triangles, charts = np.concatenate(uvs), np.concatenate(triangles), np.array(charts)
    turns = lmrefine._native.smallest_box_turns(uvs, triangles, charts)
    assert turns.shape == (6, 2)
    np.testing.assert_allclose(np.hypot(turns[:, 0], turns[:, 1]), 1.0)
    for chart in range(6):
        points = uvs[np.unique(triangles[charts == chart])]
        c, s = turns[chart]
        turned = points @ np.array([[c, s], [-s, c]])  # rows: (c x - s y, s x + c y)
        assert _box_area(turned) <= _smallest_box_reference(points) * (1 + 1e-9)
    # An id with no triangles keeps (1, 0); bad input is a ValueError naming it, never a crash.
    gap = lmrefine._native.smallest_box_turns(uvs, triangles, np.where(charts == 5, 7, charts))
    np.testing.assert_array_equal(gap[5], [1.0, 0.0])
    bad_uvs = uvs.copy()
    bad_uvs[3] = np.nan
    for args, match in (((bad_uvs, triangles, charts), "uv"), ((uvs, triangles, charts[:-1]), "charts"),
                        ((uvs, triangles, charts + len(triangles)), "charts"), ((uvs, triangles + 1000, charts),
                                                                                 "triangles|index")):
        with pytest.raises(ValueError, match=match):
            lmrefine._native.smallest_box_turns(*args)


def test_turn_to_smallest_boxes_turns_a_sheared_chart_and_nothing_else():
    uvs, triangles = _two_charts()
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    diagonal = np.array([(np.sqrt(0.5), np.sqrt(0.5))] * 2)
    sheared = stretch.stretch_charts(uvs, triangles, charts, np.array([2.0, 1.0]), diagonal)
    out, turned = stretch.turn_to_smallest_boxes(sheared, triangles, charts, np.array([True, True]))
    # The stretched (sheared) chart turns; the axis-aligned one is already in its smallest box.
    assert turned.tolist() == [True, False]
    left, right = (np.unique(triangles[charts == c]) for c in (0, 1))
    assert np.array_equal(out[right], sheared[right])
    np.testing.assert_allclose(_box_area(out[left]), _smallest_box_reference(sheared[left]), rtol=1e-3)
    assert _box_area(out[left]) < stretch.TURN_GAIN * _box_area(sheared[left])
    # A turn: areas, winding and the shape's distances are kept.
    np.testing.assert_allclose(lmrefine.allocation.signed_areas(out, triangles),
                               lmrefine.allocation.signed_areas(sheared, triangles), rtol=1e-4)
    distance = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(distance(out[left]), distance(sheared[left]), atol=1e-5)
    # Charts not asked for stay, whatever their box.
    same, none = stretch.turn_to_smallest_boxes(sheared, triangles, charts, np.array([False, False]))
    assert not none.any() and np.array_equal(same, sheared)


def _diagonal_stripes(gap):
    """4 x 4 square charts over 0.97 of the atlas, `gap` UV inside each cell; hard diagonal
    stripes over the two top-left charts, flat light elsewhere."""
    w = 0.97 / 4
    uvs, triangles = merge(*[grid_chart(4, (gap + a * w, gap + b * w), ((a + 1) * w - gap, (b + 1) * w - gap))
                             for b in range(4) for a in range(4)])
    i, j = np.mgrid[0:RESOLUTION, 0:RESOLUTION]
    light = np.full((RESOLUTION, RESOLUTION), 0.6, np.float32)
    rows, cols = slice(RESOLUTION - int(RESOLUTION * w), RESOLUTION), slice(0, int(2 * RESOLUTION * w))
    light[rows, cols] = np.where(((i + j) // 4) % 2 == 0, 1.0, 0.2)[rows, cols]
    return uvs, triangles, np.repeat(light[..., None], 3, axis=2)


def test_diagonally_stretched_charts_too_loose_to_keep_are_packed_turned_to_their_smallest_boxes():
    """Stretched along a diagonal, the striped charts are sheared and their atlas fails the density
    rule; turned to their smallest boxes they pack closer, and that packing is kept."""
    uvs, triangles, lightmap = _diagonal_stripes(gap=0.02)
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, **SCALES_WITHIN_2)
    report = result.report["repack"]["stretch"]
    assert report["used"] and report["charts_stretched"] == 2 and report["charts_turned"] == 2, report
    plain, turned = report["candidates"]
    assert plain["charts_turned"] == 0 and not plain["dense"]
    assert turned["charts_turned"] == 2 and turned["dense"]
    assert turned["padded_utilisation"] > plain["padded_utilisation"]
    assert report["predicted_error"] == turned["predicted_error"] < report["predicted_error_unstretched"]
    before = result.report["repack"]["padded_utilisation_before"]
    for candidate in (plain, turned):
        kept_density = lmrefine.allocation.MIN_UTILISATION_KEPT * before
        assert candidate["dense"] == (candidate["padded_utilisation"] >= kept_density)
    after = result.report["repack"]["padded_utilisation_after"]
    if result.report["repack"]["fill"]["charts_grown"]:  # charts grew into the space the packing left
        assert after > turned["padded_utilisation"]
    else:
        assert after == pytest.approx(turned["padded_utilisation"])
    assert lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)["valid"]
    # Measured on the output: each stretched chart's box is its smallest (a stretch of 2 along the
    # diagonal of a square, unturned, fills a box 4 times its area).
    charts = lmrefine.find_charts(uvs, triangles, lmrefine.CHART_TOLERANCE)
    areas = np.bincount(charts, weights=np.abs(lmrefine.allocation.signed_areas(result.uvs, triangles)))
    for chart in np.flatnonzero(report["chart_stretch"] > 1):
        points = result.uvs[np.unique(triangles[charts == chart])].astype(np.float64)
        assert _box_area(points) == pytest.approx(_smallest_box_reference(points), rel=1e-2)
        assert _box_area(points) < 2.0 * areas[chart]


def test_a_stretched_packing_dense_enough_keeps_its_orientation_and_no_turn_is_packed():
    """The same charts with more room: the sheared charts pack densely enough as they are, so they
    keep their orientation to the texel grid and the turned fallback is not packed."""
    uvs, triangles, lightmap = _diagonal_stripes(gap=0.03)
    report = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2,
                                 **SCALES_WITHIN_2).report["repack"]["stretch"]
    assert report["used"] and report["charts_turned"] == 0
    assert len(report["candidates"]) == 1 and report["candidates"][0]["dense"]


def test_cancelling_during_the_turned_fallback_cancels_the_refinement():
    """The fallback's packing honours the caller's progress: asked to stop there, refine_uvs stops."""
    uvs, triangles, lightmap = _diagonal_stripes(gap=0.02)
    packs = []

    def progress(fraction, stage):
        if stage == "pack":
            packs.append(fraction)
        return len(packs) < 3  # the first packing reports twice; the third report is the fallback's

    with pytest.raises(lmrefine.CancelledError):
        lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, progress=progress)
    assert len(packs) == 3
