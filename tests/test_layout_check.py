"""check_layout: flips, degenerate and overlapping triangles, out-of-bounds
UVs and the gutter between charts, at a lightmap resolution."""

import numpy as np
import pytest

import lmrefine
from layouts import grid_chart, lightmap_pack, merge, plane, smart_uv

R = 64


def square(x0, y0, size, n=1):
    return grid_chart(n, (x0, y0), (x0 + size, y0 + size))


def test_a_clean_plane_is_valid():
    uvs, tris = plane(16)
    report = lmrefine.check_layout(uvs, tris, R)
    assert report == {"flipped": 0, "degenerate": 0, "overlapping": 0, "out_of_bounds": 0,
                      "min_gutter_texels": float("inf"), "charts": 1, "valid": True}


def test_gutter_is_the_exact_distance_between_charts_in_texels():
    uvs, tris = merge(square(0.1, 0.1, 0.3, n=3), square(0.4 + 3 / R, 0.1, 0.3, n=2))
    report = lmrefine.check_layout(uvs, tris, R, padding=2)
    assert report["charts"] == 2
    assert report["min_gutter_texels"] == pytest.approx(3.0, abs=1e-4)
    assert report["valid"]
    assert not lmrefine.check_layout(uvs, tris, R, padding=4)["valid"]
    # Rectangular lightmaps measure each axis in its own texels.
    assert lmrefine.check_layout(uvs, tris, (R, 2 * R))["min_gutter_texels"] == pytest.approx(6.0, abs=1e-4)



def test_a_chart_off_by_rounding_is_one_chart_with_the_tolerance():
    # A plane whose second half is off by 2e-7 (Blender's layouts are not
    # bit-exact): bit-exact joining reads two touching charts (gutter 0).
    uvs, tris = plane(8)
    noisy = uvs.copy()
    noisy[len(uvs) // 2:] += np.float32(2e-7)
    exact = lmrefine.check_layout(noisy, tris, R)
    assert exact["charts"] > 1 and not exact["valid"]
    joined = lmrefine.check_layout(noisy, tris, R, tolerance=lmrefine.CHART_TOLERANCE)
    assert joined["charts"] == 1 and joined["valid"]
    # Charts farther apart than the tolerance stay apart.
    uvs, tris = merge(square(0.1, 0.1, 0.3), square(0.4 + 3 / R, 0.1, 0.3))
    assert lmrefine.check_layout(uvs, tris, R, tolerance=lmrefine.CHART_TOLERANCE)["charts"] == 2
    with pytest.raises(ValueError, match="tolerance"):
        lmrefine.check_layout(uvs, tris, R, tolerance=-1.0)

def test_far_apart_charts_report_their_true_gutter():
    uvs, tris = merge(square(0.0, 0.0, 0.1), square(0.8, 0.8, 0.1))
    gap = np.hypot(0.7, 0.7) * R
    assert lmrefine.check_layout(uvs, tris, R)["min_gutter_texels"] == pytest.approx(gap, rel=1e-5)


def test_overlapping_charts_are_counted_touching_ones_are_not():
    uvs, tris = merge(square(0.1, 0.1, 0.3), square(0.3, 0.3, 0.3))
    report = lmrefine.check_layout(uvs, tris, R)
    assert report["overlapping"] == 4 and not report["valid"]
    assert report["min_gutter_texels"] == 0
    touching = merge(square(0.1, 0.1, 0.3), square(0.4 + 1e-7, 0.1, 0.3))
    report = lmrefine.check_layout(*touching, R, padding=0)
    assert report["overlapping"] == 0
    assert report["min_gutter_texels"] < 1e-3


def test_a_chart_inside_another_overlaps():
    uvs, tris = merge(square(0.1, 0.1, 0.6, n=4), square(0.3, 0.3, 0.05))
    assert lmrefine.check_layout(uvs, tris, R)["overlapping"] == 2 + 2 * 1  # the small chart and what it lies on


def test_stacked_faces_all_overlap_whatever_the_stack_depth():
    # A texture map taken for a lightmap: faces stacked on one square, each its own chart (UV indices
    # of its own) or all one chart (shared UV indices); the squares elsewhere overlap nothing. Each
    # stacked triangle is found once a partner is: the same triangles as testing every pair.
    own = merge(*[square(0.1, 0.1, 0.3) for _ in range(30)])
    shared_uvs, shared_tris = square(0.6, 0.1, 0.3)
    shared = (shared_uvs, np.concatenate([shared_tris] * 30))
    apart = merge(*[square(0.1 + 0.2 * k, 0.6, 0.1) for k in range(4)])
    uvs, tris = merge(own, shared, apart)
    report = lmrefine.check_layout(uvs, tris, R)
    assert report["overlapping"] == 60 + 60 and not report["valid"]
    assert lmrefine.check_layout(*apart, R)["overlapping"] == 0


def _stack(count):
    """`count` quads over the whole square with UV indices of their own (a texture map's faces)."""
    uvs = np.tile(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32), (count, 1))
    quads = np.arange(count)[:, None] * 4
    return uvs, np.concatenate([quads + [0, 1, 2], quads + [0, 2, 3]]).astype(np.int32)


def test_a_deep_stack_at_a_high_resolution_is_refused_before_allocating():
    # A (texel, triangle) pair per stacked face and texel: 1,000 quads at 16384^2 need terabytes,
    # and failed with a bare MemoryError (or the OOM killer) part way (found by a crash hunt).
    uvs, tris = _stack(1000)
    message = (r"checking the layout at 16384x16384 \(its faces are stacked, at least 99\d deep on average\) needs "
               r"about \d+\.\d\d GiB of memory, more than half of this machine's \d+\.\d\d GiB; give the faces their "
               r"own places in the map \(a lightmap layout: Lightmap Pack or Smart UV Project\), fewer stacked "
               r"faces, or a lower resolution")
    with pytest.raises(MemoryError, match=message):
        lmrefine.check_layout(uvs, tris, 16384)
    checker = lmrefine.LayoutChecker(uvs, tris, 16384, 2.0)
    with pytest.raises(MemoryError, match=message):
        checker.check()
    with pytest.raises(MemoryError, match=message):
        checker.check(uvs * np.float32(0.999))
    # The estimate is a floor, measured without the raster: a shallow stack is still checked.
    assert lmrefine.check_layout(*_stack(3), 512)["overlapping"] == 6


def test_a_raster_of_stacked_rows_past_memory_is_refused_before_allocating():
    # A span per triangle and row: 500,000 triangles over 16384 rows.
    uvs = np.array([[0, 0], [1, 0], [0, 1]], np.float32)
    tris = np.zeros((500000, 3), np.int32) + [0, 1, 2]
    with pytest.raises(MemoryError, match=r"rasterizing 500000 triangles at 16384x16384 \(8192000000 triangle rows\) "
                                          r"needs about \d+\.\d\d GiB of memory, .*; give stacked faces their own "
                                          r"places in the map, use fewer triangles, or a lower resolution"):
        lmrefine.coverage_mask(uvs, tris, 16384)


def test_flips_against_the_chart_majority_and_against_a_reference():
    uvs, tris = plane(4)
    one_flipped = tris.copy()
    one_flipped[5] = one_flipped[5][[0, 2, 1]]
    assert lmrefine.check_layout(uvs, one_flipped, R)["flipped"] == 1
    mirrored = uvs.copy()
    mirrored[:, 0] = 1 - mirrored[:, 0]  # a wholly mirrored chart is consistent ...
    assert lmrefine.check_layout(mirrored, tris, R)["flipped"] == 0
    # ... but every triangle turned over relative to the original.
    assert lmrefine.check_layout(mirrored, tris, R, reference_uvs=uvs)["flipped"] == len(tris)


def test_degenerate_and_out_of_bounds():
    uvs, tris = plane(4)
    uvs = uvs.copy()
    uvs[tris[3, 2]] = 0.5 * (uvs[tris[3, 0]] + uvs[tris[3, 1]])  # collinear corners
    uvs[0] = (-0.01, 0.5)
    uvs[1] = (0.5, 1.01)
    report = lmrefine.check_layout(uvs, tris, R)
    assert report["degenerate"] == 1
    assert report["out_of_bounds"] == 2
    assert not report["valid"]


@pytest.mark.parametrize("layout", [lightmap_pack(charts_across=16, margin_texels=2, resolution=256),
                                    smart_uv(256, margin_texels=4)])
def test_packed_layouts_keep_their_margin(layout):
    report = lmrefine.check_layout(*layout, 256, padding=2)
    assert report["valid"]
    assert report["min_gutter_texels"] >= 2


def test_bad_input_raises_value_errors():
    uvs, tris = plane(2)
    with pytest.raises(ValueError, match="resolution"):
        lmrefine.check_layout(uvs, tris, 0)
    with pytest.raises(ValueError, match="refers to UV"):
        lmrefine.check_layout(uvs, tris + len(uvs), R)
    bad = uvs.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        lmrefine.check_layout(bad, tris, R)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        lmrefine.check_layout(uvs[:, :1], tris, R)
    with pytest.raises(ValueError, match="reference_uvs"):
        lmrefine.check_layout(uvs, tris, R, reference_uvs=uvs[:-1])


def test_failing_charts_names_the_charts_to_fix():
    uvs, tris = merge(square(0.1, 0.1, 0.2), square(0.3 + 1 / R, 0.1, 0.2),  # 1 texel apart
                      square(0.7, 0.7, 0.2), square(0.75, 0.75, 0.1))        # overlapping
    report = lmrefine.check_layout(uvs, tris, R, padding=2, failing_charts=True)
    np.testing.assert_array_equal(report["failing_charts"], [0, 1, 2, 3])
    np.testing.assert_array_equal(report["overlapping_charts"], [2, 3])  # the close pair fails on its gutter only
    report = lmrefine.check_layout(uvs, tris, R, padding=0.5, failing_charts=True)
    np.testing.assert_array_equal(report["failing_charts"], [2, 3])
    assert "failing_charts" not in lmrefine.check_layout(uvs, tris, R)
    assert "overlapping_charts" not in lmrefine.check_layout(uvs, tris, R)


def test_relative_gutter_judges_each_chart_pair_against_its_original_distance():
    # Charts 0-1 packed 1.5 texels apart, 1-2 5 texels apart; padding 2.
    R = 64
    def layout(gap01, gap12):
        return merge(grid_chart(2, (0.1, 0.4), (0.3, 0.6)),
                     grid_chart(2, (0.3 + gap01 / R, 0.4), (0.5, 0.6)),
                     grid_chart(2, (0.5 + gap12 / R, 0.4), (0.7, 0.6)))
    reference, tris = layout(1.5, 5.0)
    def check(gap01, gap12):
        uvs, _ = layout(gap01, gap12)
        return lmrefine.check_layout(uvs, tris, R, 2, reference_uvs=reference, relative_gutter=True,
                                     failing_charts=True)
    kept = check(1.5, 2.5)  # the tight pair kept its gutter, the wide one stays above the padding
    assert kept["gutter_violations"] == 0 and list(kept["failing_charts"]) == []
    assert not kept["valid"]  # valid stays absolute: 1.5 < padding
    tighter = check(1.3, 5.0)  # the tight pair got tighter
    assert tighter["gutter_violations"] == 1 and list(tighter["failing_charts"]) == [0, 1]
    thinned = check(1.5, 1.8)  # the wide pair fell below the padding
    assert thinned["gutter_violations"] == 1 and list(thinned["failing_charts"]) == [1, 2]
    assert "gutter_violations" not in lmrefine.check_layout(reference, tris, R, 2)
    with pytest.raises(ValueError, match="reference_uvs"):
        lmrefine.check_layout(reference, tris, R, 2, relative_gutter=True)


def test_gutter_texels_mark_the_texels_between_charts():
    R = 32
    uvs, tris = merge(grid_chart(2, (0.0, 0.0), (0.5, 1.0)), grid_chart(2, (0.5 + 0.4 / R, 0.0), (1.0, 1.0)))
    gutter = lmrefine._native.gutter_texels(uvs, tris, R)
    # No uncovered texel between the charts (0.4 texel apart): the texels on
    # both sides of the seam still are gutter, the rest of each chart not.
    assert lmrefine.coverage_mask(uvs, tris, R).all()
    assert gutter[:, 15:17].all() and not gutter[:, :14].any() and not gutter[:, 18:].any()


def _same_report(a, b):
    assert a.keys() == b.keys()
    for key in a:
        if key in ("failing_charts", "overlapping_charts"):
            np.testing.assert_array_equal(a[key], b[key])
        else:
            assert a[key] == b[key], key


@pytest.mark.parametrize("name", ["pack", "smart", "overlapping", "degenerate"])
def test_layout_checker_gives_what_the_single_calls_give(name, rng):
    # The refiner's LayoutChecker analyses the original once; every result
    # must equal check_layout / coverage_mask / gutter_texels / find_charts.
    if name == "pack":
        uvs, tris = lightmap_pack(8, margin_texels=1.5, resolution=R, quads=2)
    elif name == "smart":
        uvs, tris = smart_uv(R, margin_texels=3, n=6)
    elif name == "overlapping":
        uvs, tris = merge(square(0.1, 0.1, 0.3, n=3), square(0.35, 0.3, 0.3, n=2), square(0.7, 0.1, 0.2))
    else:
        uvs, tris = merge(square(0.1, 0.1, 0.3, n=3), square(0.5, 0.5, 0.3, n=2))
        uvs[tris[4, 2]] = uvs[tris[4, 1]]  # one triangle of zero area
    checker = lmrefine.LayoutChecker(uvs, tris, R, 2)
    np.testing.assert_array_equal(checker.charts, lmrefine.find_charts(uvs, tris))
    np.testing.assert_array_equal(checker.coverage_mask(), lmrefine.coverage_mask(uvs, tris, R))
    np.testing.assert_array_equal(checker.gutter_texels(), lmrefine._native.gutter_texels(uvs, tris, R))
    for failing in (False, True):
        _same_report(checker.check(failing_charts=failing),
                     lmrefine.check_layout(uvs, tris, R, 2, failing_charts=failing))
    # Warped versions: a smooth shift (gutters change), and one that flips
    # and overlaps triangles.
    shift = 0.02 * np.sin(uvs * 7.0).astype(np.float32)
    swapped = uvs.copy()
    swapped[tris[:3, 1]], swapped[tris[:3, 2]] = uvs[tris[:3, 2]], uvs[tris[:3, 1]]
    for warped in (np.clip(uvs + shift, 0, 1), swapped):
        for failing in (False, True):
            for relative in (False, True):
                _same_report(checker.check(warped, failing_charts=failing, relative_gutter=relative),
                             lmrefine.check_layout(warped, tris, R, 2, reference_uvs=uvs, failing_charts=failing,
                                                   relative_gutter=relative))
    report = checker.check(swapped, failing_charts=True)
    assert report["flipped"] >= 3 and 0 in report["failing_charts"]
    if name == "overlapping":
        assert checker.check()["overlapping"] > 0
    if name == "degenerate":
        assert checker.check()["degenerate"] == 1


def test_layout_checker_bad_input():
    uvs, tris = plane(4)
    with pytest.raises(ValueError, match="padding"):
        lmrefine.LayoutChecker(uvs, tris, R, -1)
    with pytest.raises(ValueError, match="positive"):
        lmrefine.LayoutChecker(uvs, tris, 0)
    with pytest.raises(ValueError, match="refers to UV"):
        lmrefine.LayoutChecker(uvs, tris + 1, R)
    checker = lmrefine.LayoutChecker(uvs, tris, R)
    with pytest.raises(ValueError, match="same layout"):
        checker.check(uvs[:-3])
    with pytest.raises(ValueError, match="relative_gutter"):
        checker.check(relative_gutter=True)
    bad = uvs.copy()
    bad[5, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        checker.check(bad)
