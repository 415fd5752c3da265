"""The rules the Blender add-on applies to a user's UV layout, with plain
arrays (lmrefine.layout_input, lmrefine.backoff.failures)."""

import numpy as np
import pytest

import lmrefine
from lmrefine import backoff, layout_input


def test_corners_of_one_vertex_within_the_connect_limit_get_one_uv():
    uvs = np.array([[0.5, 0.5], [0.50005, 0.49996], [0.5003, 0.5], [0.50002, 0.5]], np.float32)
    vertex = np.array([7, 7, 7, 3])
    before = uvs.copy()
    welded = layout_input.weld_uvs(uvs, vertex)
    np.testing.assert_array_equal(uvs, before)  # the input is untouched
    assert welded[0].tolist() == welded[1].tolist() == uvs[0].tolist()  # the group's leader: lowest u
    assert welded[2].tolist() == uvs[2].tolist()  # 3e-4 away: its own UV
    assert welded[3].tolist() == uvs[3].tolist()  # another vertex: never joined


def test_uvs_a_rounding_error_outside_the_unit_square_are_clamped_others_are_not():
    uvs = np.array([[-5e-5, 1.00005], [-2e-4, 1.0002], [0.25, 0.75]], np.float64)
    welded = layout_input.weld_uvs(uvs, np.arange(3))
    assert welded.tolist() == [[0.0, 1.0], [-2e-4, 1.0002], [0.25, 0.75]]


def test_welding_joins_a_chart_that_rounding_split():
    # Two triangles of one quad whose shared corners differ in the last bits.
    uvs = np.array([[0, 0], [0.5, 0], [0.5, 0.5], [1e-6, 0], [0.5, 0.5 + 1e-6], [0, 0.5]], np.float32)
    triangles = np.arange(6, dtype=np.int32).reshape(2, 3)
    vertex = np.array([0, 1, 2, 0, 2, 3])
    assert lmrefine.find_charts(uvs, triangles).tolist() == [0, 1]
    assert lmrefine.find_charts(layout_input.weld_uvs(uvs, vertex), triangles).tolist() == [0, 0]


def test_weld_names_a_bad_argument():
    with pytest.raises(ValueError, match="corner_vertex"):
        layout_input.weld_uvs(np.zeros((4, 2)), np.zeros(3, int))
    with pytest.raises(ValueError, match=r"\(L, 2\)"):
        layout_input.weld_uvs(np.zeros((4, 3)), np.zeros(4, int))


def test_geometry_problems_counts_flat_triangles_zero_uv_triangles_and_broken_vertices():
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0],    # a real triangle
                          [2, 0, 0], [3, 0, 0], [4, 0, 0],    # collinear: zero area in 3-D
                          [np.nan, 0, 0], [0, 2e9, 0]], float)
    uvs = np.array([[0, 0], [1, 0], [0, 1],              # half the map
                    [0, 0], [1e-3, 0], [0, 1e-3],         # 0.5e-6 of the map: 0.033 texels at 256
                    [0, 0], [1e-6, 0], [0, 1e-6]],        # 0.5e-12: 3e-8 texels
                   np.float32)
    triangles = np.arange(9).reshape(3, 3)
    # Corners 6..8 put the tiny UV triangle on the real 3-D triangle: it has no texel of its own.
    corner_vertex = np.array([0, 1, 2, 3, 4, 5, 0, 1, 2])
    assert layout_input.geometry_problems(positions, corner_vertex, uvs, triangles, 256) == (1, 1, 2)
    # The same tiny UV triangle on the collinear corners needs no texels: only counted as flat.
    corner_vertex = np.array([0, 1, 2, 0, 1, 2, 3, 4, 5])
    assert layout_input.geometry_problems(positions, corner_vertex, uvs, triangles, 256) == (1, 0, 2)
    # At 64 texels the second triangle is 0.002 texels: still not zero.
    assert layout_input.geometry_problems(positions[:3], corner_vertex[:6] % 3, uvs[:6], triangles[:2], 64) == (0, 0, 0)


def test_describe_problems_in_words():
    check = {"flipped": 2, "degenerate": 0, "overlapping": 1, "out_of_bounds": 0, "min_gutter_texels": 1.5}
    assert layout_input.describe_problems(check, 2) == ("2 flipped triangles, 1 overlapping triangle, "
                                                        "charts 1.50 texels apart where the padding asks for 2")
    every = dict(check, flipped=1, degenerate=3, overlapping=2, out_of_bounds=1, min_gutter_texels=0.0)
    assert layout_input.describe_problems(every, 2.5) == (
        "1 flipped triangle, 3 triangles without area, 2 overlapping triangles, 1 UV outside the map, "
        "charts 0.00 texels apart where the padding asks for 2.5")
    assert layout_input.describe_problems(dict(every, degenerate=1, out_of_bounds=4), 8.0).startswith(
        "1 flipped triangle, 1 triangle without area, 2 overlapping triangles, 4 UVs outside the map, charts 0.00 "
        "texels apart where the padding asks for 8")
    assert layout_input.describe_problems(dict(check, flipped=0, overlapping=0), 1) == ""
    assert layout_input.describe_problems(dict(check, flipped=0, overlapping=0, min_gutter_texels=np.inf), 2) == ""


ORIGINAL = {"flipped": 0, "degenerate": 1, "overlapping": 0, "out_of_bounds": 0, "min_gutter_texels": 1.5}


@pytest.mark.parametrize("change, failed", [
    ({}, []),
    ({"flipped": 1}, ["flipped"]),
    ({"degenerate": 1}, []),                      # as degenerate as the original: allowed
    ({"degenerate": 2}, ["degenerate"]),
    ({"overlapping": 3}, ["overlapping"]),
    ({"out_of_bounds": 1}, ["out_of_bounds"]),
    ({"min_gutter_texels": 1.49995}, []),        # the original's 1.5, less 1e-4 of float32 rounding
    ({"min_gutter_texels": 1.4998}, ["gutter"]),
    ({"gutter_violations": 0, "min_gutter_texels": 0.5}, []),   # per pair: no pair got closer
    ({"gutter_violations": 2}, ["gutter"]),
])
def test_a_refined_layout_fails_exactly_where_it_is_worse_than_its_source(change, failed):
    report = dict(ORIGINAL, **change)
    assert backoff.failures(report, ORIGINAL, padding=2) == failed


def test_the_gutter_allowed_is_the_padding_unless_the_original_was_tighter():
    assert backoff.allowed_gutter(2, {"min_gutter_texels": 5.0}) == pytest.approx(2 - 1e-4)
    assert backoff.allowed_gutter(2, {"min_gutter_texels": 1.5}) == pytest.approx(1.5 - 1e-4)


def _cube(offset=(0.0, 0.0, 0.0), first=0):
    """A unit cube's 8 vertices and 12 outward-wound triangles (vertex indices from `first`)."""
    positions = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float) + offset
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return positions, np.array(triangles) + first


def _signed_volume(positions, triangles):  # the plain rule, for the fixture's own check
    p = positions[triangles]
    return sum(np.dot(a, np.cross(b, c)) for a, b, c in p) / 6.0


def test_a_closed_mesh_wound_inward_is_inside_out_an_open_or_outward_one_is_not():
    positions, triangles = _cube()
    assert _signed_volume(positions, triangles) == pytest.approx(1.0)  # the fixture winds outward
    assert layout_input.inside_out_shells(positions, triangles) == (0, 1)
    assert layout_input.inside_out_shells(positions, triangles[:, ::-1]) == (1, 1)
    # One face gone: open, not judged either way.
    assert layout_input.inside_out_shells(positions, triangles[2:][:, ::-1]) == (0, 0)
    # One face flipped on its own: not consistently wound, so not judged.
    mixed = triangles.copy()
    mixed[:2] = mixed[:2, ::-1]
    assert layout_input.inside_out_shells(positions, mixed) == (0, 0)


def test_inside_out_is_judged_per_shell_far_from_the_origin_too():
    a, ta = _cube((1e6, 1e6, 0.0))
    b, tb = _cube((3e6, 0.0, 5.0), first=8)
    positions = np.concatenate([a, b])
    triangles = np.concatenate([ta, tb[:, ::-1]])  # the second cube inside out
    assert layout_input.inside_out_shells(positions, triangles) == (1, 2)
    # A quad doubled back to back (each side its own diagonal) is closed but has no inside: not judged.
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    doubled = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
    assert layout_input.inside_out_shells(quad, doubled) == (0, 1)
    assert layout_input.inside_out_shells(np.zeros((0, 3)), np.zeros((0, 3), int)) == (0, 0)


def test_charts_copied_onto_each_other_by_modifiers_are_told_from_the_source_layouts_own_overlaps():
    quad = np.array([[0.1, 0.1], [0.5, 0.1], [0.5, 0.5], [0.1, 0.5], [0.6, 0.6], [0.9, 0.6], [0.9, 0.9]], np.float32)
    source = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]])
    source_check = lmrefine.check_layout(quad, source, 64)
    # An Array modifier's three copies: the same UVs three times.
    copies = np.concatenate([source + 7 * k for k in range(3)])
    copied_check = lmrefine.check_layout(np.tile(quad, (3, 1)), copies, 64)
    assert source_check["overlapping"] == 0 and copied_check["overlapping"] == 9
    assert layout_input.copied_overlap(source_check, 3, copied_check, 9) == 9
    # A source that overlaps by itself keeps its share after a modifier that copies nothing.
    assert layout_input.copied_overlap({"overlapping": 2}, 10, {"overlapping": 8}, 40) == 0
    assert layout_input.copied_overlap({"overlapping": 2}, 10, {"overlapping": 30}, 40) == 22
    assert layout_input.copied_overlap(source_check, 3, {"overlapping": 0}, 0) == 0
