"""Bad input to the baker: clear errors naming the problem, never a crash."""

import re

import numpy as np
import pytest

import lmrefine
from baker_scenes import floor


def plane_scene():
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor()
    scene.add_mesh(positions, triangles, uvs=uvs)
    return scene


def test_empty_scene_has_nothing_to_bake():
    scene = lmrefine.Scene()
    scene.add_light("point", energy=10.0, position=(0, 0, 1))
    with pytest.raises(ValueError, match="no receiving mesh"):
        lmrefine.bake(scene, 16)
    positions, triangles, _ = floor()
    scene.add_mesh(positions, triangles, receiver=False)
    with pytest.raises(ValueError, match="no receiving mesh"):
        lmrefine.bake(scene, 16)


def test_direct_light_needs_a_light_or_a_world():
    scene = plane_scene()
    with pytest.raises(ValueError, match="no lights and no world"):
        lmrefine.bake(scene, 16)
    with pytest.raises(ValueError, match="no lights and no world"):
        lmrefine.evaluate(scene, np.zeros((1, 3)), np.array([[0, 0, 1.0]]), passes="indirect")
    # AO needs neither.
    assert lmrefine.bake(scene, 8, passes="ao", samples=1)[0].shape == (8, 8, 4)


def test_nan_vertices_are_named():
    positions, triangles, uvs = floor()
    positions[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions\[2\] is NaN"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs)


def test_nan_normals_and_zero_normals_are_named():
    positions, triangles, uvs = floor()
    normals = np.tile([0, 0, 1.0], (4, 1))
    normals[1] = 0
    with pytest.raises(ValueError, match=r"normals\[1\] is zero"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs, normals=normals)
    normals[1] = np.inf
    with pytest.raises(ValueError, match=r"normals\[1\] is NaN or Inf"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs, normals=normals)


def test_uvs_outside_the_unit_square_are_named():
    positions, triangles, uvs = floor()
    uvs[4] = (1.25, 0.5)
    with pytest.raises(ValueError, match=r"uvs\[4\] = \(1.25.*outside \[0, 1\]"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs)


def test_uvs_must_be_per_corner_and_receivers_need_them():
    positions, triangles, uvs = floor()
    with pytest.raises(ValueError, match=r"per corner, shape \(T\*3, 2\) = \(6, 2\)"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs[:4])
    with pytest.raises(ValueError, match="needs lightmap uvs"):
        lmrefine.Scene().add_mesh(positions, triangles)


def test_indices_out_of_range_and_bad_colours():
    positions, triangles, uvs = floor()
    with pytest.raises(ValueError, match="refers to vertex 7"):
        lmrefine.Scene().add_mesh(positions, np.array([[0, 1, 7], [0, 2, 3]]), uvs=uvs)
    with pytest.raises(ValueError, match="outside \\[0, 1\\]; an albedo above 1"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs, base_color=(1.5, 0, 0))
    with pytest.raises(ValueError, match="one per triangle"):
        lmrefine.Scene().add_mesh(positions, triangles, uvs=uvs, base_color=np.ones((3, 3)) * 0.5)


def test_degenerate_triangles_are_skipped_and_counted():
    positions, triangles, uvs = floor()
    positions = np.vstack([positions, [[0, 0, 0], [1, 1, 0], [2, 2, 0]]])  # collinear
    triangles = np.vstack([triangles, [[4, 5, 6]]])
    uvs = np.vstack([uvs, [[0.1, 0.1], [0.2, 0.1], [0.1, 0.2]]])
    scene = lmrefine.Scene()
    scene.add_mesh(positions, triangles, uvs=uvs)
    scene.add_light("sun", energy=1.0, direction=(0, 0, -1))
    assert scene.degenerate_triangles(0) == 1
    result = lmrefine.bake(scene, 16, samples=2)
    assert result.stats["degenerate_triangles"] == 1
    np.testing.assert_array_equal(result[0][..., 3], 1.0)


def test_bad_lights():
    scene = lmrefine.Scene()
    with pytest.raises(ValueError, match="light kind"):
        scene.add_light("laser", energy=1.0)
    with pytest.raises(ValueError, match="needs energy"):
        scene.add_light("point", position=(0, 0, 1))
    with pytest.raises(ValueError, match="unknown light parameter \"power\""):
        scene.add_light("point", energy=1.0, power=3)
    with pytest.raises(ValueError, match="energy must be finite and >= 0"):
        scene.add_light("point", energy=-1.0)
    with pytest.raises(ValueError, match="direction must not be zero"):
        scene.add_light("sun", energy=1.0, direction=(0, 0, 0))
    with pytest.raises(ValueError, match="shape must be"):
        scene.add_light("area", energy=1.0, shape="TRIANGLE")
    with pytest.raises(ValueError, match="spot_blend"):
        scene.add_light("spot", energy=1.0, spot_blend=2.0)
    assert scene.light_count == 0


@pytest.mark.parametrize("resolution", [0, -3, (16, 0)])
def test_zero_resolution(resolution):
    scene = plane_scene()
    scene.add_light("sun", energy=1.0)
    with pytest.raises(ValueError, match="resolution must be positive"):
        lmrefine.bake(scene, resolution)


def test_huge_resolution_is_refused_before_allocating():
    scene = plane_scene()
    scene.add_light("sun", energy=1.0)
    with pytest.raises(ValueError, match="above the largest lightmap"):
        lmrefine.bake(scene, 40000)
    # 64 maps of 32768^2 texels x 4 passes: terabytes, refused with the estimate.
    positions, triangles, uvs = floor()
    for _ in range(63):
        scene.add_mesh(positions, triangles, uvs=uvs)
    with pytest.raises(MemoryError, match=r"needs about \d+\.\d+ GiB"):
        lmrefine.bake(scene, 32768, passes=("direct", "ao", "indirect", "combined"))


def test_a_deep_stack_at_a_high_resolution_is_refused_before_allocating():
    # A texture map taken for a lightmap: the texel table holds a candidate per stacked face and
    # texel, 670 GB for 1,000 quads at 4096^2, past the estimate's ~1.5 per texel (found by a
    # crash hunt). The quads lie apart in 3-D, stacked in the map.
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    count = 1000
    positions = np.concatenate([quad + [0, 0, 0.01 * k] for k in range(count)]).astype(np.float32)
    first = np.arange(count)[:, None] * 4
    triangles = np.concatenate([first + [0, 1, 2], first + [0, 2, 3]]).astype(np.int32)
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)[triangles.ravel() % 4]
    scene = lmrefine.Scene()
    scene.add_mesh(positions, triangles, uvs=uvs)
    scene.add_light("sun", energy=1.0)
    with pytest.raises(MemoryError, match=r"baking at 4096x4096 \(a lightmap's faces are stacked, at least 99\d "
                                          r"deep on average\) needs about \d+\.\d\d GiB of memory, more than half "
                                          r"of this machine's \d+\.\d\d GiB; give the faces their own places in the "
                                          r"lightmap \(Lightmap Pack or Smart UV Project\), fewer stacked faces, or a "
                                          r"lower resolution") as refused:
        lmrefine.bake(scene, 4096, passes=("direct",))
    # The size asked for counts the same stacked candidates as the depth in its wording: one map,
    # one pass, 16 bytes returned and 160 working per texel, 40 per candidate past one per texel.
    figures = re.search(r"at least (\S+) deep.*needs about (\S+) GiB", str(refused.value)).groups()
    depth, gib = (float(x) for x in figures)
    texels = 4096 * 4096
    assert gib * 2**30 == pytest.approx(texels * (16 + 160 + 40 * (depth - 1)), rel=1e-3)
    # A shallow stack at a low resolution still bakes.
    few = triangles[:, 0] < 12
    shallow = lmrefine.Scene()
    shallow.add_mesh(positions[:12], triangles[few], uvs=uvs.reshape(-1, 3, 2)[few].reshape(-1, 2))
    shallow.add_light("sun", energy=1.0)
    assert lmrefine.bake(shallow, 32, passes=("direct",), samples=2)[0].shape == (32, 32, 4)


def test_bad_options():
    scene = plane_scene()
    scene.add_light("sun", energy=1.0)
    with pytest.raises(ValueError, match="unknown pass 'glossy'"):
        lmrefine.bake(scene, 8, passes="glossy")
    with pytest.raises(ValueError, match="passes is empty"):
        lmrefine.bake(scene, 8, passes=())
    with pytest.raises(ValueError, match="samples must be"):
        lmrefine.bake(scene, 8, samples=0)
    with pytest.raises(ValueError, match="ao_distance must be > 0"):
        lmrefine.bake(scene, 8, passes="ao", ao_distance=0.0)
    with pytest.raises(ValueError, match="dilation must be >= 0"):
        lmrefine.bake(scene, 8, dilation=-1)
    with pytest.raises(ValueError, match="one row per point"):
        lmrefine.evaluate(scene, np.zeros((3, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"normals\[0\] is zero"):
        lmrefine.evaluate(scene, np.zeros((1, 3)), np.zeros((1, 3)))


def test_inputs_are_not_modified():
    positions, triangles, uvs = floor()
    normals = np.tile([0, 0, 2.0], (6, 1))  # not unit: normalized inside, not in place
    copies = [a.copy() for a in (positions, triangles, uvs, normals)]
    scene = lmrefine.Scene()
    scene.add_mesh(positions, triangles, uvs=uvs, normals=normals)
    for original, copy in zip((positions, triangles, uvs, normals), copies):
        np.testing.assert_array_equal(original, copy)


def test_a_scene_cannot_change_while_it_is_baked():
    # The bake reads the scene's arrays with the GIL released; a light added from its progress
    # callback (or another thread) would reallocate them under it.
    scene = lmrefine.Scene()
    uvs = np.float32([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.1], [0.9, 0.9], [0.1, 0.9]])
    scene.add_mesh(np.float32([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]), np.int32([[0, 1, 2], [0, 2, 3]]),
                   uvs=uvs)
    scene.add_light("point", energy=10.0, position=(0.5, 0.5, 1.0))

    def progress(fraction, stage):
        scene.add_light("point", energy=10.0, position=(0.5, 0.5, 2.0))

    for call in (lambda: lmrefine.bake(scene, 16, samples=1, progress=progress),
                 lambda: lmrefine.evaluate(scene, np.float32([[0.5, 0.5, 0.0]]), np.float32([[0, 0, 1]]),
                                           samples=1, progress=progress)):
        with pytest.raises(ValueError, match="while the scene is being baked"):
            call()
    assert scene.light_count == 1
    scene.add_light("point", energy=10.0, position=(0.5, 0.5, 2.0))  # after the calls return
    assert scene.light_count == 2
