"""The chart-allocation error model (lmrefine.allocation): edge error ~ 1/s,
smooth error ~ 1/s^2, the optimum for a texel budget, and what it does to
flat, smooth and edged charts."""

import numpy as np
import pytest

import lmrefine
from lmrefine import allocation
from layouts import SCALES_WITHIN_2, grid_chart, merge

RESOLUTION = 64


def three_charts():
    """Three 16 x 16-texel square charts in a row, 4 texels apart."""
    size, gap = 16 / RESOLUTION, 4 / RESOLUTION
    charts = [grid_chart(2, (gap + k * (size + gap), gap), (gap + k * (size + gap) + size, gap + size))
              for k in range(3)]
    uvs, tris = merge(*charts)
    return uvs, tris, lmrefine.find_charts(uvs, tris, tolerance=1e-5)


def light(kind):
    """(H, W, 3) lightmap: 'flat' (constant), 'smooth' (a spot light's
    quadratic fall-off along u, no edge) or 'edge' (a hard shadow edge),
    in each chart of three_charts() in turn: chart 0 flat, 1 smooth, 2 edge."""
    v, u = np.mgrid[0:RESOLUTION, 0:RESOLUTION].astype(np.float64) + 0.5
    image = np.full((RESOLUTION, RESOLUTION), 0.5)
    smooth_chart = (u >= 24) & (u < 40)
    image = np.where(smooth_chart, 0.2 + 0.6 * ((u - 24) / 16.0) ** 2, image)
    edge_chart = u >= 44
    image = np.where(edge_chart, np.where(u + 0.3 * (v - 52) > 52, 0.9, 0.1), image)
    return np.repeat(image[..., None], 3, axis=2).astype(np.float32)


def model_terms():
    uvs, tris, charts = three_charts()
    lightmap = light(None)
    mask = lmrefine.coverage_mask(uvs, tris, RESOLUTION)
    energy = lmrefine.gradient_map(lightmap, mask).sum(axis=2)
    return uvs, tris, charts, energy, lightmap, mask


def test_each_chart_gets_the_term_of_its_light():
    uvs, tris, charts, energy, lightmap, mask = model_terms()
    edge, smooth, area = allocation.chart_errors(uvs, tris, charts, energy, lightmap, mask, True)
    assert area == pytest.approx(np.full(3, (16 / RESOLUTION) ** 2))
    assert edge[0] == pytest.approx(0, abs=1e-6) and smooth[0] == pytest.approx(0, abs=1e-6)  # flat
    assert smooth[1] > 10 * edge[1]  # a smooth fall-off: mostly the 1/s^2 term
    assert edge[2] > 3 * smooth[2]  # a hard edge: mostly the 1/s term


def test_a_chart_of_smooth_light_alone_grows_and_a_flat_chart_still_shrinks():
    uvs, tris, charts, energy, lightmap, mask = model_terms()
    scales, edge, smooth, area = allocation.chart_scales(uvs, tris, charts, energy, 0.5, 2.0, lightmap, mask, True)
    assert edge[1] < 0.1 * smooth[1]
    assert scales[0] < scales[1] < scales[2]
    assert scales[0] == pytest.approx(0.5)  # the flat chart shrinks to the bound
    free = allocation._budget_scales(edge + allocation.ENERGY_FLOOR * edge.sum() / area.sum() * area, smooth, area)
    assert free[1] > 1.5 * free[0]  # the smooth chart is well above the flat chart's floor
    # Without the lightmap (the gradient map alone: blind to linear light) the
    # smooth chart keeps only its curvature and gets less.
    _, edge_only, smooth_only, _ = allocation.chart_scales(uvs, tris, charts, energy, 0.5, 2.0, None, mask, True)
    assert smooth_only[1] < 0.5 * smooth[1] and edge_only[1] == pytest.approx(edge[1])


def test_without_smooth_light_the_scales_are_the_edge_models():
    rng = np.random.default_rng(3)
    edge, area = rng.uniform(0.01, 1, 40), rng.uniform(0.1, 2, 40)
    edge[:5] = 0  # flat charts: the floor
    scales = allocation.optimal_scales(edge, np.zeros(40), area, 0.5, 2.0)
    density = edge / area + allocation.ENERGY_FLOOR * edge.sum() / area.sum()
    raw = np.cbrt(density)
    assert scales == pytest.approx(np.clip(raw / np.median(raw), 0.5, 2.0), rel=1e-6)


def predicted_total(edge, smooth, scales):
    return float((edge / scales + smooth / scales ** 2).sum())


def test_the_free_scales_minimise_the_models_error_for_the_budget():
    edge = np.array([0.5, 0.05, 0.2])
    smooth = np.array([0.0, 0.4, 0.1])
    area = np.array([1.0, 2.0, 0.5])
    scales = allocation._budget_scales(edge, smooth, area)
    budget = area.sum()
    assert (area * scales ** 2).sum() == pytest.approx(budget, rel=1e-9)
    best = predicted_total(edge, smooth, scales)
    # Brute force over the budget's surface: s0, s1 on a fine grid, s2 from the budget.
    s0, s1 = np.meshgrid(np.linspace(0.05, 1.5, 1200), np.linspace(0.05, 1.5, 1200))
    rest = budget - area[0] * s0 ** 2 - area[1] * s1 ** 2
    ok = rest > 0
    s2 = np.sqrt(np.where(ok, rest, 1.0) / area[2])
    total = np.where(ok, edge[0] / s0 + smooth[0] / s0 ** 2 + edge[1] / s1 + smooth[1] / s1 ** 2
                     + edge[2] / s2 + smooth[2] / s2 ** 2, np.inf)
    k = np.unravel_index(np.argmin(total), total.shape)
    assert best <= total[k] + 1e-9
    assert best == pytest.approx(total[k], rel=1e-4)
    assert scales == pytest.approx([s0[k], s1[k], s2[k]], abs=5e-3)


def test_the_predicted_error_counts_both_terms():
    edge, smooth = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    assert allocation.predicted_error(edge, smooth, [1.0, 1.0]) == pytest.approx(1.0)
    assert allocation.predicted_error(edge, smooth, [2.0, 2.0]) == pytest.approx((0.5 + 0.25) / 2)
    # Shrinking a chart of smooth light costs by the square.
    assert allocation.predicted_error(edge, smooth, [1.0, 0.5]) == pytest.approx((1 + 4) / 2)


def test_the_model_is_deterministic_and_leaves_its_inputs_alone():
    uvs, tris, charts, energy, lightmap, mask = model_terms()
    copies = [x.copy() for x in (uvs, tris, charts, energy, lightmap, mask)]
    first = allocation.chart_scales(uvs, tris, charts, energy, 0.5, 2.0, lightmap, mask, True)
    second = allocation.chart_scales(uvs, tris, charts, energy, 0.5, 2.0, lightmap, mask, True)
    for a, b in zip(first, second):
        assert np.array_equal(a, b)
    for before, after in zip(copies, (uvs, tris, charts, energy, lightmap, mask)):
        assert np.array_equal(before, after)


def test_opening_removes_thin_lines_and_keeps_plateaus():
    mask = np.ones((12, 12), bool)
    values = np.zeros((12, 12))
    values[:, 5:7] = 1.0  # a line two texels wide
    values[8:, :] += 0.25  # a plateau four texels high
    opened = allocation.opening(values, mask)
    assert opened[2, 5] == 0 and opened[2, 6] == 0
    assert opened[10, 2] == pytest.approx(0.25)
    assert allocation.opening(values, np.zeros((12, 12), bool)).max() == 0


def test_the_slope_reads_luminance_from_every_channel_layout():
    rng = np.random.default_rng(5)
    gray = rng.uniform(0, 1, (10, 12)).astype(np.float32)
    mask = np.ones((10, 12), bool)
    mask[:, 6] = False  # a gutter column: no difference across it
    plain = allocation.luminance_slope(gray, mask)
    assert allocation.luminance_slope(gray[..., None], mask) == pytest.approx(plain)
    rgba = np.repeat(gray[..., None], 4, axis=2)
    assert allocation.luminance_slope(rgba, mask) == pytest.approx(plain, rel=1e-5)
    assert np.all(plain[:, 6] == 0)
    # A ramp along columns: slope 0.1 per texel inside each covered run.
    ramp = np.tile(0.1 * np.arange(12, dtype=np.float32), (10, 1))
    assert allocation.luminance_slope(ramp, mask)[mask] == pytest.approx(np.full(mask.sum(), 0.1), rel=1e-5)


def test_off_by_default_the_model_is_the_edge_model_on_the_whole_energy():
    uvs, tris, charts, energy, lightmap, mask = model_terms()
    assert allocation.SMOOTH_TERM is False
    scales, edge, smooth, area = allocation.chart_scales(uvs, tris, charts, energy, 0.5, 2.0, lightmap, mask)
    assert np.all(smooth == 0)
    assert edge == pytest.approx(np.bincount(charts, allocation.triangle_energy(uvs, tris, energy)))
    density = edge / area
    raw = np.cbrt(density + allocation.ENERGY_FLOOR * np.average(density, weights=area))
    assert np.array_equal(scales, np.clip(raw / np.median(raw), 0.5, 2.0))


def test_refine_uvs_with_the_smooth_term_returns_a_valid_repacked_layout(monkeypatch):
    from layouts import lightmap_pack
    resolution = 128
    uvs, tris = lightmap_pack(charts_across=24, margin_texels=1.0, resolution=resolution, quads=1)
    v, u = np.mgrid[0:resolution, 0:resolution] / resolution
    lightmap = np.where(u + 0.3 * v > 0.6, 1.0, 0.2) * (0.3 + 0.7 * u)  # an edge on a smooth ramp
    lightmap = np.repeat(lightmap[..., None], 3, axis=2).astype(np.float32)
    monkeypatch.setattr(allocation, "SMOOTH_TERM", True)
    result = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, padding=2)
    repack = result.report["repack"]
    assert 0 < repack["smooth_fraction"] < 1
    original = lmrefine.check_layout(uvs, tris, resolution, 2)["min_gutter_texels"]
    check = lmrefine.check_layout(result.uvs, tris, resolution, original - 1e-4)
    assert check["valid"], check
    monkeypatch.setattr(allocation, "SMOOTH_TERM", False)
    off = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, padding=2).report["repack"]
    assert off["smooth_fraction"] == 0


def two_charts_at_two_densities():
    """Two square charts of the same surface (world area 1 each), chart 0
    16 texels across, chart 1 32 (four times the texel density), quads of
    one texel, each crossed by one hard shadow edge down its middle whose
    gradient energy is two texels wide: the same light on the surface,
    twice the edge texels on chart 1."""
    resolution = 64
    small = grid_chart(16, (4 / resolution, 4 / resolution), (20 / resolution, 20 / resolution))
    large = grid_chart(32, (28 / resolution, 4 / resolution), (60 / resolution, 36 / resolution))
    uvs, tris = merge(small, large)
    charts = lmrefine.find_charts(uvs, tris, tolerance=1e-5)
    energy = np.zeros((resolution, resolution))
    energy[resolution - 20:resolution - 4, 11:13] = 1.0  # chart 0's rows (v up, rows down), its middle columns
    energy[resolution - 36:resolution - 4, 43:45] = 1.0
    world = np.where(charts == 0, 1.0 / (2 * 16 ** 2), 1.0 / (2 * 32 ** 2))
    return uvs, tris, charts, energy, world


def test_texel_weights_are_the_surface_a_texel_covers_relative_to_the_mean():
    uvs, tris, charts, _, world = two_charts_at_two_densities()
    weights = allocation.texel_weights(uvs, tris, world)
    small, large = weights[charts == 0], weights[charts == 1]
    np.testing.assert_allclose(small, small[0], rtol=1e-5)
    np.testing.assert_allclose(large, large[0], rtol=1e-5)
    np.testing.assert_allclose(small[0] / large[0], 4.0, rtol=1e-5)  # a quarter of the texel area on chart 1
    # Surface areas in any unit, and a layout of uniform density: all ones.
    np.testing.assert_allclose(allocation.texel_weights(uvs, tris, 1e4 * world), weights, rtol=1e-12)
    uniform = np.abs(allocation.signed_areas(uvs, tris)) * 7.0
    np.testing.assert_allclose(allocation.texel_weights(uvs, tris, uniform), 1.0, rtol=1e-12)


def test_with_surface_areas_a_denser_chart_is_not_scaled_up_again(monkeypatch):
    # Chart 1 already has twice chart 0's linear texel density (as after a
    # first refinement): with the same light per surface, the model's
    # optimum gives both charts the same density again (scale ratio 2),
    # where counting texels alone would keep chart 1 denser (ratio 2^(1/3)).
    monkeypatch.setattr(allocation, "ENERGY_FLOOR", 0.0)  # the floor would pull both towards the mean
    uvs, tris, charts, energy, world = two_charts_at_two_densities()
    for world_areas, expected in ((world, 2.0), (None, 2.0 ** (1 / 3))):
        scales, edge, _, _ = allocation.chart_scales(uvs, tris, charts, energy, 0.1, 10.0, world_areas=world_areas)
        np.testing.assert_allclose(scales[0] / scales[1], expected, rtol=0.02)
    # The edge error in surface units: chart 1's texels are half as wide, so half the error.
    _, edge, _, _ = allocation.chart_scales(uvs, tris, charts, energy, world_areas=world)
    np.testing.assert_allclose(edge[1] / edge[0], 0.5, rtol=0.02)


def test_refine_uvs_checks_world_areas():
    uvs, tris, _, energy, world = two_charts_at_two_densities()
    gradient = np.repeat(energy[..., None] / 4, 4, axis=2).astype(np.float32)
    for bad, message in ((world[:-1], "one number per triangle"), (np.full(len(tris), np.nan), "finite"),
                         (-world, ">= 0"), (np.array(["a"] * len(tris)), "one number per triangle")):
        with pytest.raises(ValueError, match=message):
            lmrefine.refine_uvs(None, uvs, tris, 64, gradient=gradient, world_areas=bad)
    kept = world.copy()
    result = lmrefine.refine_uvs(None, uvs, tris, 64, gradient=gradient, world_areas=world)
    np.testing.assert_array_equal(world, kept)
    assert lmrefine.check_layout(result.uvs, tris, 64, 2)["valid"]


def _checkered_corner(resolution=64, across=4, gap=0.02):
    """across x across square charts of 3 x 3 quads; a fine diagonal checker over the top-left
    chart's texels (v up: the image's first rows), flat light elsewhere."""
    w = 1.0 / across
    uvs, tris = merge(*[grid_chart(3, (gap + w * a, gap + w * b), (w * (a + 1) - gap, w * (b + 1) - gap))
                        for b in range(across) for a in range(across)])
    i, j = np.mgrid[0:resolution, 0:resolution]
    light = np.full((resolution, resolution), 0.6, np.float32)
    cell = int(resolution * w)
    light[:cell, :cell] = np.where(((i + j) // 2) % 2 == 0, 1.0, 0.2)[:cell, :cell]
    return uvs, tris, np.repeat(light[..., None], 3, axis=2)


def test_a_repack_too_loose_at_the_signal_scales_is_kept_at_their_square_roots():
    """Sixteen charts, one with light changes: at the model's scales the fifteen flat charts shrink
    and their gutters leave the atlas emptier than the density rule allows; half way to uniform
    (the scales' square roots) it packs densely enough and is kept, not all of the gain dropped."""
    uvs, tris, lightmap = _checkered_corner()
    resolution, padding = 64, 2
    # No stretch, so the output is the repack's (the fill after the triangle stretch would grow the
    # checkered chart further).
    result = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, padding=padding, max_stretch=1.0,
                                 triangle_stretch=1.0, **SCALES_WITHIN_2)
    repack = result.report["repack"]
    refused = repack["softened"]["refused"]
    assert repack["used"] and repack["softened"]["used"]
    assert refused["predicted_error"] < allocation.REQUIRED_GAIN  # the model alone would take it
    assert refused["padded_utilisation_after"] < allocation.MIN_UTILISATION_KEPT * refused["padded_utilisation_before"]
    assert repack["padded_utilisation_after"] >= allocation.MIN_UTILISATION_KEPT * repack["padded_utilisation_before"]
    assert refused["predicted_error"] < repack["predicted_error"] < allocation.REQUIRED_GAIN
    # The scales used are the square roots of the model's, measured on the output: the checkered
    # chart's texels over a flat chart's, relative to the input's.
    charts = lmrefine.find_charts(uvs, tris, lmrefine.CHART_TOLERANCE)
    full, _, _, _ = allocation.chart_scales(uvs, tris, charts, lmrefine.gradient_map(lightmap).sum(axis=2),
                                            lightmap=lightmap)
    np.testing.assert_allclose(repack["signal_scales"], np.sqrt(full))
    area = lambda u: np.bincount(charts, weights=np.abs(allocation.signed_areas(u, tris)))  # noqa: E731
    linear = np.sqrt(area(result.uvs) / area(uvs))
    checkered = int(np.argmax(full))
    flat = np.delete(np.arange(len(full)), checkered)
    assert full[checkered] / np.median(full[flat]) > 1.5
    assert linear[checkered] / np.median(linear[flat]) == pytest.approx(
        np.sqrt(full[checkered] / np.median(full[flat])), rel=0.1)
    assert lmrefine.check_layout(result.uvs, tris, resolution, padding)["valid"]
    assert any(note.startswith("charts scaled by the square roots") and
               f"{refused['padded_utilisation_after']:.0%} full" in note for note in result.report["notes"])
    # Deterministic.
    assert np.array_equal(lmrefine.refine_uvs(lightmap, uvs, tris, resolution, padding=padding,
                                              max_stretch=1.0, triangle_stretch=1.0, **SCALES_WITHIN_2).uvs,
                          result.uvs)


def test_the_charts_grow_into_the_space_the_triangle_stretchs_packing_left(monkeypatch):
    """The triangle stretch packs its charts again at a scale of its own, which leaves space of its
    own: the charts the model counts most grow into it evenly (so no triangle is stretched further),
    the others keep their size, and the grown layout is the one returned."""
    uvs, tris, lightmap = _checkered_corner()
    seen = []
    grow = allocation.grow_finished_packing

    def recorded(packed, *args, **kwargs):
        grown, report = grow(packed, *args, **kwargs)
        seen.append((packed, grown))
        return grown, report

    monkeypatch.setattr(allocation, "grow_finished_packing", recorded)
    # The checkered corner's light is mostly slope, which would refuse the stretch (its 75% of the
    # texels); the fill is the subject here, so the smooth light is left out of the judgement.
    monkeypatch.setattr(allocation, "smooth_share", lambda *args: 0.0)
    result = lmrefine.refine_uvs(lightmap, uvs, tris, 64, padding=2, max_stretch=1.0, **SCALES_WITHIN_2)
    stretch_report = result.report["triangle_stretch"]
    fill = stretch_report["fill"]
    assert stretch_report["used"] and fill["used"] and fill["charts_grown"] >= 1 and not fill["charts_grown_one_way"]
    (packed, grown), = seen
    assert np.array_equal(result.uvs, grown)
    charts = lmrefine.find_charts(uvs, tris, lmrefine.CHART_TOLERANCE)
    area = lambda u: np.bincount(charts, weights=np.abs(allocation.signed_areas(u, tris)))  # noqa: E731
    growth = area(grown) / area(packed)
    assert (growth > 1 - 1e-5).all() and (growth > allocation.FILL_SMALLEST_GROWTH ** 2 - 1e-5).sum() == \
        fill["charts_grown"]
    assert fill["texel_area"] == pytest.approx(area(grown).sum() / area(packed).sum())
    assert stretch_report["largest_stretch"] <= 2.0
    check = lmrefine.check_layout(result.uvs, tris, 64, 2)
    assert check["valid"] and check["min_gutter_texels"] >= 2.0, check


def test_the_fill_after_the_triangle_stretch_takes_the_repacks_chart_errors(monkeypatch):
    """The repack's signal_scales measured the chart errors the fill after the triangle stretch needs
    (the same source layout, charts and light): refine_uvs hands them on instead of measuring again,
    and the fill grows the same with them as without."""
    uvs, tris, lightmap = _checkered_corner()
    grow, measure = allocation.grow_finished_packing, allocation.chart_errors
    calls, measured = [], []

    def recorded(*args, **kwargs):
        calls.append((args, kwargs))
        return grow(*args, **kwargs)

    def counted(*args, **kwargs):
        measured.append(args[2])
        return measure(*args, **kwargs)

    monkeypatch.setattr(allocation, "grow_finished_packing", recorded)
    monkeypatch.setattr(allocation, "chart_errors", counted)
    monkeypatch.setattr(allocation, "smooth_share", lambda *args: 0.0)  # the stretch kept, as in the test above
    result = lmrefine.refine_uvs(lightmap, uvs, tris, 64, padding=2, max_stretch=1.0, **SCALES_WITHIN_2)
    monkeypatch.setattr(allocation, "chart_errors", measure)
    assert result.report["triangle_stretch"]["fill"]["used"]
    (args, kwargs), = calls
    assert len(measured) == 1  # the repack's, none for the fill
    packed, source_uvs, triangles, charts, energy, resolution, padding, lightmap_given, mask, world_areas, _ = args
    edge, smooth, _ = measure(source_uvs, triangles, charts, energy, lightmap_given, mask, world_areas=world_areas)
    assert np.array_equal(kwargs["errors"][0], edge) and np.array_equal(kwargs["errors"][1], smooth)
    given, again = grow(*args, **kwargs), grow(*args)
    assert np.array_equal(given[0], again[0]) and given[0] is not None
    assert given[1].keys() == again[1].keys()
    assert all(np.array_equal(given[1][key], again[1][key]) for key in given[1])


def test_a_layout_the_library_packed_itself_is_repacked_on_the_models_word_alone():
    """The re-chart route's charts were packed by the library at one scale (own_packing): no caller's
    packing to hold the repack to. The checkered corner at the model's scales, which the density rule
    refuses for a caller's layout (and packs at the square roots), is then kept at those scales; and a
    repack the model predicts no gain for is still refused."""
    uvs, tris, lightmap = _checkered_corner()
    energy = lmrefine.gradient_map(lightmap).sum(axis=2)
    args = (uvs, uvs, tris, energy, (64, 64), 2.0, 0.5, 2.0)
    callers, callers_report = allocation.repack(*args, lightmap=lightmap)
    own, own_report = allocation.repack(*args, lightmap=lightmap, own_packing=True)
    assert callers_report["softened"]["used"] and not callers_report["own_packing"]
    assert own_report["used"] and own_report["own_packing"] and "softened" not in own_report
    refused = callers_report["softened"]["refused"]
    assert own_report["predicted_error"] == pytest.approx(refused["predicted_error"])
    assert own_report["predicted_error"] < callers_report["predicted_error"]
    assert own_report["padded_utilisation_after"] < (allocation.MIN_UTILISATION_KEPT
                                                     * own_report["padded_utilisation_before"])
    charts = lmrefine.find_charts(uvs, tris, lmrefine.CHART_TOLERANCE)
    area = lambda u: np.bincount(charts, weights=np.abs(allocation.signed_areas(u, tris)))  # noqa: E731
    checkered = int(np.argmax(own_report["signal_scales"]))

    def lead(packed):
        """The checkered chart's texel gain over the median flat chart's, measured on the layout."""
        gain = area(packed) / area(uvs)
        return gain[checkered] / np.median(np.delete(gain, checkered))
    assert lead(own) > lead(callers) > 1.5
    assert lmrefine.check_layout(own, tris, 64, 2)["valid"]
    # Flat light: the model predicts no gain, and the route's own packing is not repacked either.
    flat = np.full_like(lightmap, 0.6)
    none, report = allocation.repack(uvs, uvs, tris, lmrefine.gradient_map(flat).sum(axis=2), (64, 64), 2.0, 0.5,
                                     2.0, lightmap=flat, own_packing=True)
    assert none is None and not report["used"]
    assert report["predicted_error"] >= allocation.OWN_PACKING_RULE.required_gain


def test_the_stretch_candidates_of_a_layout_the_library_packed_are_judged_by_the_model_alone():
    """The chart stretch's candidates come in order, each a fallback for the ones before (stretched
    along the main directions, turned, along the charts' axes, half the factors). For a caller's
    packing the first that packs densely enough and predicts less error is kept; for the library's
    own (the re-chart route) every candidate is judged by the model alone, and the lowest prediction
    wins."""
    uvs, tris = merge(grid_chart(2, (0.05, 0.05), (0.45, 0.45)), grid_chart(2, (0.55, 0.55), (0.95, 0.95)))
    charts = lmrefine.find_charts(uvs, tris)
    shape, padding, ones = (64, 64), 2.0, np.ones(2)
    looser = ((uvs - 0.5) * 0.8 + 0.5).astype(uvs.dtype)  # the same charts, smaller: less dense
    stretched = {"weight": ones, "report": {"charts_stretched": 2, "chart_stretch": 1.5 * ones,
                                            "largest_stretch": 1.5}}
    area, perimeter = allocation.chart_outlines(uvs, tris, charts, shape)
    dense = allocation.padded_utilisation(area, perimeter, padding, shape)
    made = []

    def packings():
        """A dense candidate that gains a little (0.9), then a looser one that gains more (0.7)."""
        for kind, layout, edge in (("main", uvs, 0.9), ("axes", looser, 0.7)):
            made.append(edge)
            yield kind, np.zeros(2, bool), 1.5 * ones, edge * ones, (layout, {"chart_scales": ones})

    for rule, expected, read in ((allocation.callers_rule(), 0.9, [0.9]),
                                 (allocation.OWN_PACKING_RULE, 0.7, [0.9, 0.7])):
        made.clear()
        report, kept = allocation._judge_stretch(stretched, packings(), tris, charts, shape, padding, ones, 1.0,
                                                 dense, rule)
        assert report["used"] and kept[-1] == pytest.approx(expected) and report["predicted_error"] == kept[-1]
        assert made == read  # a caller's packing reads no candidate past the one kept
        assert kept[0] is (uvs if expected == 0.9 else looser)
        assert report["kind"] == ("main" if expected == 0.9 else "axes")
        assert [e["kind"] for e in report["candidates"]] == (["main"] if expected == 0.9 else ["main", "axes"])
    # The looser candidate fails the density rule for a caller's packing.
    assert not allocation._judge_stretch(stretched, iter(list(packings())[1:]), tris, charts, shape, padding, ones,
                                         1.0, dense, allocation.callers_rule())[0]["used"]


def test_cancelling_during_the_softened_repack_cancels_the_refinement(monkeypatch):
    """The second packing honours the caller's progress: asked to stop there, refine_uvs stops."""
    monkeypatch.setattr(allocation, "FILL_CANDIDATES", 0)  # the fill's placements would come second
    uvs, tris, lightmap = _checkered_corner()
    packs = []

    def progress(fraction, stage):
        if stage == "pack":
            packs.append(fraction)
        return len(packs) < 3  # the first packing reports twice; the third report is the softened one's

    with pytest.raises(lmrefine.CancelledError):
        lmrefine.refine_uvs(lightmap, uvs, tris, 64, padding=2, max_stretch=1.0, progress=progress)
    assert len(packs) == 3


def test_cancelling_during_the_fill_cancels_the_refinement(monkeypatch):
    """The fill's placements honour the caller's progress: a cancel there is no chart that did not fit."""
    uvs, tris, lightmap = _checkered_corner()
    tried = []
    original = allocation.pack_charts

    def pack_charts(*args, **kwargs):
        if kwargs.get("fixed_scale") is not None:
            tried.append(1)
            kwargs["progress"] = lambda fraction, stage: False
        return original(*args, **kwargs)

    monkeypatch.setattr(allocation, "pack_charts", pack_charts)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.refine_uvs(lightmap, uvs, tris, 64, padding=2, max_stretch=1.0)
    assert tried == [1]


def _random_atlas(seed):
    """Square charts with a random gap in a grid of random size, under 1-3 random patches of stripes
    along u or along the diagonal: (uvs, triangles, lightmap, resolution)."""
    rng = np.random.default_rng(seed)
    resolution = int(rng.choice([64, 96, 128]))
    across = int(rng.integers(2, 5))
    uvs, tris, _ = _checkered_corner(resolution, across, gap=float(rng.uniform(0.01, 0.05)))
    i, j = np.mgrid[0:resolution, 0:resolution]
    light = np.full((resolution, resolution), 0.6, np.float32)
    for _ in range(int(rng.integers(1, 4))):
        r0, c0 = rng.integers(0, resolution // 2, size=2)
        size = int(rng.integers(resolution // 8, resolution // 2))
        period = int(rng.integers(2, 6))
        pattern = (j // period) % 2 if rng.random() < 0.5 else ((i + j) // period) % 2
        patch = (slice(r0, r0 + size), slice(c0, c0 + size))
        light[patch] = np.where(pattern[patch] == 0, 1.0, 0.2)
    return uvs, tris, np.repeat(light[..., None], 3, axis=2), resolution


# Seeds 0-21 keep each stretch candidate at least once: along the main directions (1, 4, 5, 8, 10,
# 13, 15, 18, 19), turned (21), along the charts' axes (6, 7, 11, 14, 16, 17), at the square roots
# (12, 20); none (0, 2, 3, 9).
@pytest.mark.parametrize("seed", range(22))
def test_random_atlases_keep_the_rules_whichever_candidate_is_kept(seed):
    """Whichever packing is kept (the model's scales or their square roots; the stretch along the
    main directions, turned, along the charts' axes or at its square root), the layout is valid,
    the kept packing passes the density rule and the report names the factors and scales used."""
    uvs, tris, lightmap, resolution = _random_atlas(seed)
    padding = 2.0
    result = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, padding=padding)
    # Valid at the padding, or at the input's gutter where that is narrower (a gap of 0.01 at 96^2).
    gutter = min(padding, lmrefine.check_layout(uvs, tris, resolution, padding)["min_gutter_texels"])
    assert lmrefine.check_layout(result.uvs, tris, resolution, gutter - 1e-4)["valid"]
    repack = result.report["repack"]
    if not repack["used"]:
        return
    assert repack["padded_utilisation_after"] >= allocation.MIN_UTILISATION_KEPT * repack["padded_utilisation_before"]
    assert repack["predicted_error"] < allocation.REQUIRED_GAIN
    if repack.get("softened"):
        refused = repack["softened"]["refused"]
        assert refused["padded_utilisation_after"] < \
            allocation.MIN_UTILISATION_KEPT * refused["padded_utilisation_before"]
    stretch = repack["stretch"]
    if stretch and stretch["used"]:
        candidates = {c["kind"]: c for c in stretch["candidates"]}
        passed = [c["kind"] for c in stretch["candidates"] if c.get("dense") and c["predicted_error"] < stretch[
            "predicted_error_unstretched"]]
        kept = candidates[stretch["kind"]]
        assert stretch["kind"] == passed[0]  # the first that passes, in the candidates' order
        assert [c["kind"] for c in stretch["candidates"]][-1] == stretch["kind"]  # none made past it
        assert stretch["largest_stretch"] == kept["largest_stretch"] == pytest.approx(stretch["chart_stretch"].max())
        first = candidates["main"]["largest_stretch"]
        expected = {"main": first, "turned": first, "half": np.sqrt(first)}.get(stretch["kind"])
        assert expected is None or kept["largest_stretch"] == pytest.approx(expected)


@pytest.mark.parametrize("seed", [6, 7])
def test_charts_stretched_along_their_axes_stay_rectangles_where_a_sheared_stretch_packs_too_loosely(seed,
                                                                                                     monkeypatch):
    """Diagonal stripes shear square charts stretched across them; sheared, and turned to their
    smallest boxes, they pack too loosely for the density rule, and the stretch along each chart's u
    or v axis is kept:
    measured on the output, every stretched chart is still a rectangle, its aspect its factor
    squared (a quarter turn aside)."""
    monkeypatch.setattr(allocation, "FILL_CANDIDATES", 0)  # no growth along one axis after the stretch
    uvs, tris, lightmap, resolution = _random_atlas(seed)
    result = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, padding=2.0, triangle_stretch=1.0)
    stretch = result.report["repack"]["stretch"]
    assert stretch["used"] and stretch["kind"] == "axes"
    assert [(c["kind"], c["dense"]) for c in stretch["candidates"]] == [("main", False), ("turned", False),
                                                                          ("axes", True)]
    assert stretch["predicted_error"] < stretch["predicted_error_unstretched"]
    assert lmrefine.check_layout(result.uvs, tris, resolution, 2.0)["valid"]
    charts = lmrefine.find_charts(uvs, tris, lmrefine.CHART_TOLERANCE)
    areas = np.bincount(charts, weights=np.abs(allocation.signed_areas(result.uvs, tris)))
    stretched = np.flatnonzero(stretch["chart_stretch"] > 1.0)
    assert len(stretched) == stretch["charts_stretched"] >= 1
    for chart in stretched:
        width, height = np.ptp(result.uvs[np.unique(tris[charts == chart])].astype(np.float64), axis=0)
        assert width * height == pytest.approx(areas[chart], rel=1e-4)
        assert max(width / height, height / width) == pytest.approx(stretch["chart_stretch"][chart] ** 2, rel=1e-3)
    # A fallback for the density rule alone: the library's own packing (no density rule) never tries it.
    energy = lmrefine.gradient_map(lightmap).sum(axis=2)
    report = allocation.repack(uvs, uvs, tris, energy, (resolution,) * 2, 2.0, 0.5, 2.0, lightmap=lightmap,
                               max_stretch=2.0, own_packing=True)[1]
    assert [c["kind"] for c in report["stretch"]["candidates"]] == ["main", "turned", "half"]  # every one judged


def test_texel_floor_keeps_two_by_two_texels_and_never_shrinks_a_smaller_chart():
    texels = np.array([1600.0, 256.0, 6.25, 2.25, 0.0])
    scales = np.array([2.0, 1.0, 0.5, 0.5, 0.5])  # the model's: the flat charts at the lower bound
    for atlas in (1000.0, 4096.0):  # the charts cover more than FLOOR_PACKING of it, or less
        floored = allocation.texel_floor(scales, texels, atlas)
        covered = max(texels.sum(), allocation.FLOOR_PACKING * atlas)
        level = np.sqrt(covered / (texels * floored ** 2).sum())  # the level the floor assumes
        kept = texels * (floored * level) ** 2
        assert kept[2] == pytest.approx(allocation.MIN_CHART_TEXELS) and kept[3] == pytest.approx(2.25)
        np.testing.assert_array_equal(floored[[0, 1, 4]], scales[[0, 1, 4]])  # large enough, or of no area
    # Nothing to raise: the scales come back as they are.
    np.testing.assert_array_equal(allocation.texel_floor(scales[:2], texels[:2], 4096.0), scales[:2])


def test_a_repack_leaves_a_small_flat_chart_its_bilinear_texels():
    # A 40 x 40-texel chart with a hard shadow edge, and two flat charts of 2.2 x 2.2 texels: the model
    # halves the flat charts' scale, which would leave them under 2 x 2 texels.
    edge = grid_chart(8, (2 / 64, 2 / 64), (42 / 64, 42 / 64))
    small = [grid_chart(1, (x / 64, 50 / 64), ((x + 2.2) / 64, 52.2 / 64)) for x in (50, 56)]
    uvs, tris = merge(edge, *small)
    v, u = np.mgrid[0:64, 0:64] + 0.5
    lightmap = np.repeat(np.where(u + 0.4 * v > 30, 0.9, 0.1)[..., None], 3, axis=2).astype(np.float32)
    lightmap[45:, 45:] = 0.5
    result = lmrefine.refine_uvs(lightmap, uvs, tris, 64)
    assert result.report["repack"]["used"]
    texels = np.abs(allocation.signed_areas(result.uvs, tris)) * 64 * 64
    charts = lmrefine.find_charts(result.uvs, tris)
    per_chart = np.bincount(charts, weights=texels)
    assert per_chart[charts[-1]] >= 0.9 * allocation.MIN_CHART_TEXELS, per_chart
    assert per_chart[charts[0]] > 1700  # the edge's chart grew


def test_the_fill_grows_a_chart_into_the_space_the_packing_left_and_keeps_the_others():
    # A chart twice as wide as tall fills the atlas's width, so the packing
    # leaves the lower half nearly empty; the small chart beside it grows
    # into it, the wide chart keeps its size.
    uvs, tris = merge(grid_chart(4, (0.0, 0.0), (1.0, 0.5)), grid_chart(2, (2.0, 0.0), (2.2, 0.2)))
    charts = lmrefine.find_charts(uvs, tris, tolerance=1e-5)
    packed, report = lmrefine.pack_charts(uvs, tris, charts, None, 128, 2.0)
    edge, smooth = np.array([1.0, 1.0]), np.zeros(2)
    grown, grown_report, factors, ratio, fill = allocation.grow_into_free_space(
        packed, tris, charts, edge, smooth, report["chart_scales"], 128, 2.0)
    assert factors[0] == 1.0 and factors[1] > 1.8
    assert fill["charts_grown"] == 1 and fill["ratio"] == pytest.approx(ratio)
    assert fill["grown_chart_triangles"] == [int(np.flatnonzero(charts == 1)[0])]  # the chart named by its lowest
    assert ratio == pytest.approx(predicted_total(edge, smooth, factors) / predicted_total(edge, smooth, np.ones(2)))
    np.testing.assert_allclose(grown_report["chart_scales"], factors, rtol=1e-12)
    # Measured on the output: the wide chart's extent is the packing's, the small one's grew.
    extent = [np.ptp(grown[np.unique(tris[charts == c])], axis=0) for c in (0, 1)]
    before = [np.ptp(packed[np.unique(tris[charts == c])], axis=0) for c in (0, 1)]
    np.testing.assert_allclose(sorted(extent[0]), sorted(before[0]), rtol=1e-5)
    np.testing.assert_allclose(sorted(extent[1]), sorted(before[1] * factors[1]), rtol=1e-5)
    check = lmrefine.check_layout(grown, tris, 128, 2.0)
    assert check["valid"] and check["min_gutter_texels"] >= 2.0, check
    # A chart whose growth could not lower the model's error by FILL_MIN_GAIN is not tried.
    little = np.array([1.0, 1.8 * allocation.FILL_MIN_GAIN])
    none, _, factors, ratio, fill = allocation.grow_into_free_space(
        packed, tris, charts, little, smooth, report["chart_scales"], 128, 2.0)
    assert none is None and ratio == 1.0 and (factors == 1.0).all()
    assert fill["packings"] == 1  # the wide chart, which has no room


def test_a_chart_that_cannot_grow_evenly_grows_along_one_axis_into_the_space_left():
    # A chart twice as wide as tall fills the atlas's width: it cannot grow evenly, but the packing
    # leaves the lower half empty, so it grows along v (its light changes half across each axis).
    uvs, tris = grid_chart(4, (0.0, 0.0), (1.0, 0.5))
    charts = lmrefine.find_charts(uvs, tris, tolerance=1e-5)
    packed, report = lmrefine.pack_charts(uvs, tris, charts, None, 128, 2.0)
    edge, smooth = np.array([1.0]), np.array([0.5])
    asked = []

    def shares():
        asked.append(True)
        return np.array([0.5])

    grown, _, factors, ratio, fill = allocation.grow_into_free_space(
        packed, tris, charts, edge, smooth, report["chart_scales"], 128, 2.0, shares=shares)
    assert asked == [True] and fill["charts_grown"] == fill["charts_grown_one_way"] == 1
    before, after = np.ptp(packed.astype(np.float64), axis=0), np.ptp(grown.astype(np.float64), axis=0)
    wide = int(np.argmax(before))  # the packer may turn the chart: the grown axis is the short one
    g = after[1 - wide] / before[1 - wide]
    assert after[wide] == pytest.approx(before[wide], rel=1e-5) and 1.5 < g <= allocation.FILL_MAX_GROWTH
    assert factors[0] == pytest.approx(np.sqrt(g), rel=1e-4)  # its linear scale of area
    s = report["chart_scales"][0]
    model = edge / s * (0.5 + 0.5 / g) + smooth / s ** 2 / g  # the even share, then the grown one
    assert ratio == pytest.approx(float(model[0] / (edge / s + smooth / s ** 2)[0]), rel=1e-4)
    check = lmrefine.check_layout(grown, tris, 128, 2.0)
    assert check["valid"] and check["min_gutter_texels"] >= 2.0, check
    # Without the light changes' shares the fill grows evenly only: nothing here.
    none, _, _, _, fill = allocation.grow_into_free_space(
        packed, tris, charts, edge, smooth, report["chart_scales"], 128, 2.0)
    assert none is None and fill["packings"] == 1
    # Held to the chart stretch's bound: at most 1.3 one way, and not at all where no stretch is allowed.
    held, _, factors, _, fill = allocation.grow_into_free_space(
        packed, tris, charts, edge, smooth, report["chart_scales"], 128, 2.0, shares=shares,
        one_way_limit=np.array([1.3]))
    g = np.ptp(held.astype(np.float64), axis=0)[1 - wide] / before[1 - wide]
    assert 1.2 < g <= 1.3 + 1e-6 and fill["charts_grown_one_way"] == 1
    none, _, _, _, fill = allocation.grow_into_free_space(
        packed, tris, charts, edge, smooth, report["chart_scales"], 128, 2.0, shares=shares,
        one_way_limit=np.array([1.0]))
    assert none is None and fill["packings"] == 1


def test_refine_uvs_grows_a_chart_along_one_axis_only_where_a_stretch_is_allowed():
    # A wide chart across the atlas and a small one, both under vertical stripes: with the chart stretch
    # allowed (max_stretch 2) a chart grows along one axis into the space the packing left; with no
    # stretch allowed (max_stretch 1) every chart keeps its shape (measured on the output: its box's
    # aspect, up to a quarter turn).
    n = 64
    uvs, tris = merge(grid_chart(6, (0.02, 0.02), (0.98, 0.45)), grid_chart(3, (0.1, 0.6), (0.3, 0.8)))
    j = np.mgrid[0:n, 0:n][1]
    lightmap = np.repeat(np.where((j // 3) % 2 == 0, 1.0, 0.2).astype(np.float32)[..., None], 3, axis=2)
    charts = lmrefine.find_charts(uvs, tris, lmrefine.CHART_TOLERANCE)

    def aspects(layout):
        boxes = [np.ptp(layout[np.unique(tris[charts == c])].astype(np.float64), axis=0) for c in range(2)]
        return np.array([box.max() / box.min() for box in boxes])

    for max_stretch in (2.0, 1.0):
        result = lmrefine.refine_uvs(lightmap, uvs, tris, n, padding=2, max_stretch=max_stretch, triangle_stretch=1.0)
        fill = result.report["repack"]["fill"]
        assert result.report["repack"]["used"] and fill["charts_grown"] >= 1, fill
        assert lmrefine.check_layout(result.uvs, tris, n, padding=2)["valid"]
        if max_stretch == 1.0:
            assert fill["charts_grown_one_way"] == 0
            np.testing.assert_allclose(aspects(result.uvs), aspects(uvs), rtol=0.02)
        else:
            assert fill["charts_grown_one_way"] >= 1
            assert (np.abs(aspects(result.uvs) / aspects(uvs) - 1) > 0.05).any()


@pytest.mark.parametrize("share_u, axis", [(0.9, 0), (0.1, 1), (0.5, 1)])
def test_a_chart_grows_along_the_axis_the_model_credits_more(share_u, axis):
    # Either axis fits (up to 1.6 along u, 1.8 along v): the growth that takes off more predicted error
    # wins, the one across the light changes; with no preference the longer growth.
    uvs, tris = grid_chart(2, (0.25, 0.25), (0.5, 0.5))
    charts = np.zeros(len(tris), np.int64)
    extent = np.ptp(uvs, axis=0)
    limits = (1.6, 1.8)

    def fits(factors, layout):
        grown = np.ptp(layout.astype(np.float64), axis=0) / extent
        return ("packed", layout) if (grown <= np.array(limits) + 1e-9).all() else None

    axis_kept, g, packing, layout = allocation._grow_one_axis(
        0, uvs, np.ones(1), np.array([share_u]), np.array([1.0]), np.array([0.0]), np.ones(1), np.array([0.0625]),
        1.0, fits, tris, charts, 0.0, 0.0)
    assert axis_kept == axis and packing[1] is layout
    assert 1.4 < g <= limits[axis]
    assert np.ptp(layout[:, 1 - axis]) == pytest.approx(extent[1 - axis])
    assert np.ptp(layout[:, axis]) == pytest.approx(extent[axis] * g)


def test_the_fill_leaves_a_packing_with_no_free_space_as_it_is():
    # Four equal squares fill the atlas: none can grow by FILL_SMALLEST_GROWTH (one try each).
    size = 0.5
    uvs, tris = merge(*(grid_chart(1, (k * 2.0, 0.0), (k * 2.0 + size, size)) for k in range(4)))
    charts = lmrefine.find_charts(uvs, tris, tolerance=1e-5)
    packed, report = lmrefine.pack_charts(uvs, tris, charts, None, 64, 2.0)
    uvs_out, _, factors, ratio, fill = allocation.grow_into_free_space(
        packed, tris, charts, np.ones(4), np.zeros(4), report["chart_scales"], 64, 2.0)
    assert uvs_out is None and ratio == 1.0 and (factors == 1.0).all()
    assert fill["charts_grown"] == 0 and fill["packings"] == allocation.FILL_CANDIDATES


def test_the_fill_tries_no_placement_where_the_free_area_cannot_hold_a_gain():
    # One square chart fills nearly the whole atlas: the area left cannot hold its growth by
    # FILL_SMALLEST_GROWTH, so no placement is tried.
    uvs, tris = grid_chart(2, (0.0, 0.0), (1.0, 1.0))
    charts = lmrefine.find_charts(uvs, tris, tolerance=1e-5)
    packed, report = lmrefine.pack_charts(uvs, tris, charts, None, 64, 1.0)
    none, _, _, _, fill = allocation.grow_into_free_space(
        packed, tris, charts, np.ones(1), np.zeros(1), report["chart_scales"], 64, 1.0)
    assert none is None and fill["packings"] == 0
