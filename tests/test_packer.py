"""The atlas packer (docs/packer.md): every output passes check_layout with
the padding, on layouts of every kind; the report describes the output."""

import os

import numpy as np
import pytest

import lmrefine
from layouts import grid_chart, lightmap_pack, merge, smart_uv


def rotation(turns):
    return np.array([[1.0, 0.0], [0.0, 1.0]]) if turns % 2 == 0 else np.array([[0.0, -1.0], [1.0, 0.0]])


def random_charts(rng, count, size_range, quads=(1, 3)):
    """`count` rectangular grid charts and random triangles scattered
    anywhere in [0, 1]^2, overlapping (the packer does not care where they
    start)."""
    layouts = []
    for _ in range(count):
        w, h = rng.uniform(*size_range, 2)
        n = int(rng.integers(*quads, endpoint=True))
        lo = rng.uniform(0, 1, 2)
        layouts.append(grid_chart(n, lo, lo + (w, h)))
    return merge(*layouts)


def l_shape(lo, size):
    """A concave chart: three quads in an L."""
    parts = [grid_chart(1, lo, (lo[0] + size, lo[1] + size)),
             grid_chart(1, (lo[0] + size, lo[1]), (lo[0] + 2 * size, lo[1] + size)),
             grid_chart(1, (lo[0], lo[1] + size), (lo[0] + size, lo[1] + 2 * size))]
    uvs, tris = merge(*parts)
    return uvs, tris


def kinds():
    rng = np.random.default_rng(7)
    slivers = merge(*(grid_chart(1, (0.1 * k, 0.2), (0.1 * k + 0.05, 0.2 + 1e-4)) for k in range(8)),
                    random_charts(rng, 10, (0.02, 0.1)))
    return {
        "smart_uv": smart_uv(),
        "lightmap_pack": lightmap_pack(charts_across=12, seed=3),
        "many_tiny": random_charts(np.random.default_rng(1), 600, (0.001, 0.01)),
        "one_huge": grid_chart(20, (-2.0, -1.0), (3.0, 0.5)),
        "mixed_sizes": merge(grid_chart(8, (0, 0), (0.9, 0.7)), random_charts(rng, 60, (0.005, 0.2))),
        "concave": merge(*(l_shape(rng.uniform(0, 1, 2), rng.uniform(0.02, 0.1)) for _ in range(40))),
        "slivers": slivers,
    }


@pytest.mark.parametrize("kind", sorted(kinds()))
@pytest.mark.parametrize("resolution,padding", [(128, 2.0), (256, 1.0), ((96, 160), 3.5)])
def test_every_output_passes_check_layout_with_the_padding(kind, resolution, padding):
    uvs, tris = kinds()[kind]
    before = uvs.copy()
    out, report = lmrefine.pack_charts(uvs, tris, None, None, resolution, padding)
    np.testing.assert_array_equal(uvs, before)  # input untouched
    check = lmrefine.check_layout(out, tris, resolution, padding)
    assert check["valid"], (kind, check)
    assert check["min_gutter_texels"] >= padding
    assert check["charts"] == report["charts"]
    height, width = (resolution, resolution) if isinstance(resolution, int) else resolution
    mask = lmrefine.coverage_mask(out, tris, (height, width))
    assert report["utilisation"] == pytest.approx(mask.mean())
    assert 0 < report["global_scale"] <= report["scale_bound"] * (1 + 1e-6)


@pytest.mark.parametrize("subdivision", [1, 3])
@pytest.mark.parametrize("kind", ["lightmap_pack", "concave", "slivers"])
def test_every_subdivision_keeps_the_padding(kind, subdivision):
    uvs, tris = kinds()[kind]
    out, report = lmrefine.pack_charts(uvs, tris, None, None, 128, 2.0, subdivision=subdivision, boxes=False)
    assert report["placement"] == "footprints"
    assert lmrefine.check_layout(out, tris, 128, 2.0)["valid"]


def test_sub_texel_positions_fit_small_charts_denser():
    uvs, tris = lightmap_pack(charts_across=20, seed=5)
    whole = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0, subdivision=1, boxes=False).report
    halves = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0, subdivision=2, boxes=False).report
    assert halves["area_utilisation"] > whole["area_utilisation"]


def equal_squares(across=24, resolution=128, gutter_texels=1.0):
    """Blender's Lightmap Pack at a low resolution: equal one-quad squares in
    rows, `gutter_texels` apart, at continuous (off-grid) positions."""
    cell = 1.0 / across
    size = cell - gutter_texels / resolution
    return merge(*(grid_chart(1, (j * cell, i * cell), (j * cell + size, i * cell + size))
                   for i in range(across) for j in range(across)))


def test_rectangular_charts_are_placed_as_boxes_at_continuous_positions():
    # Squares of 4.3 texels and 1-texel gutters: on a half-texel grid each
    # gutter takes 1.5 texels and each square rounds up; as boxes they fit as
    # tightly as the input.
    uvs, tris = equal_squares()
    gutter = lmrefine.check_layout(uvs, tris, 128, 1.0)["min_gutter_texels"]
    out, report = lmrefine.pack_charts(uvs, tris, None, None, 128, gutter)
    assert report["placement"] == "boxes"
    assert report["global_scale"] > 0.99 and report["area_utilisation"] > 0.99 * report["area_utilisation_input"]
    check = lmrefine.check_layout(out, tris, 128, gutter)
    assert check["valid"] and check["min_gutter_texels"] >= gutter
    grid = lmrefine.pack_charts(uvs, tris, None, None, 128, gutter, boxes=False).report
    assert grid["placement"] == "footprints" and grid["global_scale"] < 0.95 * report["global_scale"]


@pytest.mark.parametrize("resolution", [128, (96, 160)])
def test_boxes_of_mixed_sizes_and_turns_keep_the_padding_and_the_transforms(resolution):
    rng = np.random.default_rng(4)
    uvs, tris = merge(*(grid_chart(1, (k, 0), (k + w, h)) for k, (w, h) in enumerate(rng.uniform(0.005, 0.04, (300, 2)))))
    scales = rng.uniform(0.5, 2.0, 300)
    out, report = lmrefine.pack_charts(uvs, tris, None, scales, resolution, 1.5)
    assert report["placement"] == "boxes" and set(np.unique(report["rotations"])) == {0, 1}
    check = lmrefine.check_layout(out, tris, resolution, 1.5)
    assert check["valid"] and check["min_gutter_texels"] >= 1.5
    for c in range(report["charts"]):
        corners = np.unique(tris[report["chart_ids"] == c])
        m = report["transforms"][c]
        np.testing.assert_allclose(out[corners], uvs[corners] @ m[:, :2].T + m[:, 2], atol=1e-6)


def test_report_transforms_reproduce_the_output():
    uvs, tris = kinds()["mixed_sizes"]
    scales = np.linspace(0.5, 2.0, lmrefine.find_charts(uvs, tris).max() + 1)
    out, report = lmrefine.pack_charts(uvs, tris, None, scales, 256, 2.0)
    np.testing.assert_allclose(report["chart_scales"], report["global_scale"] * scales)
    for c in range(report["charts"]):
        corners = np.unique(tris[report["chart_ids"] == c])
        m = report["transforms"][c]
        np.testing.assert_allclose(out[corners], uvs[corners] @ m[:, :2].T + m[:, 2], atol=1e-6)
        expected = report["chart_scales"][c] * (rotation(report["rotations"][c]))
        np.testing.assert_allclose(m[:, :2], expected, atol=1e-12)
    np.testing.assert_array_equal(report["offsets"], report["transforms"][:, :, 2])
    assert set(np.unique(report["rotations"])) <= {0, 1}


def test_quarter_turns_keep_the_texel_shape_on_a_non_square_atlas():
    uvs, tris = merge(grid_chart(1, (0, 0), (1.0, 0.25)), grid_chart(1, (0, 0.5), (0.25, 1.5)))
    out, report = lmrefine.pack_charts(uvs, tris, None, None, (64, 256), 2.0)
    assert lmrefine.check_layout(out, tris, (64, 256), 2.0)["valid"]
    for c in range(2):
        corners = out[np.unique(tris[report["chart_ids"] == c])] * (256, 64)  # in texels
        source = uvs[np.unique(tris[report["chart_ids"] == c])] * (256, 64)
        extent, source_extent = np.ptp(corners, axis=0), np.ptp(source, axis=0)
        if report["rotations"][c]:
            source_extent = source_extent[::-1]
        np.testing.assert_allclose(extent, source_extent * report["chart_scales"][c], rtol=1e-5)


def test_relative_scales_are_kept_and_quarter_turns_can_be_refused():
    a = grid_chart(2, (0.0, 0.0), (0.3, 0.1))
    b = grid_chart(2, (0.5, 0.5), (0.8, 0.6))
    uvs, tris = merge(a, b)
    out, report = lmrefine.pack_charts(uvs, tris, None, np.array([1.0, 0.5]), 256, 2.0, rotations=False)
    assert report["rotations"].tolist() == [0, 0]
    extent = [np.ptp(out[np.unique(tris[report["chart_ids"] == c])], axis=0) for c in (0, 1)]
    np.testing.assert_allclose(extent[1], extent[0] * 0.5, rtol=1e-5)


def test_a_tall_chart_is_turned_when_that_fits_more():
    # Two charts 0.8 x 0.1 side by side fit flat; a third upright beside them
    # only packs large if turned.
    uvs, tris = merge(grid_chart(1, (0, 0), (1.0, 0.1)), grid_chart(1, (0, 0.2), (0.1, 1.2)))
    _, turned = lmrefine.pack_charts(uvs, tris, None, None, 128, 2.0)
    _, upright = lmrefine.pack_charts(uvs, tris, None, None, 128, 2.0, rotations=False)
    assert turned["global_scale"] >= upright["global_scale"]


def test_footprints_not_boxes_nest_concave_charts():
    # Small squares go into a large L's notch, inside its bounding box.
    uvs, tris = merge(l_shape((0.0, 0.0), 0.5), *(grid_chart(1, (0.1 * k, 2.0), (0.1 * k + 0.07, 2.07))
                                                   for k in range(6)))
    out, report = lmrefine.pack_charts(uvs, tris, None, None, 256, 1.0)
    assert lmrefine.check_layout(out, tris, 256, 1.0)["valid"]
    boxes = []
    for c in range(report["charts"]):
        corners = out[np.unique(tris[report["chart_ids"] == c])]
        boxes.append((corners.min(0), corners.max(0)))
    overlapping = sum(np.all(np.minimum(a[1], b[1]) - np.maximum(a[0], b[0]) > 0)
                      for k, a in enumerate(boxes) for b in boxes[k + 1:])
    assert overlapping > 0  # the charts share bounding-box area: they were not packed as boxes


def test_deterministic_and_independent_of_where_charts_start():
    uvs, tris = kinds()["lightmap_pack"]
    first = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0)
    second = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0)
    np.testing.assert_array_equal(first.uvs, second.uvs)
    moved = uvs + np.float32(3.0)  # whole layout shifted: same shapes, same packing
    third = lmrefine.pack_charts(moved, tris, None, None, 256, 2.0)
    assert third.report["global_scale"] == pytest.approx(first.report["global_scale"], rel=1e-6)


@pytest.mark.parametrize("kind", ["lightmap_pack", "smart_uv", "mixed_sizes"])
@pytest.mark.parametrize("scaled", [False, True])
def test_a_layout_rounded_differently_packs_the_same(kind, scaled):
    """The search aims its trial scales at the largest that fits, where a trial can flip with the
    layout's last bit; trial scales on a lattice keep two roundings of one layout (a layout per corner
    and the same per loop, docs/packer.md) in the same trials, so at the same scale. (Where each chart
    lands may still differ: equal charts one rounding apart are placed in another order.)"""
    uvs, tris = kinds()[kind]
    rng = np.random.default_rng(3)
    # Every UV one float32 step up, down or kept: the charts' sizes (and the scale bound) move by ~1e-7.
    nudged = np.nextafter(uvs, rng.choice([-1.0, 0.0, 2.0], uvs.shape).astype(np.float32))
    charts = lmrefine.find_charts(uvs, tris, 1e-5) if scaled else None
    scales = rng.uniform(0.5, 2.0, int(charts.max()) + 1) if scaled else None
    first = lmrefine.pack_charts(uvs, tris, charts, scales, 256, 2.0)
    second = lmrefine.pack_charts(nudged, tris, charts, scales, 256, 2.0)
    assert second.report["scale_bound"] != first.report["scale_bound"]  # the rounding reached the bound
    assert second.report["global_scale"] == first.report["global_scale"]
    assert second.report["trials"] == first.report["trials"]


def test_the_result_does_not_depend_on_the_thread_count(monkeypatch):
    uvs, tris = kinds()["mixed_sizes"]
    results = []
    for threads in ("1", "2", "5"):
        monkeypatch.setenv("LMREFINE_THREADS", threads)
        results.append(lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0).uvs)
    for other in results[1:]:
        np.testing.assert_array_equal(other, results[0])


def test_bitmaps_kept_between_calls_do_not_change_a_packing(tmp_path):
    # The packer keeps its footprint bitmaps between calls: a packing after
    # others (which left their charts' texels in them) equals the first
    # packing of a fresh process.
    import subprocess
    import sys
    fresh = tmp_path / "fresh.npy"
    here = os.path.dirname(os.path.abspath(__file__))
    code = ("import sys, numpy as np; sys.path.insert(0, sys.argv[2]); import lmrefine; from test_packer import kinds; "
            "uvs, tris = kinds()['concave']; np.save(sys.argv[1], lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0).uvs)")
    subprocess.run([sys.executable, "-c", code, str(fresh), here], check=True,
                   env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    for kind in ("one_huge", "mixed_sizes", "lightmap_pack"):  # bitmaps full of other charts' texels
        lmrefine.pack_charts(*kinds()[kind], None, None, 256, 2.0)
    uvs, tris = kinds()["concave"]
    np.testing.assert_array_equal(lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0).uvs, np.load(fresh))


def test_uniform_repack_of_smart_uv_layout_uses_more_of_the_atlas():
    uvs, tris = smart_uv(256, margin_texels=8)
    out, report = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0)
    assert report["utilisation"] > report["utilisation_input"]
    assert report["utilisation"] > 0.9


def test_unused_uvs_are_copied_and_charts_may_be_given():
    uvs, tris = merge(grid_chart(1, (0, 0), (0.5, 0.5)), grid_chart(1, (0.6, 0.6), (0.9, 0.9)))
    uvs = np.concatenate([uvs, np.array([[7.0, -3.0]], np.float32)])
    one_chart = np.zeros(len(tris), np.int32)  # both squares as one chart: they keep their relative place
    out, report = lmrefine.pack_charts(uvs, tris, one_chart, None, 64, 2.0)
    assert out[-1].tolist() == [7.0, -3.0]
    assert report["charts"] == 1
    d_in = uvs[tris[2, 0]] - uvs[tris[0, 0]]
    d_out = out[tris[2, 0]] - out[tris[0, 0]]
    assert np.linalg.norm(d_out) == pytest.approx(report["global_scale"] * np.linalg.norm(d_in), rel=1e-5)


def test_corners_within_the_tolerance_are_snapped_into_one_chart():
    uvs, tris = grid_chart(4, (0.1, 0.1), (0.6, 0.6))
    noisy = uvs + np.random.default_rng(0).uniform(-2e-7, 2e-7, uvs.shape).astype(np.float32)
    assert lmrefine.find_charts(noisy, tris).max() > 0  # bit-exact joining falls apart
    assert lmrefine.find_charts(noisy, tris, tolerance=lmrefine.CHART_TOLERANCE).max() == 0
    out, report = lmrefine.pack_charts(noisy, tris, None, None, 128, 2.0)
    assert report["charts"] == 1
    assert lmrefine.find_charts(out, tris).max() == 0  # snapped: bit-exact in the output
    assert lmrefine.check_layout(out, tris, 128, 2.0)["valid"]


@pytest.mark.parametrize("change,message", [
    (dict(resolution=0), "resolution"),
    (dict(padding=-1.0), "padding"),
    (dict(padding=float("nan")), "padding"),
    (dict(scales=np.array([1.0, 0.0])), "scales"),
    (dict(scales=np.array([1.0])), "scales"),
    (dict(charts=np.array([0, 0, 1, 1])), "charts"),
    (dict(charts=np.array([0, -1, 1])), "charts"),
    # A huge id would size per-chart arrays (found by the fuzz suite: 117 million charts for 8 triangles).
    (dict(charts=np.array([0, 3, 1])), r"chart ids must be in \[0, 3\)"),
    (dict(charts=np.array([0, 7 << 24, 1], ">i4")), r"chart ids must be in \[0, 3\)"),
    (dict(tolerance=-1.0), "tolerance"),
    (dict(subdivision=0), "subdivision"),
    (dict(resolution=4, padding=50.0), "wider than the diagonal of the 4 x 4 atlas"),
    (dict(resolution=4, padding=5.5), "fit"),
])
def test_bad_input_raises_a_clear_value_error(change, message):
    uvs, tris = merge(grid_chart(1, (0, 0), (0.5, 0.5)), grid_chart(1, (0.6, 0.6), (0.9, 0.9)))
    tris = tris[[0, 1, 2]]
    args = dict(charts=np.array([0, 0, 1]), scales=None, resolution=64, padding=2.0, tolerance=1e-5, subdivision=2)
    args.update(change)
    with pytest.raises(ValueError, match=message):
        lmrefine.pack_charts(uvs, tris, args["charts"], args["scales"], args["resolution"], args["padding"],
                             tolerance=args["tolerance"], subdivision=args["subdivision"])


@pytest.mark.parametrize("kind", ["mixed_sizes", "lightmap_pack", "concave"])
def test_a_fixed_scale_places_the_charts_at_that_scale_without_a_search(kind):
    uvs, tris = kinds()[kind]
    _, searched = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0)
    scales = np.random.default_rng(2).uniform(0.9, 1.0, searched["charts"])
    out, report = lmrefine.pack_charts(uvs, tris, searched["chart_ids"], scales, 256, 2.0,
                                       fixed_scale=0.9 * searched["global_scale"])
    assert report["trials"] <= 2  # the footprints, and the boxes where they fail
    assert report["global_scale"] == 0.9 * searched["global_scale"]
    np.testing.assert_allclose(report["chart_scales"], 0.9 * searched["global_scale"] * scales, rtol=1e-12)
    check = lmrefine.check_layout(out, tris, 256, 2.0)
    assert check["valid"] and check["min_gutter_texels"] >= 2.0, check
    # Past the bound (the charts' area would exceed the atlas's) nothing fits.
    with pytest.raises(ValueError, match="do not fit .* at global scale"):
        lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0, fixed_scale=1.01 * searched["scale_bound"])
    # So small that the charts' triangles collapse in float32: said so, with the fix.
    with pytest.raises(ValueError, match="at fixed_scale 1e-30 the charts' triangles collapse to lines"):
        lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0, fixed_scale=1e-30)


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_a_fixed_scale_must_be_a_positive_number(value):
    uvs, tris = grid_chart(1, (0, 0), (0.5, 0.5))
    with pytest.raises(ValueError, match="fixed_scale must be (finite|a finite global scale > 0)"):
        lmrefine.pack_charts(uvs, tris, None, None, 64, 2.0, fixed_scale=value)


def test_a_uv_index_shared_by_two_charts_is_refused():
    uvs, tris = grid_chart(1, (0, 0), (0.5, 0.5))
    with pytest.raises(ValueError, match="UV index"):
        lmrefine.pack_charts(uvs, np.array([[0, 1, 2], [0, 2, 5]]), np.array([0, 1]), None, 64, 2.0)


def test_nan_uvs_and_empty_layouts():
    uvs, tris = grid_chart(1, (0, 0), (0.5, 0.5))
    bad = uvs.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError):
        lmrefine.pack_charts(bad, tris, None, None, 64, 2.0)
    out, report = lmrefine.pack_charts(np.zeros((0, 2), np.float32), np.zeros((0, 3), np.int32), None, None, 64, 2.0)
    assert out.shape == (0, 2) and report["charts"] == 0


def test_progress_reports_and_cancels():
    uvs, tris = kinds()["lightmap_pack"]
    seen = []
    lmrefine.pack_charts(uvs, tris, None, None, 128, 2.0, progress=lambda f, stage: seen.append((f, stage)))
    assert seen and seen[-1][0] == pytest.approx(1.0)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.pack_charts(uvs, tris, None, None, 128, 2.0, progress=lambda f, stage: False)


def reference_first_fit(occupied, chart, padding, first_row=0):
    """The placement rule, plainly: the first (x, y) in scan order (rows,
    then columns, from first_row on) where every covered texel of `chart` is
    inside the atlas and farther than `padding` from every occupied texel,
    measured between texel squares (hypot(max(0, |di| - 1), max(0, |dj| -
    1)), a shared texel always too close); distance exactly `padding` is
    allowed."""
    height, width = occupied.shape
    ch, cw = chart.shape
    taken = np.argwhere(occupied)
    covered = np.argwhere(chart)
    for y in range(first_row, height - ch + 1):
        for x in range(width - cw + 1):
            if len(taken) == 0:
                return x, y
            d = np.abs((covered + (y, x))[:, None, :] - taken[None, :, :])
            gap = np.maximum(d - 1, 0)
            too_close = (gap ** 2).sum(-1) < padding ** 2
            too_close |= (d == 0).all(-1)
            if not too_close.any():
                return x, y
    return None


@pytest.mark.parametrize("seed", range(40))
def test_placement_rule_matches_the_plain_reference(seed):
    rng = np.random.default_rng(seed)
    height, width = rng.integers(6, 26, 2)
    occupied = rng.random((height, width)) < rng.uniform(0.0, 0.08)
    occupied[: rng.integers(0, height // 2)] |= rng.random((1, width)) < 0.5  # a denser top, as packing makes
    chart = rng.random(tuple(rng.integers(1, 6, 2))) < 0.7
    chart[0, 0] |= not chart.any()
    padding = float(rng.choice([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]))
    assert lmrefine._native._first_fit(occupied, chart, padding) == reference_first_fit(occupied, chart, padding)
    # A trial starts a chart's scan at the row where the last chart of its shape went (packer.cpp, shape_ids).
    first_row = int(rng.integers(0, height))
    assert (lmrefine._native._first_fit(occupied, chart, padding, first_row)
            == reference_first_fit(occupied, chart, padding, first_row))


@pytest.mark.parametrize("seed", range(30))
def test_placement_rule_skips_rows_too_short_as_the_reference(seed):
    # Rows with one free run of random length and charts whose rows have
    # different lengths (a triangle's or a lens's): first_fit jumps over the
    # corner rows where some atlas row is too short for its chart row; the
    # placement must still be the plain rule's first one.
    rng = np.random.default_rng(1000 + seed)
    height, width = int(rng.integers(6, 14)), int(rng.integers(6, 16))
    occupied = np.ones((height, width), bool)
    for row in range(height):  # mostly long runs, some short ones
        length = int(rng.integers(0, width + 1)) if rng.random() < 0.35 else width - int(rng.integers(0, 4))
        start = int(rng.integers(0, width - length + 1))
        occupied[row, start:start + length] = False
    rows = int(rng.integers(2, 6))
    chart = np.zeros((rows, 5), bool)
    for row in range(rows):
        length = int(rng.integers(1, 6))
        start = int(rng.integers(0, 6 - length))
        chart[row, start:start + length] = True
    padding = float(rng.choice([0.0, 1.0, 1.5]))
    assert lmrefine._native._first_fit(occupied, chart, padding) == reference_first_fit(occupied, chart, padding)


@pytest.mark.parametrize("seed", range(12))
def test_placement_rule_matches_the_reference_for_tall_sheared_charts(seed):
    # A stretched chart is a sheared band of many rows; first_fit narrows its
    # corners over the rows in a spread order, which must find the same
    # first position as the plain rule.
    rng = np.random.default_rng(2000 + seed)
    height, width = int(rng.integers(24, 34)), int(rng.integers(24, 34))
    occupied = rng.random((height, width)) < rng.uniform(0.01, 0.05)
    rows, thick = int(rng.integers(9, 17)), int(rng.integers(2, 5))
    shear = rng.uniform(0.3, 1.0)
    chart = np.zeros((rows, int(rows * shear) + thick + 1), bool)
    for row in range(rows):
        start = int(row * shear)
        chart[row, start:start + thick] = True
    padding = float(rng.choice([0.0, 1.0, 2.0]))
    assert lmrefine._native._first_fit(occupied, chart, padding) == reference_first_fit(occupied, chart, padding)


def test_placement_rule_reads_any_nonzero_mask_value_as_covered():
    # The kernel's masks hold 0 or 1 (its spans are found with memchr); the
    # hook's masks are the user's, so 255 or 7 is covered as 1 is.
    rng = np.random.default_rng(7)
    occupied = rng.random((16, 18)) < 0.04
    chart = rng.random((3, 4)) < 0.7
    chart[0, 0] = True
    expected = reference_first_fit(occupied, chart, 1.5)
    assert expected is not None
    as_bytes = lambda mask, value: np.where(mask, value, 0).astype(np.uint8)  # noqa: E731
    assert lmrefine._native._first_fit(as_bytes(occupied, 255), as_bytes(chart, 7), 1.5) == expected


def reference_dilation(mask, padding):
    """Every cell closer than `padding` to a covered cell of `mask`,
    measured between texel squares (hypot(max(0, |di| - 1), max(0, |dj| -
    1)), a cell always its own neighbour), plainly: the mask shifted by every
    such offset, on a canvas grown by ceil(padding) on every side."""
    reach = int(np.ceil(padding))
    height, width = mask.shape
    out = np.zeros((height + 2 * reach, width + 2 * reach), bool)
    for di in range(-reach, reach + 1):
        for dj in range(-reach, reach + 1):
            gap = np.hypot(max(0, abs(di) - 1), max(0, abs(dj) - 1))
            if gap ** 2 < padding ** 2 or di == dj == 0:
                out[reach + di:reach + di + height, reach + dj:reach + dj + width] |= mask
    return out


@pytest.mark.parametrize("seed", range(40))
def test_footprints_and_their_dilation_match_the_plain_reference(seed):
    # The kernel builds a footprint's quarter turn and its dilation from row
    # spans (footprint.cpp), not bitmaps: the result must be the mask turned
    # (np.rot90: a quarter counter-clockwise) and the plain dilation of it.
    rng = np.random.default_rng(3000 + seed)
    height, width = (int(n) for n in rng.integers(1, 30, 2))
    mask = rng.random((height, width)) < rng.uniform(0.05, 0.95)  # holes, several spans a row, empty rows
    if seed % 3 == 0:  # a sheared band, as a stretched chart's
        mask = np.zeros((height, width), bool)
        for row in range(height):
            start = int(row * width / (height + 1))
            mask[row, start:start + int(rng.integers(1, 5))] = True
    elif seed % 3 == 1:  # rectangles: runs of equal rows, as Lightmap Pack's faces
        mask = np.zeros((height, width), bool)
        for _ in range(int(rng.integers(1, 4))):
            top, left = int(rng.integers(0, height)), int(rng.integers(0, width))
            mask[top:top + int(rng.integers(1, height + 1)), left:left + int(rng.integers(1, width + 1))] = True
    padding = float(rng.choice([0.0, 0.5, 1.0, 1.5, 2.0, 3.7, 4.0, 6.2]))
    for turned in (False, True):
        covered, dilated = lmrefine._native._footprint_masks(mask, padding, turned)
        expected = np.rot90(mask) if turned else mask
        assert np.array_equal(covered.astype(bool), expected)
        assert np.array_equal(dilated.astype(bool), reference_dilation(expected, padding))


def test_a_triangle_smaller_than_the_tolerance_is_not_collapsed():
    # A sliver whose short edge (5e-6) is below the tolerance, beside a quad
    # sharing its long corner: snapping its two close corners together would
    # make it degenerate.
    quad_uvs, quad_tris = grid_chart(1, (0.2, 0.2), (0.5, 0.5))
    sliver = np.array([[0.5, 0.5], [0.9, 0.2], [0.9 + 5e-6, 0.2]], np.float32)
    uvs = np.concatenate([quad_uvs, sliver])
    tris = np.concatenate([quad_tris, np.array([[len(quad_uvs), len(quad_uvs) + 1, len(quad_uvs) + 2]])]).astype(np.int32)
    assert lmrefine.check_layout(uvs, tris, 256, 2.0)["degenerate"] == 0
    out, report = lmrefine.pack_charts(uvs, tris, None, None, 256, 2.0)
    assert report["charts"] == 1
    check = lmrefine.check_layout(out, tris, 256, 2.0)
    assert check["valid"], check


@pytest.mark.parametrize("uvs", [
    [[0.1, 0.1], [0.6, 0.1], [0.6, 0.1 + 1e-7]],          # a needle: tiny area, long side
    [[0.1, 0.1], [0.6, 0.6], [0.6, 0.6 + 2e-5]],          # a diagonal needle: a huge box at the area bound
    [[0.1, 0.1], [0.6, 0.1], [0.3, 0.1]],                 # collinear: zero area
    [[0.2, 0.2], [0.2, 0.2], [0.2, 0.2]],                 # one point
])
def test_degenerate_charts_do_not_blow_up_the_scale(uvs):
    uvs = np.array(uvs, np.float32)
    square_uvs, square_tris = grid_chart(1, (0.5, 0.5), (0.7, 0.7))
    all_uvs, tris = merge((uvs, np.array([[0, 1, 2]], np.int32)), (square_uvs, square_tris))
    for layout in ((uvs, np.array([[0, 1, 2]], np.int32)), (all_uvs, tris)):
        out, report = lmrefine.pack_charts(*layout, None, None, 64, 2.0)
        assert np.isfinite(report["global_scale"]) and report["global_scale"] > 0
        assert (out >= 0).all() and (out <= 1).all()
        check = lmrefine.check_layout(out, layout[1], 64, 2.0)
        assert check["overlapping"] == 0 and check["min_gutter_texels"] >= 2.0


def random_soup(rng):
    """Grid charts, loose triangles and fans (star-shaped, concave) anywhere
    in [-1, 1]^2, overlapping; every other seed with shared UV indices."""
    parts = []
    for _ in range(rng.integers(1, 60)):
        kind = rng.integers(0, 3)
        if kind == 0:
            lo = rng.uniform(-1, 1, 2)
            parts.append(grid_chart(int(rng.integers(1, 4)), lo, lo + rng.uniform(1e-4, 0.5, 2)))
        elif kind == 1:
            parts.append((rng.uniform(-1, 1, (3, 2)).astype(np.float32), np.array([[0, 1, 2]], np.int32)))
        else:
            centre, k = rng.uniform(0, 1, 2), int(rng.integers(3, 9))
            angles, radii = np.sort(rng.uniform(0, 2 * np.pi, k)), rng.uniform(0.01, 0.2, k)
            rim = np.c_[centre[0] + radii * np.cos(angles), centre[1] + radii * np.sin(angles)]
            fan = np.array([p for i in range(k) for p in (centre, rim[i], rim[(i + 1) % k])], np.float32)
            parts.append((fan, np.arange(3 * k, dtype=np.int32).reshape(-1, 3)))
    return merge(*parts)


@pytest.mark.parametrize("seed", range(30))
def test_random_layouts_scales_and_settings_stay_valid(seed):
    rng = np.random.default_rng(seed)
    uvs, tris = random_soup(rng)
    if seed % 2:
        keys, inverse = np.unique(uvs, axis=0, return_inverse=True)
        uvs, tris = keys.astype(np.float32), inverse.reshape(-1).astype(np.int32)[tris]
    resolution = (int(rng.integers(16, 300)), int(rng.integers(16, 300)))
    padding = float(rng.choice([0.0, 0.5, 1.0, 2.0, 3.7]))
    charts = lmrefine.find_charts(uvs, tris, tolerance=lmrefine.CHART_TOLERANCE)
    scales = rng.uniform(0.2, 3.0, charts.max() + 1)
    try:
        out, report = lmrefine.pack_charts(uvs, tris, charts, scales, resolution, padding,
                                           rotations=bool(rng.integers(0, 2)), subdivision=int(rng.integers(1, 4)))
    except ValueError as error:
        assert "do not fit" in str(error)
        return
    check = lmrefine.check_layout(out, tris, resolution, padding)
    before = lmrefine.check_layout(uvs, tris, resolution, padding)
    # charts move rigidly: overlaps inside a chart (folds, stacked faces) stay, none is added between charts
    assert check["overlapping"] <= before["overlapping"] and check["out_of_bounds"] == 0
    if before["overlapping"] == 0:
        assert check["min_gutter_texels"] >= padding
    assert check["degenerate"] <= before["degenerate"]
    np.testing.assert_allclose(report["chart_scales"], report["global_scale"] * scales)


def test_charts_that_fit_only_collapsed_are_refused():
    """Absurd scale ratios would pack a chart at 1e-30 of its size: a line, not a chart."""
    from layouts import grid_chart, merge
    uvs, tris = merge(grid_chart(2, (0.1, 0.1), (0.4, 0.4)), grid_chart(2, (0.6, 0.6), (0.9, 0.9)))
    charts = lmrefine.find_charts(uvs, tris)
    with pytest.raises(ValueError, match="collapse to lines"):
        lmrefine.pack_charts(uvs, tris, charts, np.array([1.0, 1e-30]), 64, 2.0)


def test_a_padding_wider_than_the_atlas_is_refused_at_once():
    uvs, tris = merge(grid_chart(1, (0.1, 0.1), (0.4, 0.4)), grid_chart(1, (0.6, 0.6), (0.9, 0.9)))
    with pytest.raises(ValueError, match="wider than the diagonal of the 64 x 64 atlas"):
        lmrefine.pack_charts(uvs, tris, None, None, 64, padding=3000.0)
    lmrefine.pack_charts(uvs, tris, None, None, 64, padding=8.0)  # a wide gutter that fits
