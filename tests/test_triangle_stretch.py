"""The triangle stretch (lmrefine.stretch.triangle_stretch, refine_uvs
triangle_stretch=): the shape fit against a plain reference, its guards, and
the stretch across a stripe of shadow."""

import numpy as np
import pytest

import lmrefine
from lmrefine import _native, allocation, stretch
from layouts import floor_grid, grid_chart, lightmap_pack, plane


def fit_shapes_reference(uvs, triangles, targets, anchor=1e-6):
    """The shape fit's rule, dense: every edge (i, j) of triangle t wants
    u_j - u_i = D_t (r_j - r_i), weighted by area_t / |r_j - r_i|^2; each
    vertex is pulled to its place by anchor x its summed edge weights (1
    without edges); the normal equations solved directly."""
    n = len(uvs)
    system = np.zeros((n, n))
    rhs = np.zeros((n, 2))
    for t, tri in enumerate(triangles):
        a, b, c = uvs[tri]
        area = 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        if area == 0:
            continue
        for k in range(3):
            i, j = tri[k], tri[(k + 1) % 3]
            edge = uvs[j] - uvs[i]
            w = area / (edge @ edge)
            target = targets[t] @ edge
            system[i, i] += w
            system[j, j] += w
            system[i, j] -= w
            system[j, i] -= w
            rhs[i] -= w * target
            rhs[j] += w * target
    diagonal = np.diag(system).copy()
    for i in range(n):
        pull = anchor * diagonal[i] if diagonal[i] > 0 else 1.0
        system[i, i] += pull
        rhs[i] += pull * uvs[i]
    return np.linalg.solve(system, rhs)


def shared_grid(n):
    """An n x n grid of quads over [0, 1]^2 whose triangles share vertices."""
    positions, triangles = floor_grid(n, 0.5)
    return positions[:, :2].astype(np.float64) + 0.5, triangles


def test_fit_shapes_matches_the_reference():
    rng = np.random.default_rng(3)
    uvs, tris = shared_grid(5)
    uvs = uvs + rng.normal(0, 0.02, uvs.shape)
    targets = rng.normal(0, 0.3, (len(tris), 2, 2)) + np.eye(2)
    expected = fit_shapes_reference(uvs, tris, targets)
    np.testing.assert_allclose(_native._fit_shapes(uvs, tris, targets), expected, rtol=0, atol=1e-9)


def test_fit_shapes_identity_keeps_the_layout_and_a_stretch_is_met():
    uvs, tris = shared_grid(4)
    same = _native._fit_shapes(uvs, tris, np.tile(np.eye(2), (len(tris), 1, 1)))
    np.testing.assert_allclose(same, uvs, atol=1e-10)
    # One consistent target for all triangles is met exactly, about the centre.
    fitted = _native._fit_shapes(uvs, tris, np.tile(np.diag([2.0, 0.5]), (len(tris), 1, 1)))
    np.testing.assert_allclose(np.ptp(fitted, axis=0), [2.0, 0.5], rtol=1e-5)
    np.testing.assert_allclose(fitted.mean(axis=0), uvs.mean(axis=0), atol=1e-5)


def test_fit_shapes_rejects_bad_input():
    uvs, tris = shared_grid(2)
    targets = np.tile(np.eye(2), (len(tris), 1, 1))
    with pytest.raises(ValueError, match="outside"):
        _native._fit_shapes(uvs, tris + 100, targets)
    bad = uvs.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        _native._fit_shapes(bad, tris, targets)
    with pytest.raises(ValueError, match="one per triangle"):
        _native._fit_shapes(uvs, tris, targets[:-1])
    nan_targets = targets.copy()
    nan_targets[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="targets"):
        _native._fit_shapes(uvs, tris, nan_targets)
    # A vertex no triangle uses stays where it is; degenerate triangles add nothing.
    extra = np.vstack([uvs, [[0.3, 0.7]]])
    degenerate = np.vstack([tris, [[0, 0, 1]]])
    out = _native._fit_shapes(extra, degenerate, np.tile(np.eye(2), (len(degenerate), 1, 1)))
    np.testing.assert_allclose(out, extra, atol=1e-10)


def stripe_lightmap(resolution, centre=0.5, width=0.03):
    """A vertical stripe of shadow (a picket's) across a lit plane."""
    x = (np.arange(resolution) + 0.5) / resolution
    lit = np.where(np.abs(x - centre) < width / 2, 0.1, 1.0).astype(np.float32)
    return np.ascontiguousarray(np.broadcast_to(lit, (resolution, resolution)))


def test_a_stripe_gets_wider_across_and_narrower_along():
    resolution = 128
    uvs, tris = plane(32, margin=0.05)
    lightmap = stripe_lightmap(resolution)
    mask = lmrefine.coverage_mask(uvs, tris, resolution)
    charts = np.zeros(len(tris), np.int64)
    out, kept, report, _ = stretch.triangle_stretch(lightmap, mask, uvs, uvs, tris, charts,
                                                     (resolution, resolution), 2.0)
    assert kept.tolist() == [1.0]
    assert report["triangles_stretched"] > 0 and report["charts_kept_shape"] == 0
    corners = uvs[tris]
    near = np.abs(corners[:, :, 0].mean(axis=1) - 0.5) < 0.02
    width_before = np.ptp(corners[:, :, 0], axis=1)
    height_before = np.ptp(corners[:, :, 1], axis=1)
    after = out[tris]
    across = np.ptp(after[:, :, 0], axis=1) / width_before
    along = np.ptp(after[:, :, 1], axis=1) / height_before
    # Across the stripe (u) the triangles widen, along it (v) they shorten, their area about kept.
    assert np.median(across[near]) > 1.3
    assert np.median(along[near]) < 0.9
    far = np.abs(corners[:, :, 0].mean(axis=1) - 0.5) > 0.3
    assert abs(np.median(across[far]) - 1.0) < 0.15
    areas_before, areas_after = allocation.signed_areas(uvs, tris), allocation.signed_areas(out, tris)
    assert (np.sign(areas_after) == np.sign(areas_before)).all()


def test_refine_uvs_triangle_stretch_report_and_validity():
    resolution = 128
    uvs, tris = plane(32, margin=0.05)
    lightmap = stripe_lightmap(resolution)
    result = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, triangle_stretch=2.0)
    report = result.report["triangle_stretch"]
    assert report["max_stretch"] == 2.0 and report["triangles_stretched"] > 0
    check = lmrefine.check_layout(result.uvs, tris, resolution, 2.0)
    assert check["valid"], check
    assert all(np.array_equal(result.report["check"][k], check[k]) for k in check)
    if report["used"]:
        assert report["predicted_edge_error"] < 1.0 and report["predicted_error"] < 1.0
    else:
        assert report["reason"]
    assert report["used"], "the stripe is the stretch's own case"
    # The figures are the output's: each triangle's map from the layout before the stretch (the plain
    # repack's, triangle_stretch=1) to the result, measured one by one.
    before = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, triangle_stretch=1).uvs
    measured = []
    for tri in tris:
        a, b = before[tri].astype(np.float64), result.uvs[tri].astype(np.float64)
        m = np.column_stack([b[1] - b[0], b[2] - b[0]]) @ np.linalg.inv(np.column_stack([a[1] - a[0], a[2] - a[0]]))
        s = np.linalg.svd(m, compute_uv=False)
        measured.append(np.sqrt(s[0] / s[1]))
    measured = np.array(measured)
    assert report["triangles_stretched"] == int((measured > stretch.MEASURED_STRETCH).sum()) > 0
    assert report["largest_stretch"] == pytest.approx(measured.max(), rel=1e-6)
    assert report["largest_stretch"] <= 2.0
    # The default is 2; 1 turns it off, and so does refining inside the charts only (no packing).
    assert lmrefine.refine_uvs(lightmap, uvs, tris, resolution).report["triangle_stretch"]["max_stretch"] == 2.0
    assert lmrefine.refine_uvs(lightmap, uvs, tris, resolution, triangle_stretch=1).report["triangle_stretch"] is None
    assert lmrefine.refine_uvs(lightmap, uvs, tris, resolution, repack=False).report["triangle_stretch"] is None
    for bad in (0.5, 17.0, float("nan"), float("inf"), True, "2"):
        with pytest.raises(ValueError, match="triangle_stretch"):
            lmrefine.refine_uvs(lightmap, uvs, tris, resolution, triangle_stretch=bad)


def test_triangle_stretch_on_random_light_never_flips():
    rng = np.random.default_rng(7)
    resolution = 64
    for seed in range(4):
        uvs, tris = grid_chart(12, (0.1, 0.1), (0.9, 0.9))
        lightmap = rng.random((resolution, resolution)).astype(np.float32)
        lightmap[:, : resolution // 2] *= 0.1
        mask = lmrefine.coverage_mask(uvs, tris, resolution)
        charts = np.zeros(len(tris), np.int64)
        out, kept, _, _ = stretch.triangle_stretch(lightmap, mask, uvs, uvs, tris, charts,
                                                   (resolution, resolution), 1.0 + seed)
        assert kept[0] in (1.0, 0.5, 0.25, 0.0)
        before, after = allocation.signed_areas(uvs, tris), allocation.signed_areas(out, tris)
        assert (np.sign(after) == np.sign(before)).all()
        assert np.isfinite(out).all()


def test_triangle_edge_error_of_simple_maps():
    uvs, tris = shared_grid(3)
    count = len(tris)
    across = np.tile([1.0, 0.0], (count, 1))
    model = {"direction": across, "share": np.full(count, 1.0), "weight": np.ones(count)}
    # The same layout: 1. Scaled by g everywhere: 1 / g. Stretched by a across e1, all the light across: 1 / a.
    assert stretch.triangle_edge_error(model, uvs, uvs, tris) == pytest.approx(1.0)
    assert stretch.triangle_edge_error(model, uvs, 0.5 * uvs, tris) == pytest.approx(2.0)
    stretched = uvs * np.array([2.0, 0.5])
    assert stretch.triangle_edge_error(model, uvs, stretched, tris) == pytest.approx(0.5)
    # Light changes split evenly: the model's f(a) = (1 / a + a) / 2 for a stretch a that keeps the area.
    even = {**model, "share": np.full(count, 0.5)}
    assert stretch.triangle_edge_error(even, uvs, stretched, tris) == pytest.approx((0.5 + 2.0) / 2)
    # Without light changes nothing counts: 1.
    assert stretch.triangle_edge_error({**model, "weight": np.zeros(count)}, uvs, stretched, tris) == 1.0


def test_widening_across_the_light_changes_is_measured_on_the_output():
    """report["transition_widening_across"]: the texels across the light changes at the triangles there,
    new over old; a stretch that keeps the area raises it, not the area widening."""
    from lmrefine import refine

    resolution = 128
    uvs, tris = plane(32, margin=0.05)
    lightmap = stripe_lightmap(resolution)
    centre = np.array([0.5, 0.5], np.float32)
    stretched = (uvs - centre) * np.array([1.6, 1 / 1.6], np.float32) * 0.6 + centre  # across the stripe (u)
    figures = refine.layout_figures(lightmap, uvs, stretched, tris)
    assert figures["transition_widening"] == pytest.approx(0.36, rel=1e-3)
    assert figures["transition_widening_across"] == pytest.approx(1.6 * 0.6, rel=1e-3)
    turned = (uvs - centre) * np.array([1 / 1.6, 1.6], np.float32) * 0.6 + centre  # along it
    assert refine.layout_figures(lightmap, uvs, turned, tris)["transition_widening_across"] == \
        pytest.approx(0.6 / 1.6, rel=1e-3)
    on = lmrefine.refine_uvs(lightmap, uvs, tris, resolution).report
    off = lmrefine.refine_uvs(lightmap, uvs, tris, resolution, triangle_stretch=1.0).report
    assert on["triangle_stretch"]["used"]
    assert on["transition_widening_across"] > off["transition_widening_across"]
    assert on["transition_widening"] < off["transition_widening"]  # the stretch trades area for shape
    assert lmrefine.refine_uvs(None, uvs, tris, resolution, gradient=np.ones((resolution, resolution, 4),
                               np.float32)).report["transition_widening_across"] is None


def test_chart_gains_sum_the_edge_term_per_chart():
    uvs, tris = grid_chart(1, (0.0, 0.0), (1.0, 1.0))
    uvs = np.vstack([uvs, uvs + 2.0]).astype(np.float64)
    tris = np.vstack([tris, tris + len(tris) * 3])
    charts = np.array([0, 0, 1, 1])
    # Every triangle's light changes all across u (share 1), weight 1.
    model = {"direction": np.tile([1.0, 0.0], (4, 1)), "share": np.ones(4), "weight": np.ones(4)}
    after = uvs.copy()
    after[:6, 0] *= 2.0   # chart 0 twice as wide across: its term halves
    after[6:, 0] = 2.0 + (after[6:, 0] - 2.0) * 0.5  # chart 1 half as wide: its term doubles
    np.testing.assert_allclose(stretch.chart_gains(model, uvs, after, tris, charts), [2 * 0.5, 2 * -1.0])
    weights, terms = stretch.triangle_edge_terms(model, uvs, after, tris)
    assert terms.sum() / weights.sum() == pytest.approx(stretch.triangle_edge_error(model, uvs, after, tris))


def test_best_served_subsets_take_the_largest_gains_first():
    from lmrefine.refine import _best_served
    gains = np.array([3.0, -1.0, 1.0, 0.5, 0.0])
    subsets = [np.flatnonzero(s).tolist() for s in _best_served(gains, np.ones(5, bool))]
    # 100% of the gain: three charts; 75%: two; 50% and 25%: the first alone (listed once).
    assert subsets == [[0, 2, 3], [0, 2], [0]]
    assert [np.flatnonzero(s).tolist() for s in _best_served(gains, np.array([0, 1, 1, 1, 1], bool))] == \
        [[2, 3], [2]]
    assert _best_served(np.array([-1.0, 0.0]), np.ones(2, bool)) == []


def striped_patches(resolution, seed):
    """Patches of stripes at random angles and periods on a lit map."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:resolution, 0:resolution] + 0.5
    lightmap = np.ones((resolution, resolution), np.float32)
    for _ in range(6):
        angle, period = rng.uniform(0, np.pi), rng.uniform(4, 12)
        cx, cy, radius = rng.uniform(0, resolution, 2).tolist() + [rng.uniform(15, 50)]
        inside = (x - cx) ** 2 + (y - cy) ** 2 < radius * radius
        stripe = np.sin((x * np.cos(angle) + y * np.sin(angle)) * 2 * np.pi / period) > 0.6
        lightmap[inside & stripe] = 0.1
    return lightmap


def test_the_best_served_charts_keep_their_stretch_when_all_are_refused():
    resolution = 128
    uvs, tris = lightmap_pack(6, 2, resolution, 4)
    # The chart stretch off: the triangle stretch alone decides which charts keep their stretch.
    result = lmrefine.refine_uvs(striped_patches(resolution, 3), uvs, tris, resolution, max_stretch=1.0)
    report = result.report["triangle_stretch"]
    # Every chart stretched packs too loosely for the model; a few of them do not.
    assert report["every_chart_edge_error"] >= 1.0
    assert report["used"] and report["predicted_edge_error"] < 1.0
    check = lmrefine.check_layout(result.uvs, tris, resolution, 2.0)
    assert check["valid"]
    # The report's check is check_layout's of the layout returned.
    assert result.report["check"].keys() == check.keys()
    assert all(np.array_equal(result.report["check"][k], check[k]) for k in check)
    # The charts left out keep their shape: each triangle's map from the
    # layout before the stretch is one rotation and scale for all of them.
    maps, good = stretch.triangle_maps(result.unstretched_uvs, result.uvs, tris)
    charts = _native.LayoutChecker(result.unstretched_uvs, tris, resolution, 2.0).charts[good]
    singular = np.linalg.svd(maps, compute_uv=False)
    anisotropy = np.zeros(charts.max() + 1)
    np.maximum.at(anisotropy, charts, singular[:, 0] / singular[:, 1])
    stretched = int((anisotropy > 1.01).sum())
    assert 0 < stretched <= report["charts_stretched"] < len(anisotropy)
    kept_shape = anisotropy <= 1.01
    scales = singular[kept_shape[charts], 0]
    assert np.ptp(scales) < 1e-3 * scales.mean()


def test_source_tensors_read_once_map_as_read_each_time():
    resolution = 64
    uvs, tris = lightmap_pack(3, 2, resolution, 2)
    lightmap = striped_patches(resolution, 1)
    mask = lmrefine.coverage_mask(uvs, tris, resolution)
    moved = uvs * np.float32(0.8) + np.float32(0.05)
    source = stretch.source_tensors(lightmap, mask, uvs, tris)
    np.testing.assert_array_equal(stretch.triangle_tensors(lightmap, mask, uvs, moved, tris, source),
                                  stretch.triangle_tensors(lightmap, mask, uvs, moved, tris))
    # In the source's own frame the mapping is the identity.
    np.testing.assert_allclose(stretch.triangle_tensors(lightmap, mask, uvs, uvs, tris), source, rtol=1e-12,
                               atol=1e-15)
    # A layout scaled by 0.8 sees gradients 1 / 0.8 as steep: tensors / 0.64.
    np.testing.assert_allclose(stretch.triangle_tensors(lightmap, mask, uvs, moved, tris, source), source / 0.64,
                               rtol=1e-5, atol=1e-6 * np.abs(source).max())


def test_a_flip_costs_the_stretch_around_it_not_the_whole_chart(monkeypatch):
    """A fit that flips one triangle under the stretch (a stand-in for the
    squeezed triangles of a refined layout, which the real fit can flip)
    halves the stretch of the triangles near it; the rest of the chart keeps
    all of it. With no local back-off the whole chart steps down to half."""
    resolution = 128
    uvs, tris = plane(32, margin=0.05)
    lightmap = stripe_lightmap(resolution)
    mask = lmrefine.coverage_mask(uvs, tris, resolution)
    charts = np.zeros(len(tris), np.int64)
    shape = (resolution, resolution)
    free, _, _, _ = stretch.triangle_stretch(lightmap, mask, uvs, uvs, tris, charts, shape, 2.0)
    centres = uvs[tris].mean(axis=1)
    victim = int(np.argmin(np.abs(centres[:, 0] - 0.49) + np.abs(centres[:, 1] - 0.5)))
    fit = _native._fit_shapes
    first = {}

    def flipping_fit(start, vertex_triangles, targets):
        fitted = fit(start, vertex_triangles, targets)
        deviation = np.abs(targets[victim] - np.eye(2)).max()
        first.setdefault("deviation", deviation)
        if deviation >= 0.4 * first["deviation"]:  # the victim flips until its stretch is a quarter
            a, b, c = fitted[vertex_triangles[victim]]
            edge = (b - a) / np.linalg.norm(b - a)
            foot = a + edge * np.dot(c - a, edge)
            fitted[vertex_triangles[victim][2]] = 2 * foot - c
        return fitted

    monkeypatch.setattr(stretch._native, "_fit_shapes", flipping_fit)
    assert first == {} and np.abs(free - uvs).max() > 0
    out, kept, report, model = stretch.triangle_stretch(lightmap, mask, uvs, uvs, tris, charts, shape, 2.0)
    assert kept.tolist() == [1.0] and report["charts_backed_off"] == 0
    backed = model["local"] < 1
    assert backed[victim] and 0 < report["triangles_backed_off"] == backed.sum() < 0.05 * len(tris)
    assert (np.sign(allocation.signed_areas(out, tris)) == np.sign(allocation.signed_areas(uvs, tris))).all()
    # Far from the victim the triangles keep the free fit's shapes (the fit is global: they move a little).
    far = np.linalg.norm(centres - centres[victim], axis=1) > 0.3
    for axis in (0, 1):
        np.testing.assert_allclose(np.ptp(out[tris[far]][:, :, axis], axis=1),
                                   np.ptp(free[tris[far]][:, :, axis], axis=1), rtol=0.05)

    monkeypatch.setattr(stretch, "LOCAL_BACKOFF_ROUNDS", 0)
    first.clear()
    _, whole, whole_report, _ = stretch.triangle_stretch(lightmap, mask, uvs, uvs, tris, charts, shape, 2.0)
    assert whole.tolist() == [0.25] and whole_report["triangles_backed_off"] == 0


def test_smooth_share_is_the_smooth_terms_part_of_the_model():
    resolution = 128
    uvs, tris = plane(32, margin=0.05)
    mask = lmrefine.coverage_mask(uvs, tris, resolution)
    charts = np.zeros(len(tris), np.int32)
    x = (np.arange(resolution) + 0.5) / resolution
    ramp = np.ascontiguousarray(np.broadcast_to((0.2 + 0.8 * x).astype(np.float32), (resolution, resolution)))
    shares = {}
    for name, lightmap in (("ramp", ramp), ("stripe", stripe_lightmap(resolution))):
        energy = lmrefine.gradient_map(lightmap, mask).sum(axis=2)
        shares[name] = allocation.smooth_share(uvs, tris, charts, energy, lightmap, mask)
        edge, smooth, _ = allocation.chart_errors(uvs, tris, charts, energy, lightmap, mask, smooth_term=True)
        assert shares[name] == pytest.approx(smooth.sum() / (edge.sum() + smooth.sum()))
    # Linear light is all slope (the gradient map does not see it); a one-texel-wide stripe is all edge.
    assert shares["ramp"] > 0.99 and shares["stripe"] == 0.0
    energy = lmrefine.gradient_map(ramp, mask).sum(axis=2)
    assert allocation.smooth_share(uvs, tris, charts, energy, None, mask) == 0.0  # no lightmap: no slope term


def test_triangle_stretch_error_prices_lost_texels_in_smooth_light():
    from lmrefine.refine import triangle_stretch_error

    assert triangle_stretch_error(0.9, 0.8, 0.0) == pytest.approx(0.9)
    assert triangle_stretch_error(0.9, 0.8, 1.0) == pytest.approx(1.25)
    assert triangle_stretch_error(0.9, 0.8, 0.5) == pytest.approx(0.5 * 0.9 + 0.5 / 0.8)
    assert triangle_stretch_error(1.0, 1.0, 0.3) == pytest.approx(1.0)


@pytest.mark.parametrize("share", [0.0, 0.5])
def test_a_stretch_losing_texels_is_refused_where_smooth_light_weighs(monkeypatch, share):
    resolution = 128
    uvs, tris = plane(32, margin=0.05)
    monkeypatch.setattr(allocation, "smooth_share", lambda *args: share)
    report = lmrefine.refine_uvs(stripe_lightmap(resolution), uvs, tris, resolution).report["triangle_stretch"]
    # The stripe's stretch gains across it and packs into less of the atlas (the case above).
    assert report["predicted_edge_error"] < 1.0 and report["texel_area"] < 0.9
    assert report["smooth_share"] == share
    expected = (1 - share) * report["predicted_edge_error"] + share / report["texel_area"]
    assert report["predicted_error"] == pytest.approx(expected)
    assert report["used"] == (expected < 1.0)
    if share:
        assert not report["used"] and "smooth light (50% of the error)" in report["reason"]
