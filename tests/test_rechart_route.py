"""refine_uvs' re-chart route (positions=, docs/refiner.md "The re-chart
route"): the no-room rule on the source layout's charts, the lightmap carried
over to the re-charted layout (checked against a plain reference beside it),
the model's prediction, and the route itself: valid, deterministic, inputs
untouched, off when asked."""

import numpy as np
import pytest

import lmrefine
from lmrefine import metrics, rechart_route
from lmrefine.allocation import signed_areas
from layouts import SCALES_WITHIN_2, floor_grid, grid_chart, lightmap_pack, smart_uv
from test_metrics import bilinear_reference

CELLS = 12
# The floor's quads are about 7 texels wide at 96^2: re-charted it measures
# less error than its one-quad charts refined (at 128^2 they measure less:
# test_route_chooses_what_measures_less_error).
RESOLUTION = 96


def _floor_layouts(resolution=RESOLUTION):
    """A floor of CELLS x CELLS quads with per-corner positions (3T, 3), and
    two layouts of it: one chart per quad (Lightmap Pack's kind) and one
    chart for the whole floor (Smart UV's kind), both (3T, 2) per corner."""
    positions, triangles = floor_grid(CELLS, 1.0)
    corners = positions[triangles].reshape(-1, 3).astype(np.float64)
    per_face = lightmap_pack(charts_across=CELLS, margin_texels=2, resolution=resolution)
    one_chart = grid_chart(CELLS, (0.05, 0.05), (0.95, 0.95))
    return corners, per_face, one_chart


def _floor_scene(uvs, triangles, corners=None):
    """The floor under a sun, half of it in the shadow of a roof (a hard
    edge across the quads), with the layout (uvs, triangles); `corners`: its
    positions per corner (default the CELLS x CELLS floor's)."""
    scene = lmrefine.Scene()
    scene.add_mesh(_corner_positions() if corners is None else corners, triangles, uvs=uvs)
    roof = np.array([(-2, -2, 1), (0.13, -2, 1), (0.13, 2, 1), (-2, 2, 1)], np.float32)
    scene.add_mesh(roof, np.array([(0, 1, 2), (0, 2, 3)], np.int32), receiver=False)
    scene.add_light("sun", energy=3.0, angle=0.01, direction=(0.25, 0.1, -1.0))
    return scene


def _shadowed_floor(uvs, triangles, corners=None, resolution=RESOLUTION, samples=8, seed=0):
    """_floor_scene baked at `resolution`."""
    return np.ascontiguousarray(lmrefine.bake(_floor_scene(uvs, triangles, corners), resolution,
                                              passes=("direct",), samples=samples, seed=seed)[0][..., :3])


def _corner_positions():
    positions, triangles = floor_grid(CELLS, 1.0)
    return positions[triangles].reshape(-1, 3).astype(np.float32)


@pytest.fixture(scope="module")
def lightmap_pack_case():
    corners, (uvs, triangles), _ = _floor_layouts()
    return corners, uvs, triangles, _shadowed_floor(uvs, triangles)


# --- the no-room rule ---------------------------------------------------------

def test_no_room_on_a_lightmap_pack_layout():
    uvs, triangles = lightmap_pack(charts_across=8, quads=1)
    room = rechart_route.layout_room(uvs, triangles)
    assert room["charts"] == 64 and room["triangles_per_chart"] == 2.0
    assert room["room_fraction"] == 0.0 and room["no_room"]
    # Charts of 2 x 2 quads: one inner UV each, which 6 of the 8 triangles (two per quad, split
    # along the same diagonal) touch.
    uvs, triangles = lightmap_pack(charts_across=8, quads=2)
    room = rechart_route.layout_room(uvs, triangles)
    assert room["room_fraction"] == pytest.approx(0.75) and not room["no_room"]


def test_room_on_a_smart_uv_layout():
    uvs, triangles = smart_uv()
    room = rechart_route.layout_room(uvs, triangles)
    assert room["charts"] == 5 and not room["no_room"]
    # Only the triangles on the charts' outer ring of quads touch no inner UV... except at their inner
    # corner: every triangle of a 24 x 24-quad chart but those of its four corner quads has one.
    assert room["room_fraction"] > 0.95


def test_room_counts_area_not_triangles():
    # One big chart with inner UVs and many tiny one-face charts: the big chart's area decides.
    big = grid_chart(4, (0.02, 0.02), (0.7, 0.7))
    small = [grid_chart(1, (0.75 + 0.02 * (k % 10), 0.02 + 0.02 * (k // 10)),
                        (0.76 + 0.02 * (k % 10), 0.03 + 0.02 * (k // 10))) for k in range(60)]
    from layouts import merge
    uvs, triangles = merge(big, *small)
    room = rechart_route.layout_room(uvs, triangles)
    assert room["triangles_per_chart"] < 3 and not room["no_room"]
    assert room["room_fraction"] > 0.9


# --- carrying the lightmap over -----------------------------------------------

def _source_owners(source_uvs, source_triangles, shape):
    """(texel owners (H, W), chart per triangle) of the source layout, charts
    as the baker finds them (tolerance 0)."""
    checker = lmrefine._native.LayoutChecker(source_uvs, source_triangles, shape, 0.0)
    return checker.texel_owners(), checker.charts


def _owned_read(image, owners, chart, uv):
    """The source map at `uv` read from the texels `owners` gives to `chart`:
    bilinear where it owns the 2 x 2 texels, else their bilinear weights
    renormalized over those it owns, else its nearest texel within two (the
    first in row order on a tie), else bilinear. Plain loops, in the native
    kernel's order of operations."""
    image = image if image.ndim == 3 else image[..., None]
    height, width = image.shape[:2]
    x = min(max(uv[0] * width - 0.5, 0.0), width - 1.0)
    y = min(max((1.0 - uv[1]) * height - 0.5, 0.0), height - 1.0)
    j0 = min(int(np.floor(x)), width - 2) if width > 1 else 0
    i0 = min(int(np.floor(y)), height - 2) if height > 1 else 0
    fx = x - j0 if width > 1 else 0.0
    fy = y - i0 if height > 1 else 0.0
    j1, i1 = min(j0 + 1, width - 1), min(i0 + 1, height - 1)
    texels = [(i0, j0), (i0, j1), (i1, j0), (i1, j1)]
    weights = [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy]
    if all(owners[t] == chart for t in texels):
        return bilinear_reference(image, np.array([uv]))[0]
    total, value = 0.0, np.zeros(image.shape[2])
    for texel, weight in zip(texels, weights):
        if owners[texel] == chart and weight > 0.0:
            total += weight
            value += weight * image[texel].astype(np.float64)
    if total > 0.0:
        return value / total
    ci, cj = int(np.floor(y + 0.5)), int(np.floor(x + 0.5))
    best, best_distance = None, np.inf
    for i in range(max(ci - 2, 0), min(ci + 2, height - 1) + 1):
        for j in range(max(cj - 2, 0), min(cj + 2, width - 1) + 1):
            distance = (j - x) * (j - x) + (i - y) * (i - y)
            if owners[i, j] == chart and distance < best_distance:
                best, best_distance = (i, j), distance
    if best is None:
        return bilinear_reference(image, np.array([uv]))[0]
    return image[best].astype(np.float64)


def _resample_reference(lightmap, source_uvs, source_triangles, uvs, triangles, mask):
    """Plain loops: every covered texel's centre in the triangle it lies
    deepest in (barycentrics clamped), read in the source map from the texels
    of that triangle's source chart (_owned_read)."""
    height, width = mask.shape
    owners, charts = _source_owners(source_uvs, source_triangles, mask.shape)
    out = np.zeros(lightmap.shape, np.float32)
    for i in range(height):
        for j in range(width):
            if not mask[i, j]:
                continue
            point = np.array([(j + 0.5) / width, 1 - (i + 0.5) / height])
            best, best_score = None, -np.inf
            for t, (a, b, c) in enumerate(np.asarray(uvs, np.float64)[triangles]):
                matrix = np.array([b - a, c - a]).T
                if abs(np.linalg.det(matrix)) < 1e-300:
                    continue
                beta, gamma = np.linalg.solve(matrix, point - a)
                bary = np.array([1 - beta - gamma, beta, gamma])
                if bary.min() > best_score:
                    best, best_score = (t, bary), bary.min()
            t, bary = best
            bary = np.clip(bary, 0, None) / np.clip(bary, 0, None).sum()
            at = bary @ np.asarray(source_uvs, np.float64)[source_triangles[t]]
            out[i, j] = _owned_read(lightmap, owners, charts[t], at).reshape(out[i, j].shape)
    return out


def _texel_points_numpy(uvs, triangles, shape, mask):
    """For every texel of `mask` in row-major order: the triangle holding its
    centre (texel_points) and the centre's barycentrics there, clamped into
    the triangle; a third each where no triangle with area reaches."""
    triangle, bary, score = lmrefine._native.texel_points(uvs, triangles, shape)
    where = np.asarray(mask, bool)
    bary = np.clip(bary[where], 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    bary[~np.isfinite(score[where])] = 1.0 / 3.0
    return triangle[where], bary


def _resample_numpy(lightmap, source_uvs, source_triangles, uvs, triangles, mask):
    """resample_lightmap in numpy (the texel points as before the native
    kernel, each read by _owned_read), which _native.carry_lightmap must
    match bit for bit."""
    lightmap = np.asarray(lightmap, np.float32)
    owners, charts = _source_owners(source_uvs, source_triangles, lightmap.shape[:2])
    triangle, bary = _texel_points_numpy(np.asarray(uvs, np.float64), triangles, lightmap.shape[:2], mask)
    source = np.asarray(source_uvs, np.float64)[np.asarray(source_triangles)[triangle]]  # (P, 3, 2)
    points = np.einsum("pk,pkd->pd", bary, source)
    values = np.array([_owned_read(lightmap, owners, charts[t], point) for t, point in zip(triangle, points)])
    values = values.reshape(len(points), -1)
    out = np.zeros(lightmap.shape[:2] + (values.shape[1],), np.float32)
    out[mask] = values
    return out.reshape(lightmap.shape)


@pytest.mark.parametrize("seed", range(6))
def test_resample_lightmap_matches_its_numpy_form_bit_for_bit(seed):
    # Random triangles over and beyond the map (texels they only graze, overlaps, a degenerate
    # one), a random source layout of the same triangles, RGB and single-channel maps.
    rng = np.random.default_rng(seed)
    count = int(rng.integers(1, 30))
    uvs = rng.uniform(-0.1, 1.1, (3 * count, 2))
    uvs[:3] = uvs[0]  # no area: texels only it reaches take a third of each corner
    triangles = np.arange(3 * count, dtype=np.int32).reshape(-1, 3)
    source_uvs = rng.uniform(0, 1, (3 * count, 2)).astype(np.float32)
    source_triangles = triangles[:, ::-1].copy()
    shape = (int(rng.integers(1, 40)), int(rng.integers(1, 40)))
    mask = rng.random(shape) < 0.8
    for channels in ((3,), ()):
        lightmap = rng.uniform(0, 4, shape + channels).astype(np.float32)
        fast = rechart_route.resample_lightmap(lightmap, source_uvs, source_triangles, uvs, triangles, mask)
        slow = _resample_numpy(lightmap, source_uvs, source_triangles, uvs, triangles, mask)
        assert fast.dtype == slow.dtype == np.float32 and fast.shape == slow.shape == lightmap.shape
        assert np.array_equal(fast, slow)


def test_carry_lightmap_refuses_bad_input():
    carry = lmrefine._native.carry_lightmap
    lightmap, mask = np.zeros((8, 8, 3), np.float32), np.ones((8, 8), bool)
    uvs, triangles = np.array([[0, 0], [1, 0], [0, 1]], np.float64), np.array([[0, 1, 2]], np.int32)
    with pytest.raises(ValueError, match="lightmap must be float32"):
        carry(lightmap.astype(np.float64), uvs, triangles, uvs, triangles, mask)
    with pytest.raises(ValueError, match=r"source_uvs\[1\] is NaN"):
        carry(lightmap, np.array([[0, 0], [np.nan, 0], [0, 1]]), triangles, uvs, triangles, mask)
    with pytest.raises(ValueError, match=r"uvs must have shape \(N, 2\)"):
        carry(lightmap, uvs, triangles, np.zeros((3, 3)), triangles, mask)
    with pytest.raises(ValueError, match=r"triangles\[0\] indexes uvs row 3"):
        carry(lightmap, uvs, triangles, uvs, np.array([[0, 1, 3]]), mask)
    with pytest.raises(ValueError, match="the same triangles"):
        carry(lightmap, uvs, np.zeros((2, 3), np.int32), uvs, triangles, mask)
    with pytest.raises(ValueError, match="mask must have the lightmap's shape"):
        carry(lightmap, uvs, triangles, uvs, triangles, np.ones((8, 7), bool))
    with pytest.raises(ValueError, match="mask must be a numpy array"):
        carry(lightmap, uvs, triangles, uvs, triangles, None)


@pytest.mark.parametrize("far", [1e9, 1e30, -1e300])
def test_carry_lightmap_takes_a_source_layout_far_outside_the_map(far):
    # The source's texel owners rasterize it in float32 (1e300 is Inf there): clamped, never undefined.
    lightmap, mask = np.full((8, 8, 3), 2.0, np.float32), np.ones((8, 8), bool)
    uvs, triangles = np.array([[0, 0], [1, 0], [0, 1]], np.float64), np.array([[0, 1, 2]], np.int32)
    source = np.array([[0, 0], [far, 0], [0, 1]], np.float64)
    carried = lmrefine._native.carry_lightmap(lightmap, source, triangles, uvs, triangles, mask)
    assert np.array_equal(carried, lightmap)


def test_resample_lightmap_matches_the_reference(rng):
    positions, triangles = floor_grid(3, 1.0)
    source = lightmap_pack(charts_across=3, margin_texels=2, resolution=32)
    target = grid_chart(3, (0.1, 0.1), (0.9, 0.9))
    lightmap = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
    mask = lmrefine.coverage_mask(*target, 32)
    fast = rechart_route.resample_lightmap(lightmap, *source, *target, mask)
    slow = _resample_reference(lightmap, *source, *target, mask)
    assert fast.dtype == np.float32 and fast.shape == lightmap.shape
    np.testing.assert_allclose(fast, slow, atol=1e-5)
    assert not fast[~mask].any()


def test_resample_lightmap_reads_each_chart_from_its_own_texels():
    # Lightmap Pack packs unrelated faces about a texel apart, so their covered texels touch: a
    # face's carried light holds none of its neighbours' (nor of the dilated gutter).
    source_uvs, triangles = lightmap_pack(charts_across=4, margin_texels=1.0, resolution=32)
    target_uvs, _ = grid_chart(4, (0.05, 0.05), (0.95, 0.95))
    owners, charts = _source_owners(source_uvs, triangles, (32, 32))
    lightmap = np.where(owners >= 0, owners, 99).astype(np.float32)  # each chart its id, the gutter 99
    mask = lmrefine.coverage_mask(target_uvs, triangles, 32)
    carried = rechart_route.resample_lightmap(lightmap, source_uvs, triangles, target_uvs, triangles, mask)
    triangle, bary = _texel_points_numpy(target_uvs.astype(np.float64), triangles, (32, 32), mask)
    np.testing.assert_allclose(carried[mask], charts[triangle], rtol=0, atol=1e-5)
    # Read bilinearly across the borders, one texel in seven would hold a mix.
    plain = bilinear_reference(lightmap, np.einsum("pk,pkd->pd", bary, source_uvs[triangles[triangle]]))[:, 0]
    assert np.mean(np.abs(plain - charts[triangle]) > 1e-3) > 0.1


def test_resample_lightmap_carries_a_linear_light_exactly():
    # Light linear in the source's UVs inside each chart is read back at the same surface points.
    source_uvs, triangles = lightmap_pack(charts_across=4, margin_texels=4, resolution=64)
    target_uvs, _ = grid_chart(4, (0.05, 0.05), (0.95, 0.95))
    y, x = np.mgrid[0:64, 0:64] + 0.5
    lightmap = (x / 64).astype(np.float32)  # u at each texel centre
    mask = lmrefine.coverage_mask(target_uvs, triangles, 64)
    carried = rechart_route.resample_lightmap(lightmap, source_uvs, triangles, target_uvs, triangles, mask)
    # Where a target texel's centre lies inside a triangle, the value is that point's source u.
    triangle, bary = _texel_points_numpy(target_uvs.astype(np.float64), triangles, (64, 64), mask)
    expected = np.einsum("pk,pk->p", bary, source_uvs[triangles[triangle], 0])
    inside = np.abs(carried[mask] - expected) < 1e-4
    assert inside.mean() > 0.6  # texels whose bilinear footprint stays inside their source chart


# --- the model's prediction ---------------------------------------------------

def test_predicted_error_of_scaled_layouts():
    uvs, triangles = smart_uv()
    energy = np.ones((256, 256), np.float32)
    assert rechart_route.predicted_error(uvs, uvs, triangles, energy) == pytest.approx(1.0)
    half = uvs * 0.5  # a quarter of the texels: twice the edge error
    assert rechart_route.predicted_error(uvs, half, triangles, energy) == pytest.approx(2.0, rel=1e-6)
    assert rechart_route.predicted_error(half, uvs, triangles, energy) == pytest.approx(0.5, rel=1e-6)


def test_one_error_model_predicts_as_fresh_calls(lightmap_pack_case):
    # The route asks one model about two layouts: each answer equals
    # predicted_error's own, bit for bit, in either order.
    corners, uvs, triangles, lightmap = lightmap_pack_case
    mask = lmrefine.coverage_mask(uvs, triangles, RESOLUTION)
    energy = lmrefine.gradient_map(lightmap, mask).sum(axis=2)
    _, _, one_chart = _floor_layouts()
    layouts = [one_chart[0], uvs, (0.5 * uvs + 0.25).astype(np.float32)]
    for args in ((), (corners, lightmap)):
        model = rechart_route.ErrorModel(uvs, triangles, energy, *args)
        shared = [model.relative(layout) for layout in layouts + layouts[::-1]]
        fresh = [rechart_route.predicted_error(uvs, layout, triangles, energy, *args)
                 for layout in layouts + layouts[::-1]]
        assert shared == fresh
    assert shared[1] == 1.0


def test_the_model_counts_the_texels_across_the_light_change():
    # The floor's shadow edge runs along v (the roof's edge): its gradient points along u. At the
    # same texel area, texels twice as fine across it (2 x u, v / 2) predict about half the edge
    # error, twice as fine along it (u / 2, 2 x v) more than before; area alone would say the same.
    corners, _, (one_chart, triangles) = _floor_layouts()
    lightmap = _shadowed_floor(one_chart, triangles)
    mask = lmrefine.coverage_mask(one_chart, triangles, RESOLUTION)
    energy = lmrefine.gradient_map(lightmap, mask).sum(axis=2)
    model = rechart_route.ErrorModel(one_chart, triangles, energy, corners, lightmap)
    centre = one_chart.mean(axis=0)
    across = (centre + (one_chart - centre) * np.float32([2.0, 0.5])).astype(np.float32)
    along = (centre + (one_chart - centre) * np.float32([0.5, 2.0])).astype(np.float32)
    assert model.relative(across) < 0.7 < 1.0 < model.relative(along)
    # A uniform scale counts as before: half the texel size, half the edge error (the border term,
    # of the light's slope, falls as its square).
    assert 0.25 < model.relative((centre + (one_chart - centre) * 2.0).astype(np.float32)) <= 0.5 + 1e-6


def test_predicted_error_counts_chart_borders():
    # A smooth light ramp (no edges): the same floor at the same texel density costs less with
    # one chart than with a chart per quad, whose borders the dilation fills.
    corners, (per_face, triangles), (one_chart, _) = _floor_layouts()
    y, x = np.mgrid[0:RESOLUTION, 0:RESOLUTION] + 0.5
    ramp = (x / RESOLUTION).astype(np.float32)
    energy = np.zeros((RESOLUTION, RESOLUTION), np.float32)
    mask = lmrefine.coverage_mask(per_face, triangles, RESOLUTION)
    # Scale the one-chart layout to the per-face layout's UV area: only the borders differ.
    area = lambda u: np.abs(lmrefine.allocation.signed_areas(u, triangles)).sum()
    centre = one_chart.mean(axis=0)
    same_density = (centre + (one_chart - centre) * np.sqrt(area(per_face) / area(one_chart))).astype(np.float32)
    ratio = rechart_route.predicted_error(per_face, same_density, triangles, energy, corners, ramp, mask)
    # Border length: 4 sides per quad against the floor's 4 sides; the ramp's slope is the same.
    assert ratio == pytest.approx(4 * CELLS / (4 * CELLS * CELLS), rel=0.05)
    assert rechart_route.predicted_error(per_face, per_face, triangles, energy, corners, ramp, mask) == \
        pytest.approx(1.0)


def test_lowest_packed_of_one_square_chart():
    # One chart of L x L texels with light changes and no slope (a flat map: the border term is 0) packs
    # at most g = (R + p - sqrt(pi) p / 2) / L across an R^2 atlas at padding p (Brunn-Minkowski is exact
    # for a disc, close for a square); the edge term falls as 1 / g.
    corners, _, (one_chart, triangles) = _floor_layouts()
    energy = np.ones((RESOLUTION, RESOLUTION), np.float32)
    flat = np.full((RESOLUTION, RESOLUTION, 3), 0.5, np.float32)
    model = rechart_route.ErrorModel(one_chart, triangles, energy, corners, flat)
    side = 0.9 * RESOLUTION
    for padding in (0.0, 2.0, 3.5):
        g = (RESOLUTION + padding - np.sqrt(np.pi) * padding / 2) / side
        assert model.lowest_packed((RESOLUTION, RESOLUTION), padding, [1.0]) == pytest.approx(1 / g, rel=1e-5)
    assert model.lowest_packed((RESOLUTION, RESOLUTION), 2.0, [0.0]) is None  # no live chart
    assert rechart_route.ErrorModel(one_chart, triangles, energy).lowest_packed((128, 128), 2.0, [1.0]) is None


def test_lowest_packed_bounds_every_packing_at_its_scales(lightmap_pack_case):
    # Whatever the packer makes of the source's charts at g x scales (turned, or stretched at equal
    # area first), the model predicts no less than the bound at those scales; the bound is close.
    corners, uvs, triangles, lightmap = lightmap_pack_case
    mask = lmrefine.coverage_mask(uvs, triangles, RESOLUTION)
    energy = lmrefine.gradient_map(lightmap, mask).sum(axis=2)
    model = rechart_route.ErrorModel(uvs, triangles, energy, corners, lightmap)
    charts, signal, _, _ = lmrefine.allocation.signal_scales(uvs, triangles, energy, 0.5, 2.0, lightmap, mask)
    rng = np.random.default_rng(3)
    from lmrefine import stretch
    for scales in (signal, np.sqrt(signal), np.ones_like(signal), rng.uniform(0.5, 2.0, len(signal))):
        for padding in (1.0, 2.0):
            bound = model.lowest_packed((RESOLUTION, RESOLUTION), padding, scales)
            packed, _ = lmrefine.pack_charts(uvs, triangles, charts, scales, RESOLUTION, padding)
            predicted = model.relative(packed)
            assert bound <= predicted and bound > 0.8 * predicted, (bound, predicted)
            factor = rng.uniform(1.0, 2.0, len(scales))
            direction = np.column_stack([np.cos(factor), np.sin(factor)])
            stretched = stretch.stretch_charts(uvs, triangles, charts, factor, direction)
            packed, _ = lmrefine.pack_charts(stretched, triangles, charts, scales, RESOLUTION, padding)
            # A stretch by up to 2 may space the light changes up to twice as finely.
            assert model.lowest_packed((RESOLUTION, RESOLUTION), padding, scales, max_stretch=2.0) <= \
                model.relative(packed)


def test_route_does_not_make_the_source_repack_the_bound_rules_out(lightmap_pack_case, monkeypatch):
    # The re-charted floor predicts less than any packing of the source's one-quad charts can:
    # the source's repack is not made, and the layout returned is the one the full comparison picks.
    # Made, the source's repack is not finished (no triangle stretch): the re-charted layout wins.
    corners, uvs, triangles, lightmap = lightmap_pack_case
    from lmrefine import refine
    made, finished = [], []
    repack_stage, finish = refine._repack_stage, refine._finished
    monkeypatch.setattr(refine, "_repack_stage", lambda stage, *own: made.append(stage) or repack_stage(stage, *own))
    monkeypatch.setattr(refine, "_finished", lambda stage, packed: finished.append(stage) or finish(stage, packed))
    skipped = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners,
                                  **SCALES_WITHIN_2)
    info = skipped.report["rechart"]
    assert info["used"] and info["predicted_error_source_route"] is None
    assert info["predicted_error"] < info["source_route_bound"] < 1.0
    assert "at least" in skipped.report["notes"][0] and len(made) == 1  # the re-charted layout's alone
    monkeypatch.setattr(refine, "_source_lowest", lambda stage: None)
    made.clear()
    finished.clear()
    full = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners,
                               **SCALES_WITHIN_2)
    assert len(made) == 2 and len(finished) == 1 and finished[0] is made[0]  # the re-charted layout's
    assert np.array_equal(full.uvs, skipped.uvs)
    assert full.report["rechart"]["predicted_error_source_route"] >= info["source_route_bound"]


def test_the_source_lowest_is_its_own_prediction_without_a_repack_and_none_with_overlaps():
    from lmrefine.refine import _source_lowest

    from types import SimpleNamespace

    model = type("Model", (), {"relative": staticmethod(lambda layout: 0.75)})()
    fields = {"hold": False, "check": {"overlapping": 0}, "new_uvs": None,
              "options": {"repack": False, "strength": 24.0}}

    def stage(**changed):  # the _InCharts fields _source_lowest reads
        return SimpleNamespace(**{**fields, **changed})

    assert _source_lowest(stage())(model) == 0.75  # the in-chart layout is what the source route returns
    assert _source_lowest(stage(options={"repack": True, "strength": 0}))(model) == 0.75
    assert _source_lowest(stage(hold=True, options={"repack": True, "strength": 24.0}))(model) == 0.75
    assert _source_lowest(stage(check={"overlapping": 3})) is None


def test_lowest_packed_bounds_the_packings_of_a_layout_moved_inside_its_charts(lightmap_pack_case):
    # The one-chart floor deformed by the automaton (repack off), then packed at several scales: the
    # model predicts no less than the bound from the deformed layout.
    corners, _, (one_chart, triangles) = _floor_layouts()
    lightmap = _shadowed_floor(one_chart, triangles)
    mask = lmrefine.coverage_mask(one_chart, triangles, RESOLUTION)
    energy = lmrefine.gradient_map(lightmap, mask).sum(axis=2)
    moved = lmrefine.refine_uvs(lightmap, one_chart, triangles, RESOLUTION, repack=False).uvs
    assert not np.array_equal(moved, one_chart)
    model = rechart_route.ErrorModel(one_chart, triangles, energy, corners, lightmap)
    charts = lmrefine.find_charts(moved, triangles, lmrefine.CHART_TOLERANCE)
    for scale in (0.6, 0.9, 1.0):
        bound = model.lowest_packed((RESOLUTION, RESOLUTION), 2.0, [scale], moved)
        packed, _ = lmrefine.pack_charts(moved, triangles, charts, [scale], RESOLUTION, 2.0)
        assert bound <= model.relative(packed) < 1.05 * bound
    assert model.lowest_packed((RESOLUTION, RESOLUTION), 2.0, [1.0], moved) < \
        model.lowest_packed((RESOLUTION, RESOLUTION), 2.0, [1.0])  # the automaton's gain counts


# --- the route ----------------------------------------------------------------

@pytest.mark.parametrize("resolution", [96, 128])
def test_route_chooses_what_measures_less_error(resolution, monkeypatch):
    # The floor from one-quad charts, its two choices forced and baked, measured against the light
    # at points on it: the route returns the one that measures less error. At 96^2 that is the
    # re-charted floor (its quads are 7 texels wide), at 128^2 the quads' own refinement (9 texels).
    from lmrefine import refine
    corners, (uvs, triangles), _ = _floor_layouts(resolution)
    lightmap = _shadowed_floor(uvs, triangles, resolution=resolution)
    rng = np.random.default_rng(0)
    triangle = rng.integers(0, len(triangles), 4000)
    bary = rng.dirichlet([1, 1, 1], len(triangle))
    points = np.einsum("nk,nkc->nc", bary, corners[triangles[triangle]]).astype(np.float32)
    truth = lmrefine.evaluate(_floor_scene(uvs, triangles, corners), points,
                              np.tile(np.float32([0, 0, 1]), (len(points), 1)), passes=("direct",), samples=128,
                              seed=5)[:, :3]

    def error(layout):
        baked = _shadowed_floor(layout, triangles, corners, resolution, samples=32, seed=1)
        read = lmrefine.metrics.bilinear_lookup(baked, lmrefine.metrics.interpolate_corners(layout, triangle, bary))
        return float(np.sqrt(((read - truth) ** 2).sum(axis=1).mean()))

    def refine_route(**options):
        return lmrefine.refine_uvs(lightmap, uvs, triangles, resolution, padding=2, positions=corners, **options)

    finished, finish = [], refine._finished
    monkeypatch.setattr(refine, "_finished", lambda stage, packed: finished.append(stage) or finish(stage, packed))
    chosen = refine_route()
    assert len(finished) == 1  # only the layout returned gets its triangle stretch
    source = refine_route(rechart=False)
    monkeypatch.setattr(refine, "_source_lowest", lambda stage: (lambda model: np.inf))  # re-charting wins
    recharted = refine_route()
    assert recharted.report["rechart"]["used"] and not source.report["rechart"]["used"]
    better = recharted if error(recharted.uvs) < error(source.uvs) else source
    assert np.array_equal(chosen.uvs, better.uvs)
    assert chosen.report["rechart"]["used"] == (resolution == 96)


def test_route_recharts_a_lightmap_pack_source(lightmap_pack_case):
    corners, uvs, triangles, lightmap = lightmap_pack_case
    copies = [a.copy() for a in (corners, uvs, triangles, lightmap)]
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    for before, after in zip(copies, (corners, uvs, triangles, lightmap)):
        assert np.array_equal(before, after)  # inputs untouched
    info = result.report["rechart"]
    assert info["used"], info
    assert info["room"]["no_room"] and info["charts"] == 1  # the flat floor: one chart
    assert info["predicted_error"] < rechart_route.REQUIRED_GAIN
    assert result.uvs.shape == uvs.shape and result.uvs.dtype == np.float32
    check = lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)
    assert check["valid"], check
    assert len(np.unique(lmrefine.find_charts(result.uvs, triangles, lmrefine.CHART_TOLERANCE))) == 1
    # Figures against the user's layout: the shadow edge's triangles gained texels.
    assert result.report["moved"] and result.report["transition_widening"] > 1.5
    assert result.report["notes"][0].startswith("re-charted: the source layout gives the refiner no room")
    from lmrefine.backoff import worse_than_source
    assert worse_than_source(result.uvs, uvs, triangles, RESOLUTION, 2)[0] == []
    again = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    assert np.array_equal(again.uvs, result.uvs)  # deterministic


def test_polygon_ids_join_the_triangles_that_share_uvs():
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9], [7, 9, 10], [10, 11, 7], [12, 13, 14]])
    assert rechart_route.polygon_ids(triangles).tolist() == [0, 0, 4, 7, 7, 7, 12]
    assert rechart_route.polygon_ids(np.arange(12).reshape(-1, 3)).tolist() == [0, 3, 6, 9]  # per corner
    # A long fan closes in a few rounds (pointer jumping), to one polygon.
    fan = np.array([[0, k, k + 1] for k in range(1, 2000)])
    assert set(rechart_route.polygon_ids(fan[::-1]).tolist()) == {0}
    assert rechart_route.polygon_ids(np.zeros((0, 3), np.int32)).shape == (0,)


def _bumpy_quads_per_loop():
    """A hilly floor of CELLS x CELLS quads as Blender hands it over: four
    loops per quad (positions and Lightmap Pack UVs per loop), its two
    triangles sharing the diagonal's loops. The hills turn faces more than
    the route's angle, so chart borders would cross quads."""
    positions, triangles = floor_grid(CELLS, 1.0)
    positions = positions.astype(np.float64)
    positions[:, 2] = 0.35 * np.sin(3 * positions[:, 0]) * np.cos(2 * positions[:, 1])
    quads = triangles.reshape(-1, 6)[:, [0, 1, 2, 5]]  # (a, b, c), (a, c, d) -> a, b, c, d
    per_face, _ = lightmap_pack(charts_across=CELLS, margin_texels=2, resolution=RESOLUTION)
    uvs = per_face.reshape(-1, 6, 2)[:, [0, 1, 2, 5]].reshape(-1, 2)
    loops = np.arange(4 * len(quads)).reshape(-1, 4)
    loop_triangles = np.concatenate([loops[:, [0, 1, 2]], loops[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
    return positions[quads.reshape(-1)], uvs, loop_triangles.astype(np.int32)


def test_route_keeps_a_polygons_triangles_in_one_chart(monkeypatch):
    """Found on the bundled hillside in a real Blender window: the add-on's layout is per loop, so a
    chart border through a quad's diagonal cannot be written, and the route gave up ("corners that
    share a UV into different charts") and left the Lightmap Pack source repacked at its own gutter."""
    corners, uvs, triangles = _bumpy_quads_per_loop()
    # The baker reads a mesh per corner.
    lightmap = _shadowed_floor(uvs[triangles].reshape(-1, 2), np.arange(3 * len(triangles)).reshape(-1, 3),
                               corners[triangles].reshape(-1, 3))
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners,
                                 **SCALES_WITHIN_2)
    info = result.report["rechart"]
    assert info["used"], info
    assert result.uvs.shape == uvs.shape  # one UV per loop, as the source
    assert lmrefine.check_layout(result.uvs, triangles, RESOLUTION, padding=2)["valid"]
    # Every triangle of a quad in one chart of the refined layout.
    charts = lmrefine.find_charts(result.uvs, triangles, lmrefine.CHART_TOLERANCE)
    assert (charts[0::2] == charts[1::2]).all()
    # Without the polygons the re-charting cuts quads and the route gives up.
    monkeypatch.setattr(rechart_route, "polygon_ids", lambda triangles, polygons=None: np.arange(len(triangles)))
    cut = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    assert not cut.report["rechart"]["used"] and "different charts" in cut.report["rechart"]["reason"]


def test_route_keeps_the_faces_it_is_given_of_a_per_corner_layout_whole():
    """A per-corner layout (the sample .npz files, a caller's numpy arrays) shares no UV index, so only
    polygons= tells the route which triangles were one quad."""
    corners, uvs, triangles = _bumpy_quads_per_loop()
    corner_uvs, corner_triangles = uvs[triangles].reshape(-1, 2), np.arange(3 * len(triangles)).reshape(-1, 3)
    corner_positions = corners[triangles].reshape(-1, 3)
    lightmap = _shadowed_floor(corner_uvs, corner_triangles, corner_positions)
    faces = np.repeat(np.arange(len(triangles) // 2) * 7 + 100, 2)  # any integer ids, one per quad
    kept = lmrefine.refine_uvs(lightmap, corner_uvs, corner_triangles, RESOLUTION, padding=2,
                               positions=corner_positions, polygons=faces, **SCALES_WITHIN_2)
    assert kept.report["rechart"]["used"], kept.report["rechart"]
    charts = lmrefine.find_charts(kept.uvs, corner_triangles, lmrefine.CHART_TOLERANCE)
    assert (charts[0::2] == charts[1::2]).all()
    # The same layout per loop gives the same layout (within float32 rounding: UVs are welded per index)
    # up to the triangle stretch, whose least-squares fit of the two differs by rounding: its packing
    # may then end one step of the packer's lattice of scales (1e-4) apart.
    per_loop = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners,
                                   **SCALES_WITHIN_2)
    assert per_loop.report["triangle_stretch"]["used"] == kept.report["triangle_stretch"]["used"]
    if kept.unstretched_uvs is not None:
        np.testing.assert_allclose(per_loop.unstretched_uvs[triangles].reshape(-1, 2), kept.unstretched_uvs,
                                   rtol=0, atol=1e-6)
    np.testing.assert_allclose(per_loop.uvs[triangles].reshape(-1, 2), kept.uvs, rtol=0, atol=2e-4)
    # Without the faces the hills cut quads along their diagonals.
    cut = lmrefine.refine_uvs(lightmap, corner_uvs, corner_triangles, RESOLUTION, padding=2,
                              positions=corner_positions, **SCALES_WITHIN_2)
    charts = lmrefine.find_charts(cut.uvs, corner_triangles, lmrefine.CHART_TOLERANCE)
    assert cut.report["rechart"]["used"] and (charts[0::2] != charts[1::2]).any()


def test_polygon_ids_join_the_faces_given_with_the_shared_uvs():
    triangles = np.arange(18).reshape(-1, 3)  # per corner: nothing shared
    faces = rechart_route.polygons_array([5, 5, -2, 9, 9, 9], 6)
    assert faces.tolist() == [1, 1, 0, 2, 2, 2]
    assert rechart_route.polygon_ids(triangles, faces).tolist() == [0, 0, 6, 9, 9, 9]
    shared = triangles.copy()
    shared[2, 0] = 0  # the third triangle shares a UV with the first: one face with it
    assert rechart_route.polygon_ids(shared, faces).tolist() == [0, 0, 0, 9, 9, 9]


@pytest.mark.parametrize("polygons, match", [
    (np.zeros(5, np.int32), r"one integer face id per triangle, shape \(\d+,\)"),
    (np.zeros(CELLS * CELLS * 2, np.float32), "one integer face id per triangle"),
    (np.zeros(CELLS * CELLS * 2, bool), "one integer face id per triangle"),
])
def test_route_bad_polygons(lightmap_pack_case, polygons, match):
    corners, uvs, triangles, lightmap = lightmap_pack_case
    with pytest.raises(ValueError, match=match):
        lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, positions=corners, polygons=polygons)
    with pytest.raises(ValueError, match=r"polygons= is read only with positions="):
        lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, polygons=np.zeros(len(triangles), np.int32))


def test_route_packs_charts_apart_when_the_automaton_fit_undid_a_region(monkeypatch):
    """The bundled hillside's Lightmap Pack source at 192^2: its re-charted terrain is one large chart,
    packed exactly the padding from the boulders' charts, so every edge texel is rigid, and the finest
    automaton level's fit sent a region back to rest (fit_reset). The route then packs the charts half a
    texel farther apart, where the edge texels may shrink, and keeps that layout (its fit takes fewer
    rounds and does not reset): the terrain's shadow edges gain the texels the cascade had taken back. (Which
    bakes cascade depends on where the packer puts the charts: first found at 256^2 with seed 1's bake,
    this case is seed 0's at 192^2 since the packer's scale estimate, docs/packer.md.)"""
    from lmrefine.sample_scenes import load_sample
    scene = load_sample("hillside")
    uvs, triangles = scene.layout("lightmap")
    positions = scene.positions[scene.triangles].reshape(-1, 3)
    lightmap = lmrefine.bake(scene.to_scene(uvs), 192, passes="direct", samples=8, seed=0)[0][..., :3]
    # The automaton's bounds of the time it was found (min_shrink 0.25, edge_shrink 0.8, scales within 2x):
    # with today's defaults this bake's fit no longer resets.
    from lmrefine import refine
    finished, finish = [], refine._finished
    monkeypatch.setattr(refine, "_finished", lambda stage, packed: finished.append(stage) or finish(stage, packed))
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, 192, positions=positions, normals=scene.normals,
                                 min_shrink=0.25, edge_shrink=0.8, **SCALES_WITHIN_2)
    info = result.report["rechart"]
    assert info["used"] and info["edge_room"] is True, info
    assert len(finished) == 1  # the layout kept: the first one's triangle stretch is not made
    assert lmrefine.check_layout(result.uvs, triangles, 192, padding=2)["valid"]
    assert "packed half a texel farther apart" in result.report["notes"][0]
    from lmrefine.evaluation_report import layout_text
    text = layout_text({"variant": "lightmap", "refine": result.report})
    assert "packed half a texel farther apart and refined again: kept." in text
    # The same route without the retry: the layout the cascade left.
    monkeypatch.setattr(rechart_route, "fit_reset", lambda result: False)
    first = lmrefine.refine_uvs(lightmap, uvs, triangles, 192, positions=positions, normals=scene.normals,
                                min_shrink=0.25, edge_shrink=0.8, **SCALES_WITHIN_2)
    assert first.report["rechart"]["used"] and first.report["rechart"]["edge_room"] is None
    assert first.report["levels"][-1]["fit_reset"]  # the automaton's own report of the cascade
    assert info["predicted_error"] < first.report["rechart"]["predicted_error"]
    terrain = scene.object_id == scene.objects.index("Terrain")

    def terrain_spread(layout):
        """95th over 5th percentile of the terrain triangles' texel density against the source."""
        density = np.abs(signed_areas(layout, triangles) / signed_areas(uvs, triangles))[terrain]
        return np.percentile(density, 95) / np.percentile(density, 5)

    assert terrain_spread(result.uvs) > 1.4 * terrain_spread(first.uvs)  # measured 5.3 against 3.6
    assert result.report["levels"][-1]["fit_rounds"] < first.report["levels"][-1]["fit_rounds"]  # 35 against 93
    assert not result.report["levels"][-1]["fit_reset"]


def test_later_stages_of_a_recharted_layout_with_no_room_refine_inside_its_charts(lightmap_pack_case):
    """The stage rule (metrics.further_stage_options): from a source layout with no room, re-charted or not,
    stages 2, 3, ... keep the charts' scales and places; a layout with room repacks again."""
    corners, uvs, triangles, lightmap = lightmap_pack_case
    routed = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    assert routed.report["rechart"]["used"] and routed.report["rechart"]["room"]["no_room"]
    assert metrics.further_stage_options(routed.report) == {"repack": False}
    off = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners, rechart=False)
    assert metrics.further_stage_options(off.report) == {"repack": False}  # no room, not re-charted
    # Without the positions stage 1 did not measure the room: the user's options as they are.
    assert metrics.further_stage_options(lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION).report) == {}
    # A layout with room, re-charted for its folds or not, repacks again.
    assert metrics.further_stage_options({"rechart": {"used": True, "room": {"no_room": False}}}) == {}
    corners_room, _, (uvs_room, triangles_room) = _floor_layouts()
    with_room = lmrefine.refine_uvs(_shadowed_floor(uvs_room, triangles_room), uvs_room, triangles_room,
                                    RESOLUTION, padding=2, positions=corners_room)
    assert metrics.further_stage_options(with_room.report) == {}
    # The stage-2 refinement with the rule refines inside the charts, no repack.
    second = lmrefine.refine_uvs(lightmap, routed.uvs, triangles, RESOLUTION, padding=2,
                                 **metrics.further_stage_options(routed.report))
    assert second.report["repack"] is None
    assert lmrefine.check_layout(second.uvs, triangles, RESOLUTION, padding=2)["valid"]


def test_a_tessellated_lightmap_pack_source_keeps_the_route():
    # A floor of 3 x 3 quads, one chart each, under a roof's shadow edge. Splitting the triangles the edge
    # crosses puts vertices inside their charts: the split layout reads as having room and would keep its
    # 9 charts. The options from the layout before the split ask for the route.
    positions, vertex_triangles = floor_grid(3, 1.0)
    uvs, triangles = lightmap_pack(charts_across=3, margin_texels=2, resolution=RESOLUTION)
    lightmap = _shadowed_floor(uvs, triangles, positions[vertex_triangles].reshape(-1, 3).astype(np.float32))
    strength = lmrefine.transition_strength_of(lightmap, uvs, triangles)
    split = lmrefine.tessellate(positions, vertex_triangles, uvs[triangles].reshape(-1, 2), strength, budget=4.0)
    split_triangles = np.arange(len(split.uvs), dtype=np.int32).reshape(-1, 3)
    split_corners = split.positions[split.triangles].reshape(-1, 3)
    assert rechart_route.layout_room(uvs, triangles)["no_room"]
    assert not rechart_route.layout_room(split.uvs, split_triangles)["no_room"]
    gated = lmrefine.refine_uvs(lightmap, split.uvs, split_triangles, RESOLUTION, padding=2, positions=split_corners)
    assert not gated.report["rechart"]["used"] and "has room" in gated.report["rechart"]["reason"]
    options = lmrefine.tessellated_refine_options({"strength": 24.0}, uvs, triangles)
    assert options == {"strength": 24.0, "rechart": "always"}
    routed = lmrefine.refine_uvs(lightmap, split.uvs, split_triangles, RESOLUTION, padding=2,
                                 positions=split_corners, **options)
    info = routed.report["rechart"]
    assert info["used"] and info["always"] and info["charts"] == 1, info
    assert routed.report["notes"][0].startswith("re-charted: the source layout's 9 charts were asked")
    assert lmrefine.check_layout(routed.uvs, split_triangles, RESOLUTION, padding=2)["valid"]
    assert metrics.further_stage_options(routed.report) == {"repack": False}  # as for a layout with no room
    # The route turned off, or a layout with room before the split: the options as they were.
    assert lmrefine.tessellated_refine_options({"rechart": False}, uvs, triangles) == {"rechart": False}
    _, _, (uvs_room, triangles_room) = _floor_layouts()
    assert lmrefine.tessellated_refine_options({}, uvs_room, triangles_room) == {}


def test_route_off_switch(lightmap_pack_case):
    corners, uvs, triangles, lightmap = lightmap_pack_case
    plain = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2)
    off = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners, rechart=False)
    assert plain.report["rechart"] is None
    assert not off.report["rechart"]["used"] and "off" in off.report["rechart"]["reason"]
    assert np.array_equal(plain.uvs, off.uvs)
    assert len(np.unique(lmrefine.find_charts(off.uvs, triangles, lmrefine.CHART_TOLERANCE))) == CELLS ** 2


def test_route_keeps_a_layout_with_room():
    corners, _, (uvs, triangles) = _floor_layouts()
    lightmap = _shadowed_floor(uvs, triangles)
    plain = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2)
    routed = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    info = routed.report["rechart"]
    assert not info["used"] and not info["room"]["no_room"] and "has room" in info["reason"]
    assert np.array_equal(plain.uvs, routed.uvs)


def test_route_needs_the_lightmap(lightmap_pack_case):
    corners, uvs, triangles, lightmap = lightmap_pack_case
    gradient = lmrefine.gradient_map(lightmap, lmrefine.coverage_mask(uvs, triangles, RESOLUTION))
    result = lmrefine.refine_uvs(None, uvs, triangles, RESOLUTION, padding=2, gradient=gradient,
                                 positions=corners)
    assert not result.report["rechart"]["used"]
    assert "not re-charted: re-charting needs the lightmap" in " ".join(result.report["notes"])


def _quads_per_loop(n, fourth_corner):
    """n x n quads, one chart each, the two triangles of a quad sharing the diagonal's two UVs (as
    Blender's loops of one face); `fourth_corner(x, y)` places each quad's corner over (x, y + 1)."""
    positions, uvs, triangles = [], [], []
    for k in range(n * n):
        x, y = k % n, k // n
        quad = [(x, y, 0), (x + 1, y, 0), (x + 1, y + 1, 0), fourth_corner(x, y)]
        base = len(positions)
        positions += quad
        cell = 1.0 / n
        uvs += [(x * cell + 0.02, y * cell + 0.02), ((x + 1) * cell - 0.02, y * cell + 0.02),
                ((x + 1) * cell - 0.02, (y + 1) * cell - 0.02), (x * cell + 0.02, (y + 1) * cell - 0.02)]
        triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(positions, np.float64), np.array(uvs, np.float32), np.array(triangles, np.int32)


def test_route_keeps_a_folded_quad_whole_and_refuses_a_uv_shared_across_charts():
    y, x = np.mgrid[0:64, 0:64]
    lightmap = np.where(x > 27, 1.0, 0.1).astype(np.float32)
    # Quads folded 60 degrees along their diagonal: the re-chart angle would cut each in two, but
    # a polygon's triangles stay in one chart, so the route runs (the model keeps the source here).
    lift = np.sin(np.radians(60))
    positions, uvs, triangles = _quads_per_loop(4, lambda x, y: (x, y + 1, lift))
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, 64, padding=2, positions=positions)
    info = result.report["rechart"]
    assert info["room"]["no_room"] and "charts" in info, info
    assert "corners that share a UV" not in info.get("reason", "")
    assert lmrefine.check_layout(result.uvs, triangles, 64, padding=2)["valid"]
    # A quad whose second triangle has no area: that triangle gets a chart of its own, and one UV
    # cannot sit in both charts, so the route gives up and says why.
    positions, uvs, triangles = _quads_per_loop(4, lambda x, y: (x + 0.5, y + 0.5, 0))
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, 64, padding=2, positions=positions)
    info = result.report["rechart"]
    assert info["room"]["no_room"] and not info["used"]
    assert "corners that share a UV" in info["reason"]
    assert lmrefine.check_layout(result.uvs, triangles, 64, padding=2)["valid"]


@pytest.mark.parametrize("positions, error, match", [
    (np.zeros((5, 3)), ValueError, r"positions must have shape \(\d+, 3\)"),
    (np.full((CELLS * CELLS * 6, 3), np.nan), ValueError, r"positions\[0\] is NaN or Inf"),
    ("mesh", TypeError, "positions must be an"),
    (np.zeros((CELLS * CELLS * 6, 3), object), TypeError, "positions must hold real numbers"),
])
def test_route_bad_positions(lightmap_pack_case, positions, error, match):
    _, uvs, triangles, lightmap = lightmap_pack_case
    with pytest.raises(error, match=match):
        lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, positions=positions)


def test_route_names_a_mesh_too_small_to_re_chart(lightmap_pack_case):
    # The reason blamed the padding, the resolution and the scales (found by a crash hunt).
    corners, uvs, triangles, lightmap = lightmap_pack_case
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners * 1e-20)
    info = result.report["rechart"]
    assert not info["used"]
    assert info["reason"].startswith("the mesh could not be re-charted: the mesh is too small to lay out: its 288 "
                                     "triangles hold 4e-40 square units of surface")
    assert info["reason"].endswith("scale the mesh up (apply its object scale, or model in larger units)")


@pytest.mark.parametrize("rechart, error", [
    # A str is the right type with a value the switch does not know (a TypeError until a crash hunt).
    ("yes", ValueError), ("sometimes", ValueError), ("Always", ValueError),
    (1, TypeError), (None, TypeError), (0.5, TypeError),
])
def test_route_bad_switch(lightmap_pack_case, rechart, error):
    corners, uvs, triangles, lightmap = lightmap_pack_case
    with pytest.raises(error) as raised:
        lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, positions=corners, rechart=rechart)
    assert str(raised.value) == f"rechart must be True, False or 'always', got {rechart!r}"


def _texel_points_reference(uvs, triangles, shape):
    """texel_points' rule, one triangle at a time over its texel bounding box:
    a texel keeps the first triangle whose smallest barycentric at its centre
    is largest."""
    height, width = shape
    best = np.full(shape, -np.inf)
    owner = np.zeros(shape, np.int64)
    bary_out = np.zeros(shape + (3,))
    for t, corners in enumerate(np.asarray(uvs, np.float64)[triangles]):
        p = corners * (width, height)
        p[:, 1] = height - p[:, 1]
        ab, ac = p[1] - p[0], p[2] - p[0]
        det = ab[0] * ac[1] - ab[1] * ac[0]
        if det == 0:
            continue
        c0, r0 = np.clip(np.floor(p.min(axis=0)), 0, (width - 1, height - 1)).astype(int)
        c1, r1 = np.clip(np.floor(p.max(axis=0)), 0, (width - 1, height - 1)).astype(int)
        rows, cols = np.mgrid[r0:r1 + 1, c0:c1 + 1]
        apx, apy = cols + 0.5 - p[0, 0], rows + 0.5 - p[0, 1]
        beta = (apx * ac[1] - apy * ac[0]) / det
        gamma = (ab[0] * apy - ab[1] * apx) / det
        bary = np.stack([1 - beta - gamma, beta, gamma], axis=-1)
        score = bary.min(axis=-1)
        better = score > best[rows, cols]
        best[rows[better], cols[better]] = score[better]
        owner[rows[better], cols[better]] = t
        bary_out[rows[better], cols[better]] = bary[better]
    return owner, bary_out, best


@pytest.mark.parametrize("seed", range(4))
def test_texel_points_match_the_reference_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    count = int(rng.integers(1, 40))
    uvs = rng.uniform(-0.1, 1.1, (3 * count, 2))
    uvs[:3] = uvs[0]  # a triangle with no area
    triangles = np.arange(3 * count, dtype=np.int32).reshape(-1, 3)
    shape = (int(rng.integers(1, 48)), int(rng.integers(1, 48)))
    fast = lmrefine._native.texel_points(uvs, triangles, shape)
    slow = _texel_points_reference(uvs, triangles, shape)
    for a, b in zip(fast, slow):
        assert a.shape == b.shape and np.array_equal(a, b)


def test_texel_points_refuse_bad_input():
    triangles = np.array([[0, 1, 2]], np.int32)
    with pytest.raises(ValueError, match=r"triangles\[0\] indexes uv 2"):
        lmrefine._native.texel_points(np.zeros((2, 2)), triangles, 8)
    with pytest.raises(ValueError, match=r"uvs\[1\] is NaN"):
        lmrefine._native.texel_points(np.array([[0, 0], [np.nan, 0], [1, 1]]), triangles, 8)
    with pytest.raises(ValueError, match="shape"):
        lmrefine._native.texel_points(np.zeros((3, 3)), triangles, 8)


def test_route_decides_on_the_layouts_before_the_triangle_stretch(lightmap_pack_case, monkeypatch):
    """The route compares its candidates before the triangle stretch (RefineResult.unstretched_uvs), so
    the stretch never changes which route is taken. Here every stretch is kept (the judgement's bar
    raised), which costs each candidate packing scale."""
    from lmrefine import refine as refine_module

    corners, uvs, triangles, lightmap = lightmap_pack_case
    off = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners,
                              triangle_stretch=1.0)
    monkeypatch.setattr(refine_module, "TRIANGLE_STRETCH_REQUIRED_GAIN", 10.0)
    on = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    assert off.unstretched_uvs is None and on.report["triangle_stretch"]["used"]
    for key in ("used", "predicted_error", "predicted_error_source_route", "charts"):
        assert on.report["rechart"].get(key) == off.report["rechart"].get(key), key
    assert np.array_equal(on.unstretched_uvs, off.uvs) and not np.array_equal(on.uvs, off.uvs)
    assert lmrefine.check_layout(on.uvs, triangles, RESOLUTION, padding=2)["valid"]


def test_route_report_reads_the_light_changes_where_the_refinement_found_them():
    """The bundled game_level's Lightmap Pack source at 256^2: faces of about three texels a texel
    apart, so the gradient map, read within each face (refine.chart_separated), shows few of its light
    changes, and its top decile is noise. The report counts the triangles the re-charted refinement
    found at light changes in the map carried to its layout (read from the source's top decile it said
    0.84x: fewer texels at the light changes, where evaluate measured 5.4x at the truth's)."""
    from lmrefine.sample_scenes import load_sample
    scene = load_sample("game_level")
    uvs, triangles = scene.layout("lightmap")
    positions = scene.positions[scene.triangles].reshape(-1, 3)
    lightmap = lmrefine.bake(scene.to_scene(uvs), 256, passes="direct", samples=8, seed=0)[0][..., :3]
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, 256, padding=1, positions=positions)
    assert result.report["rechart"]["used"]
    assert result.report["transition_widening"] > 3  # measured 6.9
    assert result.report["transition_widening_across"] > 2  # measured 3.7


def test_route_repacks_its_own_charts_on_the_models_word():
    """The bundled fence_and_tree's Lightmap Pack source at 256^2 re-charts into 7 charts, which the
    route packs at one scale to 94% of the atlas. Scaled by their light, the flat back of the wall
    shrinks and the square floor cannot fill what it leaves: 87% with its gutters, which the density
    rule refused for a caller's layout, and the model's 0.97 missed its margin. The route's own packing
    is repacked on the model's word (the triangle stretch then fits into the room: measured 1.46x ->
    1.63x); the back of the wall gets a third of the texels of its lit front."""
    from lmrefine.sample_scenes import load_sample
    scene = load_sample("fence_and_tree")
    uvs, triangles = scene.layout("lightmap")
    positions = scene.positions[scene.triangles].reshape(-1, 3)
    lightmap = lmrefine.bake(scene.to_scene(uvs), 256, passes="direct", samples=8, seed=0)[0][..., :3]
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, 256, padding=1, positions=positions)
    repack = result.report["repack"]
    assert result.report["rechart"]["used"] and repack["used"] and repack["own_packing"]
    assert repack["padded_utilisation_after"] < (lmrefine.allocation.MIN_UTILISATION_KEPT
                                                 * repack["padded_utilisation_before"])
    assert result.report["triangle_stretch"]["used"]
    # Measured on the output: the wall's two 25 m^2 sides, the lit front (centres at y 4.45) and the flat back (4.75).
    centre_y = scene.positions[scene.triangles][:, :, 1].mean(axis=1)
    wall = scene.object_id == scene.objects.index("BackWall")
    texels = lmrefine.metrics.uv_areas(result.uvs, triangles)
    front = texels[wall & (centre_y < 4.5)].sum()
    back = texels[wall & (centre_y > 4.7)].sum()
    assert back < 0.5 * front  # measured 0.30; 1.0 before
    assert lmrefine.check_layout(result.uvs, triangles, 256, 2)["valid"]


def test_layout_figures_count_the_light_changes_where_the_first_refinement_found_them(lightmap_pack_case):
    # The add-on's figures over several stages start from the first refinement's light changes: given
    # those of a re-charted result, layout_figures of its layout is its report.
    corners, uvs, triangles, lightmap = lightmap_pack_case
    result = lmrefine.refine_uvs(lightmap, uvs, triangles, RESOLUTION, padding=2, positions=corners)
    assert result.report["rechart"]["used"]
    figures = lmrefine.refine.layout_figures(lightmap, uvs, result.uvs, triangles,
                                             light_changes=result.light_changes)
    for key in ("transition_widening", "transition_widening_across", "transition_triangle_texels"):
        assert figures[key] == pytest.approx(result.report[key], rel=1e-9), key


def _grown_area(polygon, radius, step=0.01):
    """Plain reference: the area of a convex polygon (counter-clockwise, (n, 2)) grown by a disc,
    counted on a grid of `step`: a point is in it when it is inside the polygon or within `radius`
    of one of its edges."""
    lo, hi = polygon.min(axis=0) - radius - step, polygon.max(axis=0) + radius + step
    x, y = np.meshgrid(np.arange(lo[0], hi[0], step) + step / 2, np.arange(lo[1], hi[1], step) + step / 2)
    points = np.column_stack([x.ravel(), y.ravel()])
    inside = np.ones(len(points), bool)
    near = np.zeros(len(points), bool)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        edge = b - a
        inside &= edge[0] * (points[:, 1] - a[1]) - edge[1] * (points[:, 0] - a[0]) >= 0
        t = np.clip(((points - a) @ edge) / (edge @ edge), 0.0, 1.0)
        near |= np.linalg.norm(points - (a + t[:, None] * edge), axis=1) <= radius
    return (inside | near).sum() * step * step


def test_a_triangle_or_convex_quadrilateral_grown_by_a_disc_covers_its_perimeter_bound():
    # Steiner: a convex chart of area a grown by r covers a + perimeter r + pi r^2, and no equal-area
    # stretch of a triangle (a quadrilateral) has a smaller perimeter than the equilateral one (the square).
    rng = np.random.default_rng(5)
    radius = 0.3
    for factor, polygon in ((rechart_route.TRIANGLE_PERIMETER, np.array([[0, 0], [1, 0], [0.5, np.sqrt(0.75)]])),
                            (rechart_route.QUADRILATERAL_PERIMETER, np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]]))):
        area = 0.5 * abs(np.cross(polygon[1] - polygon[0], polygon[-1] - polygon[0])) * (len(polygon) - 2)
        bound = lambda a: a + factor * np.sqrt(a) * radius + np.pi * radius ** 2  # noqa: E731
        # The regular one meets the bound.
        assert _grown_area(polygon, radius) == pytest.approx(bound(area), rel=0.01)
        for _ in range(4):
            # Any other shape of its kind (a random equal-area affine image) covers more.
            matrix = rng.normal(size=(2, 2))
            matrix /= np.sqrt(abs(np.linalg.det(matrix)))
            shape = polygon @ matrix.T
            if np.linalg.det(matrix) < 0:
                shape = shape[::-1]
            assert _grown_area(shape, radius) >= 0.99 * bound(area)
    assert rechart_route.DISC_PERIMETER < rechart_route.QUADRILATERAL_PERIMETER < rechart_route.TRIANGLE_PERIMETER


def test_perimeter_factors_by_the_shape_of_each_chart():
    charts_uvs = [
        [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]],  # one triangle
        [[0.3, 0.0], [0.4, 0.0], [0.4, 0.1], [0.3, 0.0], [0.4, 0.1], [0.3, 0.1]],  # a square of two
        [[0.6, 0.0], [0.7, 0.05], [0.62, 0.05], [0.6, 0.0], [0.62, 0.05], [0.6, 0.1]],  # a dart (concave)
        [[0.0, 0.5], [0.1, 0.5], [0.1, 0.6], [0.0, 0.5], [0.1, 0.6], [0.0, 0.6],
         [0.1, 0.5], [0.2, 0.5], [0.1, 0.6]],  # three triangles
    ]
    uvs = np.array([p for chart in charts_uvs for p in chart], np.float32)
    triangles = np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)
    charts, vertex, _ = rechart_route._chart_borders(uvs, triangles)
    count = int(charts.max()) + 1
    factors = rechart_route.perimeter_factors(uvs, triangles, charts, vertex, count)
    by_triangle = factors[charts]
    assert by_triangle[0] == rechart_route.TRIANGLE_PERIMETER
    assert by_triangle[1] == by_triangle[2] == rechart_route.QUADRILATERAL_PERIMETER
    assert by_triangle[3] == by_triangle[4] == rechart_route.DISC_PERIMETER
    assert (by_triangle[5:] == rechart_route.DISC_PERIMETER).all()
    assert count == 4
