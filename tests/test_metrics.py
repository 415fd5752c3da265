"""Metrics on constructed cases with known answers (no baker, no Blender)."""

import numpy as np
import pytest

from lmrefine import metrics


def plane(n=8, size=2.0):
    """An n x n grid of quads (2 triangles each) in z = 0, per-corner UVs
    mapping it onto [0.1, 0.9]^2 (one chart)."""
    xs = np.linspace(0, size, n + 1)
    positions = np.array([(x, y, 0.0) for y in xs for x in xs], np.float32)
    triangles = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i
            triangles += [(a, b, c), (a, c, d)]
    triangles = np.array(triangles, np.int32)
    corners = positions[triangles.reshape(-1)]
    uvs = (0.1 + 0.8 * corners[:, :2] / size).astype(np.float32)
    return positions, triangles, uvs


def test_surface_samples_are_uniform_by_area_and_reproducible():
    positions = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 5), (3, 0, 5), (0, 3, 5)], np.float32)
    triangles = np.array([(0, 1, 2), (3, 4, 5)], np.int32)  # areas 0.5 and 4.5
    samples = metrics.sample_surface(positions, triangles, 20000, seed=3)
    assert abs(np.mean(samples.triangle == 1) - 0.9) < 0.01
    np.testing.assert_allclose(samples.bary.sum(axis=1), 1.0)
    assert (samples.bary >= 0).all()
    np.testing.assert_allclose(samples.normals[:, 2], 1.0, atol=1e-6)
    # Uniform inside a triangle: the mean is the centroid.
    first = samples.points[samples.triangle == 0]
    np.testing.assert_allclose(first.mean(axis=0), [1 / 3, 1 / 3, 0], atol=0.01)
    again = metrics.sample_surface(positions, triangles, 20000, seed=3)
    np.testing.assert_array_equal(samples.points, again.points)
    with pytest.raises(ValueError, match="no area"):
        metrics.sample_surface(np.zeros((3, 3), np.float32), np.array([(0, 1, 2)]), 10)


def test_bilinear_lookup_follows_the_texel_space_convention():
    image = np.zeros((4, 8, 1), np.float32)
    image[0, 0] = 1.0                      # top-left texel: centre (1/16, 7/8)
    assert metrics.bilinear_lookup(image, np.array([[1 / 16, 7 / 8]]))[0, 0] == pytest.approx(1.0)
    assert metrics.bilinear_lookup(image, np.array([[1 / 16, 1 / 8]]))[0, 0] == pytest.approx(0.0)
    # Halfway between texel centres (0, 0) and (0, 1): 0.5.
    assert metrics.bilinear_lookup(image, np.array([[2 / 16, 7 / 8]]))[0, 0] == pytest.approx(0.5)
    # A linear ramp along u is reproduced exactly between the first and last texel centres.
    ramp = np.tile(np.arange(8, dtype=np.float32), (4, 1))
    u = np.linspace(1 / 16, 15 / 16, 11)
    values = metrics.bilinear_lookup(ramp, np.stack([u, np.full_like(u, 0.5)], axis=1))[:, 0]
    np.testing.assert_allclose(values, u * 8 - 0.5, atol=1e-6)
    # Clamped beyond the border.
    assert metrics.bilinear_lookup(ramp, np.array([[0.0, 0.5], [1.0, 0.5]]))[:, 0] == pytest.approx([0, 7])


def bilinear_reference(image, uv):
    """metrics.bilinear_lookup in plain numpy (what it was before the native
    kernel): texel coordinates clamped to the border, the 2 x 2 texels
    around, weights in float64."""
    image = np.asarray(image)
    if image.ndim == 2:
        image = image[..., None]
    uv = np.asarray(uv, np.float64)
    height, width = image.shape[:2]
    x = np.clip(uv[:, 0] * width - 0.5, 0.0, width - 1.0)
    y = np.clip((1.0 - uv[:, 1]) * height - 0.5, 0.0, height - 1.0)
    j0 = np.minimum(np.floor(x).astype(np.int64), width - 2) if width > 1 else np.zeros(len(x), np.int64)
    i0 = np.minimum(np.floor(y).astype(np.int64), height - 2) if height > 1 else np.zeros(len(y), np.int64)
    fx = (x - j0)[:, None] if width > 1 else np.zeros((len(x), 1))
    fy = (y - i0)[:, None] if height > 1 else np.zeros((len(y), 1))
    j1, i1 = np.minimum(j0 + 1, width - 1), np.minimum(i0 + 1, height - 1)
    top = image[i0, j0] * (1 - fx) + image[i0, j1] * fx
    bottom = image[i1, j0] * (1 - fx) + image[i1, j1] * fx
    return top * (1 - fy) + bottom * fy


@pytest.mark.parametrize("shape", [(33, 47, 3), (16, 16), (1, 9, 2), (9, 1), (1, 1, 4)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.float16, np.int32])
def test_bilinear_lookup_matches_the_numpy_reference_bit_for_bit(shape, dtype):
    rng = np.random.default_rng(len(shape) * 100 + shape[0])
    image = (rng.normal(size=shape) * 50).astype(dtype)
    uv = rng.uniform(-0.2, 1.2, (3000, 2))
    uv[:6] = [[np.inf, 0.5], [-np.inf, np.inf], [0, 1], [1, 0], [0.5, -np.inf], [0.5, 0.5]]
    fast, slow = metrics.bilinear_lookup(image, uv), bilinear_reference(image, uv)
    assert fast.dtype == slow.dtype == np.float64 and fast.shape == slow.shape
    assert np.array_equal(fast, slow)
    # A non-contiguous view and float32 UVs read the same.
    view = np.asarray(image)[::-1][::-1]
    assert np.array_equal(metrics.bilinear_lookup(view, uv.astype(np.float32)),
                          bilinear_reference(image, uv.astype(np.float32)))
    assert metrics.bilinear_lookup(image, np.zeros((0, 2))).shape == (0, slow.shape[1])


def test_bilinear_lookup_refuses_bad_input():
    from lmrefine import _native

    image = np.zeros((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match=r"uv\[1\] is NaN"):
        metrics.bilinear_lookup(image, np.array([[0.5, 0.5], [np.nan, 0.5]]))
    with pytest.raises(ValueError, match=r"uv must have shape \(P, 2\)"):
        metrics.bilinear_lookup(image, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="uv must hold real numbers"):
        metrics.bilinear_lookup(image, np.array([["a", "b"]]))
    with pytest.raises(ValueError, match="image is empty"):
        metrics.bilinear_lookup(np.zeros((0, 4), np.float32), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="image must have shape"):
        metrics.bilinear_lookup(np.zeros((2, 2, 2, 2), np.float32), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="image must be float32 or float64"):
        _native.bilinear_lookup(np.zeros((2, 2), np.int32), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="image must be a numpy array"):
        _native.bilinear_lookup([[0.0]], np.zeros((1, 2)))


def test_a_perfect_lightmap_gives_zero_error():
    # Light that is linear in u (hence in x) is reproduced exactly by a
    # bilinear lookup of its texel-centre samples: zero error everywhere.
    positions, triangles, uvs = plane()
    samples = metrics.sample_surface(positions, triangles, 5000, seed=1)
    resolution = 64
    u_centres = (np.arange(resolution) + 0.5) / resolution
    light = np.repeat(np.tile(3.0 * u_centres, (resolution, 1))[..., None], 3, axis=2)
    point_uv = metrics.interpolate_corners(uvs, samples.triangle, samples.bary)
    truth = np.repeat(3.0 * point_uv[:, :1], 3, axis=1)
    stats = metrics.error_stats(metrics.bilinear_lookup(light, point_uv), truth)
    assert stats["rmse"] < 1e-5 and stats["mae"] < 1e-5
    # And a known offset gives exactly that error.
    stats = metrics.error_stats(metrics.bilinear_lookup(light + 0.25, point_uv), truth)
    assert stats["rmse"] == pytest.approx(0.25, abs=1e-5) and stats["mae"] == pytest.approx(0.25, abs=1e-5)
    assert np.isnan(metrics.error_stats(truth, truth, where=np.zeros(len(truth), bool))["rmse"])


def test_transitions_are_found_at_a_shadow_edge_and_never_across_a_crease():
    positions, triangles, _ = plane(n=16)
    samples = metrics.sample_surface(positions, triangles, 4000, seed=2)
    step = 0.02
    points, normals, distances = metrics.gradient_stencil(positions, triangles, samples, step)
    # Neighbours stay on the plane, inside the point's own triangle, within `step`.
    assert np.abs(points[:, 2]).max() < 1e-6
    assert distances.max() <= step + 1e-12 and distances.min() > 0
    moved = np.linalg.norm(points.astype(np.float64) - np.tile(samples.points, (2, 1)), axis=1)
    np.testing.assert_allclose(moved, distances, atol=1e-5)

    def shade(p):  # a soft shadow edge 0.1 m wide at x = 1
        return np.repeat(np.clip((p[:, :1] - 0.95) / 0.1, 0, 1), 3, axis=1)

    gradient = metrics.surface_gradient(shade(samples.points), shade(points), distances)
    transitions = metrics.transition_mask(gradient)
    assert 0.03 < transitions.mean() <= 0.1 + 1e-9
    near_edge = np.abs(samples.points[:, 0] - 1.0) < 0.06 + step
    assert near_edge[transitions].all()
    # The gradient inside the ramp is its slope (10 per metre).
    inside = np.abs(samples.points[:, 0] - 1.0) < 0.03
    np.testing.assert_allclose(gradient[inside], 10.0, rtol=0.02)
    # Flat light: no transitions at all.
    flat = metrics.surface_gradient(np.ones((len(samples), 3)), np.ones((2 * len(samples), 3)), distances)
    assert not metrics.transition_mask(flat).any()


def test_uniform_density_change_of_two_gives_widening_two():
    positions, triangles, uvs = plane()
    corner_triangles = np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)
    world = metrics.triangle_areas(positions, triangles)
    base = metrics.texel_density(uvs, corner_triangles, world, 64)
    # Scaling UVs by sqrt(2) doubles every UV area: density doubles everywhere.
    refined_uvs = 0.05 + (uvs - 0.1) * np.sqrt(2.0)
    refined = metrics.texel_density(refined_uvs, corner_triangles, world, 64)
    np.testing.assert_allclose(refined / base, 2.0, rtol=1e-5)
    # 0.8^2 of the atlas over 4 m^2 at 64^2 texels.
    np.testing.assert_allclose(base, 0.64 * 64 * 64 / 4.0, rtol=1e-5)
    samples = metrics.sample_surface(positions, triangles, 1000, seed=0)
    transitions = np.zeros(1000, bool)
    transitions[::7] = True
    assert metrics.transition_widening(base, refined, samples.triangle, transitions) == pytest.approx(2.0, rel=1e-5)
    assert np.isnan(metrics.transition_widening(base, refined, samples.triangle, np.zeros(1000, bool)))
    # Only the transition points count: doubling there, halving elsewhere.
    mixed = base.copy()
    hot = np.zeros(len(base), bool)
    hot[samples.triangle[transitions]] = True
    mixed[hot] *= 2
    mixed[~hot] *= 0.5
    assert metrics.transition_widening(base, mixed, samples.triangle, transitions) == pytest.approx(2.0)


def test_equal_error_search_finds_a_known_crossing():
    multipliers = [1, 1.5, 2, 3, 4]
    # Error linear in log-resolution: e = 1 - 0.4 ln(m); e = 0.6 at m = e^1.
    errors = [1 - 0.4 * np.log(m) for m in multipliers]
    ratio, status = metrics.equal_error_resolution(multipliers, errors, 0.6)
    assert status == "within" and ratio == pytest.approx(np.e, rel=1e-9)
    # Exactly at a tested point.
    ratio, status = metrics.equal_error_resolution(multipliers, [8, 6, 4, 2, 1], 4.0)
    assert status == "within" and ratio == pytest.approx(2.0)
    # The refined map equals the baseline at R: ratio 1.
    assert metrics.equal_error_resolution(multipliers, [8, 6, 4, 2, 1], 8.0) == (1.0, "within")
    # Better than the baseline at 4R: a lower bound, flagged.
    assert metrics.equal_error_resolution(multipliers, [8, 6, 4, 2, 1], 0.5) == (4.0, "above")
    # Worse than the baseline at R: below 1, flagged.
    ratio, status = metrics.equal_error_resolution(multipliers, [8, 6, 4, 2, 1], 9.0)
    assert status == "below" and ratio < 1.0
    # Noisy, non-monotone baseline: the first crossing counts.
    ratio, status = metrics.equal_error_resolution(multipliers, [8, 5, 6, 2, 1], 5.5)
    assert status == "within" and 1.0 < ratio < 1.5
    # A baseline whose error hardly falls with resolution (noise-limited): no answer.
    ratio, status = metrics.equal_error_resolution(multipliers, [0.22, 0.22, 0.215, 0.21, 0.205], 0.2)
    assert status == "flat" and np.isnan(ratio)
    with pytest.raises(ValueError, match="ascending"):
        metrics.equal_error_resolution([2, 1], [1, 2], 1.5)


def test_equal_error_interval_is_wide_where_the_baseline_stops_falling():
    from lmrefine.evaluation import _ill_determined_note
    multipliers = [1, 1.5, 2, 3, 4]
    # The room at 32 samples (its plain bakes' errors, seed 0): flat from 2R to 3R. Its refined map's
    # error sits just below that stretch, so the ratio reads 3.0 while 2% more error reads 1.9.
    room = [0.017644, 0.014647, 0.013159, 0.0131594, 0.011499]
    assert metrics.equal_error_resolution(multipliers, room, 0.013156)[0] == pytest.approx(3.0, abs=0.01)
    low, high = metrics.equal_error_interval(multipliers, room, 0.013156)
    assert 1.8 < low < 2.0 and 3.0 < high < 3.2
    # Error falling as a power of resolution (texels resolving the light): a narrow interval.
    steep = [m ** -0.6 for m in multipliers]
    low, high = metrics.equal_error_interval(multipliers, steep, 2.5 ** -0.6)
    assert low < 2.5 < high < 1.1 * low
    # The note: only for the wide one, naming the flattest stretch and the samples.
    sweep = lambda errors: [{"resolution": int(256 * m), "multiplier": m, "rmse": e}
                            for m, e in zip(multipliers, errors)]
    result = {"equal_error_interval": list(metrics.equal_error_interval(multipliers, room, 0.013156)),
              "resolution_sweep": sweep(room), "rmse_refined": 0.013156, "bake_samples": 32}
    note = _ill_determined_note(result)
    assert note.startswith("ill-determined ratio: the refined map's error 0.01316 +-2% matches the uniform baseline "
                           "anywhere from 1.9") and "(0.01316 at 512, 0.01316 at 768)" in note
    assert "more --samples (now 32)" in note
    # The stretch named is the flattest one the interval spans, not a flatter one elsewhere.
    elsewhere = [0.0150, 0.0152] + room[2:]  # rising from R to 1.5R, outside the interval 1.9-3.1x
    low, high = metrics.equal_error_interval(multipliers, elsewhere, 0.013156)
    assert 1.5 < low < 2.0 and 3.0 < high < 3.2
    note = _ill_determined_note({**result, "equal_error_interval": [low, high], "resolution_sweep": sweep(elsewhere)})
    assert "(0.01316 at 512, 0.01316 at 768)" in note
    narrow = {**result, "equal_error_interval": [2.4, 2.6], "resolution_sweep": sweep(steep)}
    assert _ill_determined_note(narrow) is None
    # Flat over the whole range: no interval (equal_error_resolution says "flat").
    assert np.isnan(metrics.equal_error_interval(multipliers, [0.22, 0.22, 0.215, 0.21, 0.205], 0.2)).all()


def test_truth_noise_is_the_noise_of_the_mean_of_two_estimates(rng):
    truth = rng.random((200000, 3))
    first = truth + rng.normal(0, 0.1, truth.shape)
    second = truth + rng.normal(0, 0.1, truth.shape)
    # Each estimate has noise 0.1; their mean has 0.1 / sqrt(2).
    assert metrics.truth_noise(first, second) == pytest.approx(0.1 / np.sqrt(2), rel=0.01)
    measured = metrics.error_stats((first + second) / 2, truth)["rmse"]
    assert metrics.truth_noise(first, second) == pytest.approx(measured, rel=0.01)


def test_layout_change_is_the_median_texel_density_change_and_drives_the_stage_rule():
    uvs = np.array([(0, 0), (0.5, 0), (0, 0.5), (1, 0), (1, 0.5), (0.5, 1)], np.float32)
    triangles = np.array([(0, 1, 2), (1, 3, 4), (2, 4, 5)])
    assert metrics.layout_change(uvs, uvs, triangles) == 0.0
    moved = uvs.copy()
    moved[0] = (0.0, -0.5)  # the first triangle's area x 2, the others unchanged: changes 1, 0, 0
    assert metrics.layout_change(uvs, moved, triangles) == 0.0
    moved[5] = (0.5, 1.5)   # the third triangle grows too: changes 1, 0, > 0
    third = metrics.uv_areas(moved, triangles)[2] / metrics.uv_areas(uvs, triangles)[2] - 1
    assert metrics.layout_change(uvs, moved, triangles) == pytest.approx(min(1.0, third))
    assert metrics.stage_stop_reason(2, True, metrics.STAGE_MIN_CHANGE) is None
    assert "stage 1 kept" in metrics.stage_stop_reason(2, True, 0.01)
    assert "stage 2 kept" in metrics.stage_stop_reason(3, False, 0.5)
    # A third or later stage that moved enough but backed off below STAGE_MIN_BACKOFF somewhere stops
    # too; a second stage does not (second stages that backed off that far still gained, measured).
    assert metrics.STAGE_BACKOFF_FROM == 3
    assert metrics.stage_stop_reason(3, True, 0.5, backoff=metrics.STAGE_MIN_BACKOFF) is None
    assert metrics.stage_stop_reason(2, True, 0.5, backoff=0.05) is None
    stopped = metrics.stage_stop_reason(3, True, 0.5, backoff=0.05)
    assert "stage 2 kept" in stopped and "5% of its deformation" in stopped
    # ... and so does one that gave its light changes no more texels than the stage before.
    assert metrics.stage_stop_reason(2, True, 0.5, widening=1.01) is None
    stopped = metrics.stage_stop_reason(2, True, 0.5, widening=0.99)
    assert "stage 1 kept" in stopped and "0.99x" in stopped


def _quad_plane(size, uv_scale=1.0):
    """One size x size quad as two triangles (face 0), UVs filling [0, uv_scale]^2."""
    positions = np.array([(0, 0, 0), (size, 0, 0), (size, size, 0), (0, size, 0)], np.float64)
    uvs = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32) * uv_scale
    return positions, uvs, np.array([(0, 1, 2), (0, 2, 3)])


def test_texels_per_metre_of_a_known_plane():
    """A 2 m x 2 m plane whose UVs fill [0, 1]^2 at 256 x 256 has 256 texels over 2 m: 128 per metre."""
    positions, uvs, triangles = _quad_plane(2.0)
    areas = metrics.triangle_areas(positions, triangles)
    assert metrics.texels_per_metre(uvs, triangles, areas, 256) == pytest.approx([128.0, 128.0])
    assert metrics.texels_per_metre(uvs, triangles, areas, 256, faces=[7, 7]) == pytest.approx([128.0, 128.0])
    # Half the UV square in each direction: 64 per metre; a 512 x 256 map: sqrt(2) x 128.
    assert metrics.texels_per_metre(uvs * 0.5, triangles, areas, 256) == pytest.approx([64.0, 64.0])
    assert metrics.texels_per_metre(uvs, triangles, areas, (256, 512)) == pytest.approx([128 * 2 ** 0.5] * 2)


def test_texels_per_metre_is_the_root_of_texel_density_and_pools_a_face():
    rng = np.random.default_rng(3)
    positions = rng.random((30, 3))
    uvs = rng.random((30, 2)).astype(np.float32)
    triangles = rng.permutation(30).reshape(10, 3)
    areas = metrics.triangle_areas(positions, triangles)
    per_triangle = metrics.texels_per_metre(uvs, triangles, areas, 64)
    assert per_triangle == pytest.approx(np.sqrt(metrics.texel_density(uvs, triangles, areas, 64)), rel=1e-12)
    # Triangles 0-2 form one face: they share sqrt(summed texels / summed area).
    faces = np.array([0, 0, 0, 1, 2, 3, 4, 5, 6, 7])
    pooled = metrics.texels_per_metre(uvs, triangles, areas, 64, faces=faces)
    texels = metrics.uv_areas(uvs, triangles)[:3].sum() * 64 * 64
    assert pooled[:3] == pytest.approx([np.sqrt(texels / areas[:3].sum())] * 3, rel=1e-12)
    assert pooled[3:] == pytest.approx(per_triangle[3:], rel=1e-12)


def test_texels_per_metre_on_messy_faces():
    """No world area, NaN or huge coordinates give NaN (nothing to show), a zero UV area gives 0 (no texels),
    and the inputs are left as they were."""
    positions, uvs, triangles = _quad_plane(2.0)
    positions = np.concatenate([positions, [(0, 0, 0), (1, 0, 0), (2, 0, 0)], [(0, 0, 0), (1e200, 0, 0),
                                                                               (0, 1e200, 0)]])
    uvs = np.concatenate([uvs, [(0, 0), (1, 0), (0, 1)], [(0, 0), (1, 0), (0, 1)]]).astype(np.float32)
    uvs[1] = np.nan
    triangles = np.array([(0, 1, 2), (0, 2, 3), (4, 5, 6), (7, 8, 9), (0, 0, 2)])
    uvs_before, triangles_before = uvs.copy(), triangles.copy()
    with np.errstate(all="ignore"):
        areas = metrics.triangle_areas(positions, triangles)  # inf for the huge triangle
    with np.errstate(all="raise"):  # no warning escapes
        values = metrics.texels_per_metre(uvs, triangles, areas, 256)
        pooled = metrics.texels_per_metre(uvs, triangles, areas, 256, faces=[0, 0, 1, 2, 3])
    assert np.isnan(values[0]) and values[1] == pytest.approx(128.0)  # triangle 0 has a NaN UV
    assert np.isnan(values[2]) and np.isnan(values[3]) and np.isnan(values[4])  # flat, infinite, degenerate
    assert np.isnan(pooled[:2]).all()  # a NaN UV spoils its whole face
    assert np.array_equal(uvs[~np.isnan(uvs)], uvs_before[~np.isnan(uvs_before)]) and np.array_equal(
        triangles, triangles_before)
    flat_uvs = uvs.copy()
    flat_uvs[:4] = 0.5
    assert metrics.texels_per_metre(flat_uvs, triangles[:2], areas[:2], 256) == pytest.approx([0.0, 0.0])


def test_noise_level_finds_the_noise_and_not_the_light_changes(rng):
    """Shadow edges, a smooth falloff and chart borders are not noise; added Gaussian noise is found
    (its luminance deviation over the median light) within a tenth."""
    size = 128
    y, x = np.mgrid[0:size, 0:size] / size
    light = 0.6 + 0.3 * x  # smooth falloff
    light = np.where((x > 0.3) & (x < 0.45), 0.05, light)  # a hard shadow band
    light = np.where((x - 0.7) ** 2 + (y - 0.6) ** 2 < 0.02, 0.1, light)  # a disc's shadow
    lightmap = np.repeat(light[..., None], 3, axis=2).astype(np.float32)
    mask = np.zeros((size, size), bool)
    mask[4:60, 4:124] = mask[66:124, 4:124] = True  # two charts, black gutter between
    lightmap[~mask] = 0.0
    clean = metrics.noise_level(lightmap, mask)
    assert clean < 0.002
    median = float(np.median(light[mask]))
    for sigma in (0.01, 0.03, 0.1):
        noisy = lightmap + np.where(mask[..., None], rng.normal(0.0, sigma * median, lightmap.shape), 0.0)
        found = metrics.noise_level(noisy.astype(np.float32), mask)
        luminance_sigma = sigma * float(np.linalg.norm(metrics.LUMINANCE))  # independent channels
        assert abs(found - luminance_sigma) < 0.1 * luminance_sigma, (sigma, found, luminance_sigma)
    one_channel = metrics.noise_level(noisy[..., :1].astype(np.float32), mask)  # the last one, sigma 0.1
    assert abs(one_channel - 0.1) < 0.01 and metrics.noise_level(noisy[..., 0], mask) == one_channel
    assert metrics.noise_level(lightmap, np.zeros((size, size), bool)) == 0.0
    assert metrics.noise_level(np.zeros_like(lightmap), mask) == 0.0
