"""Atlas groups without Blender: which objects share one atlas (lmrefine.scene_export.atlas_groups) and
how the add-on joins their layouts and merges their bakes into one map (addon/lmrefine_blender/atlas.py,
loaded on its own: it needs no bpy)."""

import importlib.util
import os
from types import SimpleNamespace

import numpy as np
import pytest

import lmrefine
from lmrefine.scene_export import atlas_groups, overlap

REPO = os.path.normpath(os.path.join(os.path.dirname(__file__), ".."))
_spec = importlib.util.spec_from_file_location("lmrefine_blender_atlas",
                                               os.path.join(REPO, "addon", "lmrefine_blender", "atlas.py"))
atlas = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(atlas)


def square(u0, v0, u1, v1):
    """A quad chart (two triangles) over the UV rectangle."""
    uvs = np.array([(u0, v0), (u1, v0), (u1, v1), (u0, v1)], np.float32)
    return uvs, np.array([(0, 1, 2), (0, 2, 3)], np.int32)


def target(name, layout):
    uvs, triangles = layout
    return SimpleNamespace(obj=SimpleNamespace(name=name), layout=SimpleNamespace(uvs=uvs, triangles=triangles))


def test_side_by_side_layouts_share_an_atlas_and_overlapping_ones_do_not():
    left, right = square(0.05, 0.05, 0.45, 0.95), square(0.55, 0.05, 0.95, 0.95)
    whole = square(0.05, 0.05, 0.95, 0.95)
    assert atlas_groups([left, right]) == [[0, 1]]
    # Each laid out on its own lightmap (filling the square): one group each.
    assert atlas_groups([whole, square(0.1, 0.1, 0.9, 0.9)]) == [[0], [1]]
    # Greedy in the given order: 'whole' overlaps both halves, which still go together.
    assert atlas_groups([left, whole, right]) == [[0, 2], [1]]
    assert atlas_groups([whole, left, right]) == [[0], [1, 2]]


def test_charts_that_merely_touch_still_share_an_atlas():
    left, right = square(0.05, 0.05, 0.502, 0.95), square(0.5, 0.05, 0.95, 0.95)  # half a texel of overlap
    masks = [lmrefine.coverage_mask(uvs, triangles, 256) for uvs, triangles in (left, right)]
    assert np.count_nonzero(masks[0] & masks[1]) == np.count_nonzero(masks[0][:, 128])  # one shared column
    assert not overlap(*masks) and atlas_groups([left, right]) == [[0, 1]]
    # A real overlap (a tenth of each) is one.
    assert atlas_groups([left, square(0.45, 0.05, 0.95, 0.95)]) == [[0], [1]]


def test_an_empty_layout_overlaps_nothing():
    empty = (np.zeros((0, 2), np.float32), np.zeros((0, 3), np.int32))
    assert atlas_groups([square(0.1, 0.1, 0.9, 0.9), empty]) == [[0, 1]]


def groups_reference(layouts, resolution):
    """Plain reference of atlas_groups: greedy, every pair of masks compared with `overlap`."""
    masks = [lmrefine.coverage_mask(uvs, triangles, resolution) if len(triangles) else None
             for uvs, triangles in layouts]
    groups = []
    for index, mask in enumerate(masks):
        home = next((group for group in groups if not any(overlap(mask, masks[other]) for other in group)), None)
        if home is None:
            groups.append([index])
        else:
            home.append(index)
    return groups


@pytest.mark.parametrize("seed", range(6))
def test_grouping_equals_the_pairwise_reference_on_random_atlases(seed):
    """Random rectangles: some side by side in a grid of cells (one atlas), some filling most of the
    square (a lightmap of their own), some straddling two cells."""
    rng = np.random.default_rng(seed)
    layouts = []
    for _ in range(14):
        kind = rng.integers(3)
        if kind == 0:
            cell = rng.integers(4, size=2) / 4.0
            layouts.append(square(*(cell + 0.02), *(cell + 0.23)))
        elif kind == 1:
            layouts.append(square(*rng.uniform(0.0, 0.1, 2), *rng.uniform(0.9, 1.0, 2)))
        else:
            low = rng.uniform(0.0, 0.7, 2)
            layouts.append(square(*low, *(low + rng.uniform(0.05, 0.3, 2))))
    assert atlas_groups(layouts, 64) == groups_reference(layouts, 64)


def test_groups_are_named_after_their_largest_member_and_sorted_by_name():
    targets = [target("Wall", square(0.55, 0.05, 0.95, 0.3)), target("Ground", square(0.05, 0.05, 0.5, 0.95)),
               target("Crate", square(0.55, 0.4, 0.7, 0.55)), target("Solo", square(0.05, 0.05, 0.95, 0.95))]
    groups = atlas.group_targets(targets, 64)
    assert [(group.name, group.objects) for group in groups] == [
        ("Ground_atlas", ["Crate", "Ground", "Wall"]), ("Solo", ["Solo"])]
    assert [group.name for group in atlas.group_targets(targets, 64, shared=False)] == [
        "Wall", "Ground", "Crate", "Solo"]


def test_group_names_never_collide_with_an_object_named_like_an_atlas():
    targets = [target("Ground", square(0.05, 0.05, 0.5, 0.95)), target("Crate", square(0.55, 0.05, 0.95, 0.5)),
               target("Ground_atlas", square(0.05, 0.05, 0.95, 0.95))]
    assert [group.name for group in atlas.group_targets(targets, 64)] == ["Ground_atlas_2", "Ground_atlas"]


def test_join_and_split_round_trip_with_offset_triangles():
    targets = [target("A", square(0.1, 0.1, 0.4, 0.4)), target("B", square(0.6, 0.6, 0.9, 0.9))]
    [group] = atlas.group_targets(targets, 64)
    uvs, triangles = group.join()
    assert uvs.shape == (8, 2) and triangles.tolist() == [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]
    parts = group.split(uvs + 1.0)
    np.testing.assert_array_equal(parts["B"], targets[1].layout.uvs + 1.0)
    np.testing.assert_array_equal(parts["A"], targets[0].layout.uvs + 1.0)


def test_merge_takes_each_covered_texel_from_its_object_and_fills_the_gutter_from_the_joined_charts():
    rng = np.random.default_rng(3)
    resolution = 24
    layouts = [square(0.1, 0.1, 0.45, 0.9), square(0.6, 0.1, 0.9, 0.4), square(0.6, 0.6, 0.9, 0.9)]
    uvs, triangles, _, rows = atlas.join_layouts(layouts)
    masks = [lmrefine.coverage_mask(uvs, triangles[r], resolution) for r in rows]
    maps = [rng.random((resolution, resolution, 4), dtype=np.float32) for _ in layouts]
    copies = [image.copy() for image in maps]
    for margin in (1, 16):
        merged = atlas.merge_maps(maps, masks, uvs, triangles, margin)
        covered = np.zeros_like(masks[0])
        composed = np.zeros_like(maps[0])
        for image, mask in zip(maps, masks):
            composed[mask & ~covered] = image[mask & ~covered]
            covered |= mask
        np.testing.assert_array_equal(merged, lmrefine.dilate(composed, uvs, triangles, margin))
        for image, mask in zip(maps, masks):
            np.testing.assert_array_equal(merged[mask], image[mask])
        if margin == 1:
            assert not merged[0, 0].any() and not merged[-1, -1].any()  # two rings out
    for image, copy in zip(maps, copies):
        np.testing.assert_array_equal(image, copy)  # the inputs are not modified


@pytest.mark.parametrize("resolution", [16, 64])
def test_merged_per_object_bakes_equal_the_bakers_own_atlas_bake(resolution):
    """The Embree baker's atlas=True bakes every receiver into one map; merging its per-object maps
    gives the same light on the charts and the same gutter, also where the two objects' charts are
    two texels apart (a gutter texel between them from the chart nearest it)."""
    scene = lmrefine.Scene()
    squares = [square(0.05, 0.05, 0.47, 0.95), square(0.47 + 2.05 / resolution, 0.05, 0.95, 0.95)]
    for index, (uvs, triangles) in enumerate(squares):
        x = float(index) * 1.2
        positions = np.array([(x, 0, 0), (x + 1, 0, 0), (x + 1, 1, 0), (x, 1, 0)], np.float32)
        scene.add_mesh(positions, triangles, uvs=uvs[triangles.ravel()], receiver=True)
    scene.add_light("sun", energy=2.0, matrix=np.eye(4).tolist())
    own = lmrefine.bake(scene, resolution, samples=4, seed=1)
    shared = lmrefine.bake(scene, resolution, samples=4, seed=1, atlas=True)["atlas"]
    uvs, triangles, _, rows = atlas.join_layouts(squares)
    masks = [lmrefine.coverage_mask(uvs, triangles[r], resolution) for r in rows]
    merged = atlas.merge_maps([own[0], own[1]], masks, uvs, triangles, 16)
    np.testing.assert_allclose(merged[..., :3], shared[..., :3], rtol=1e-5, atol=1e-6)
