"""The baker's machinery: determinism, dilation, atlas mode, smooth shading
without self-shadowing, progress and cancellation, stats, denoising."""

import numpy as np
import pytest

import lmrefine
from lmrefine import metrics
from baker_scenes import floor, quad, texel_centers


def lit_scene(world=True):
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor()
    scene.add_mesh(positions, triangles, uvs=uvs)
    blocker, blocker_triangles, _ = floor(half=0.3, z=0.6)
    scene.add_mesh(blocker, blocker_triangles, receiver=False)
    scene.add_light("area", energy=80.0, shape="DISK", size=0.4, position=(0.1, 0, 1.5))
    if world:
        scene.set_world((0.1, 0.1, 0.1))
    return scene


def test_bake_is_deterministic_for_a_seed_whatever_the_thread_count(monkeypatch):
    scene = lit_scene()
    first = lmrefine.bake(scene, 24, passes=("direct", "ao"), samples=8, seed=7)
    monkeypatch.setenv("LMREFINE_THREADS", "1")
    single = lmrefine.bake(scene, 24, passes=("direct", "ao"), samples=8, seed=7)
    monkeypatch.setenv("LMREFINE_THREADS", "3")
    three = lmrefine.bake(scene, 24, passes=("direct", "ao"), samples=8, seed=7)
    for name in ("direct", "ao"):
        np.testing.assert_array_equal(first[name][0], single[name][0])
        np.testing.assert_array_equal(first[name][0], three[name][0])
    other = lmrefine.bake(scene, 24, samples=8, seed=8)[0]
    assert not np.array_equal(other, first["direct"][0])
    # Same light, different noise: the seeds agree on average.
    assert other[..., 0].mean() == pytest.approx(first["direct"][0][..., 0].mean(), rel=0.03)


def two_chart_scene():
    # Two charts with a 12-texel gutter (at 32 texels): a lit floor and a
    # floor facing away from the sun (black).
    scene = lmrefine.Scene()
    lit = floor(uv_rect=(0.0, 0.0, 0.375, 1.0))
    dark = quad(([3, -1, 0], [3, 1, 0], [5, -1, 0]), (0.75, 0.0, 1.0, 1.0))  # faces -z
    scene.add_mesh(lit[0], lit[1], uvs=lit[2])
    scene.add_mesh(dark[0], dark[1], uvs=dark[2])
    scene.add_light("sun", energy=2.0, angle=0.0, direction=(0, 0, -1))
    return scene


def test_dilation_fills_the_gutter_from_each_chart_and_never_writes_inside():
    scene = two_chart_scene()
    plain = lmrefine.bake(scene, 32, samples=4, dilation=0, atlas=True)["atlas"]
    dilated = lmrefine.bake(scene, 32, samples=4, dilation=3, atlas=True)["atlas"]
    covered = plain[..., 3] > 0
    np.testing.assert_array_equal(dilated[covered], plain[covered])
    np.testing.assert_array_equal(dilated[..., 3], plain[..., 3])  # alpha stays coverage
    lit = 2.0 / np.pi
    # Columns 0-11 lit chart, 12-23 gutter, 24-31 dark chart.
    assert np.all(covered[:, :12]) and not covered[:, 12:24].any() and np.all(covered[:, 24:])
    np.testing.assert_allclose(dilated[:, 12:15, :3], lit, rtol=1e-6)  # 3 rings from the lit chart
    np.testing.assert_array_equal(dilated[:, 15:21, :3], 0.0)  # beyond the dilation
    np.testing.assert_array_equal(dilated[:, 21:24, :3], 0.0)  # from the dark chart
    np.testing.assert_array_equal(plain[~covered, :3], 0.0)


def test_dilation_never_mixes_two_charts_in_a_narrow_gutter():
    scene = two_chart_scene()
    image = lmrefine.bake(scene, 32, samples=4, dilation=16, atlas=True)["atlas"]
    lit = 2.0 / np.pi
    gutter = image[:, 12:24, 0]
    # Every gutter texel took one chart's colour: lit or black, never a blend.
    assert np.all(np.isclose(gutter, lit, rtol=1e-6) | (gutter == 0.0))
    np.testing.assert_allclose(gutter[:, :6], lit, rtol=1e-6)
    np.testing.assert_array_equal(gutter[:, 6:], 0.0)


def test_a_gutter_texel_takes_the_chart_nearest_its_centre():
    # Two charts two texels apart (at 32 texels), as the packer leaves them:
    # the lit one (chart 0) ends at x = 9.05 texels, the dark one starts at
    # 11.05, so column 10 is the only free one. Its centre (10.5) is 0.55
    # from the dark chart and 1.45 from the lit one; by ring counts the two
    # tie (three neighbours each) and the lower id, the lit chart, took it, so
    # a bilinear lookup just inside the dark chart's border read lit light.
    scene = lmrefine.Scene()
    lit = floor(uv_rect=(0.0, 0.0, 9.05 / 32, 1.0))
    dark = quad(([3, -1, 0], [3, 1, 0], [5, -1, 0]), (11.05 / 32, 0.0, 1.0, 1.0))  # faces -z
    scene.add_mesh(lit[0], lit[1], uvs=lit[2])
    scene.add_mesh(dark[0], dark[1], uvs=dark[2])
    scene.add_light("sun", energy=2.0, angle=0.0, direction=(0, 0, -1))
    image = lmrefine.bake(scene, 32, samples=4, dilation=16, atlas=True)["atlas"]
    covered = image[..., 3] > 0
    assert np.all(covered[:, :10]) and not covered[:, 10].any() and np.all(covered[:, 11:])
    np.testing.assert_array_equal(image[:, 10, :3], 0.0)
    lit_value = 2.0 / np.pi
    np.testing.assert_allclose(image[:, :10, 0], lit_value, rtol=1e-6)
    # Points on each chart a tenth of a texel inside its border read only its own light.
    v = np.full(2, 0.5)
    looked_up = metrics.bilinear_lookup(image[..., :3], np.stack([np.array([8.95, 11.15]) / 32, v], 1))
    np.testing.assert_allclose(looked_up[0], lit_value, rtol=1e-6)
    np.testing.assert_array_equal(looked_up[1], 0.0)


def test_per_mesh_maps_and_atlas():
    scene = two_chart_scene()
    maps = lmrefine.bake(scene, 16, samples=2)
    assert sorted(maps) == [0, 1]
    assert maps[0][..., 3].sum() == 6 * 16 and maps[1][..., 3].sum() == 4 * 16
    atlas = lmrefine.bake(scene, 16, samples=2, atlas=True)
    assert list(atlas) == ["atlas"]
    np.testing.assert_array_equal(atlas["atlas"][..., 3], np.maximum(maps[0][..., 3], maps[1][..., 3]))


def uv_sphere(rings=24, segments=48):
    """A UV sphere with per-corner lat-long lightmap UVs and smooth normals."""
    v, u = np.meshgrid(np.linspace(0, 1, rings + 1), np.linspace(0, 1, segments + 1), indexing="ij")
    theta, phi = np.pi * (1 - v), 2 * np.pi * u
    grid = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    index = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]
    triangles = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    uv = np.stack([u, v], axis=-1).reshape(-1, 2)
    positions = grid.reshape(-1, 3)
    # Keep only non-degenerate triangles: the poles' fans have a zero-area half.
    return positions, triangles, uv[triangles.ravel()], positions[triangles.ravel()]


def test_smooth_sphere_under_a_sun_has_no_self_shadowing():
    positions, triangles, uvs, normals = uv_sphere()
    scene = lmrefine.Scene()
    scene.add_mesh(positions * 100.0 + 500.0, triangles, uvs=uvs, normals=normals)  # far from the origin
    assert scene.degenerate_triangles(0) == 2 * 48  # pole triangles
    sun = np.array([0.3, -0.4, -0.866])
    sun /= np.linalg.norm(sun)
    scene.add_light("sun", energy=1.0, angle=0.0, direction=sun)
    image = lmrefine.bake(scene, 64, samples=16, dilation=0)[0]
    # The texel centre's direction on the sphere (lat-long layout).
    x, y = texel_centers(64, half=0.5)
    u, v = x + 0.5, y + 0.5
    theta, phi = np.pi * (1 - v), 2 * np.pi * u
    n = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    cosine = n @ -sun
    expected = np.maximum(cosine, 0) / np.pi
    lit = (cosine > 0.3) & (np.abs(np.cos(theta)) < 0.95)
    assert lit.sum() > 800
    np.testing.assert_allclose(image[lit, 0], expected[lit], rtol=0.03)
    assert np.all(image[cosine < -0.2, 0] == 0.0)


def test_a_chart_border_on_a_contact_line_bakes_as_the_surface_next_to_it():
    """A wall standing on a floor, its chart's bottom edge through the middle
    of a texel row: that row's texels are half outside the chart. Their
    outside samples must land on the wall near its bottom, which the sun
    lights, not on the line where wall and floor meet, where a ray starts in
    the floor's plane and finds it (the row baked half dark before)."""
    resolution = 32
    u0, v0, u1, v1 = 8.5 / resolution, 4.5 / resolution, 23.5 / resolution, 27.5 / resolution
    scene = lmrefine.Scene()
    wall, wall_triangles, wall_uvs = quad(([-1, 0, 0], [1, 0, 0], [-1, 0, 2]), (u0, v0, u1, v1))  # faces -y
    scene.add_mesh(wall, wall_triangles, uvs=wall_uvs)
    ground, ground_triangles, _ = floor(half=3.0)
    scene.add_mesh(ground, ground_triangles, receiver=False)
    scene.add_light("sun", energy=3.0, angle=0.0, direction=(0.0, 1.0, -1.0))
    image = lmrefine.bake(scene, resolution, samples=16, dilation=0)[0][..., 0]
    columns = slice(10, 22)
    bottom = resolution - 5  # the row v in [4, 5] / resolution: half inside the chart
    inner = image[8:resolution - 8, columns]
    expected = 3.0 * np.cos(np.pi / 4) / np.pi  # irradiance / pi (the colour pass is off)
    np.testing.assert_allclose(inner, expected, rtol=1e-3)
    np.testing.assert_allclose(image[bottom, columns], expected, rtol=0.02)
    np.testing.assert_allclose(image[resolution - 28, columns], expected, rtol=0.02)  # the top edge, no contact


def test_progress_reports_stages_and_cancel_raises_without_result():
    scene = lit_scene()
    calls = []
    lmrefine.bake(scene, 32, passes=("direct", "ao"), samples=4,
                  progress=lambda fraction, stage: calls.append((fraction, stage)))
    stages = [stage for _, stage in calls]
    assert "baking direct" in stages and "baking ao" in stages
    assert all(0.0 <= f <= 1.0 for f, _ in calls) and calls[-1][0] == 1.0

    def cancel(fraction, stage):
        return False

    with pytest.raises(lmrefine.CancelledError):
        lmrefine.bake(scene, 32, samples=4, progress=cancel)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.evaluate(scene, np.zeros((10, 3)), np.tile([0, 0, 1.0], (10, 1)), progress=cancel)

    def boom(fraction, stage):
        raise KeyError("from the callback")

    with pytest.raises(KeyError):
        lmrefine.bake(scene, 32, samples=4, progress=boom)


def test_stats_count_rays_and_time_per_pass():
    scene = lit_scene(world=False)
    result = lmrefine.bake(scene, 16, passes=("direct", "ao"), samples=4)
    stats = result.stats
    covered = 16 * 16
    assert stats["texels"] == covered
    # direct: one shadow ray per light sample (none where the light is behind); ao: one per sample.
    assert covered * 4 <= stats["rays"] <= 2 * covered * 4
    assert set(stats["pass_seconds"]) == {"direct", "ao"}
    # Rays per second of tracing: the rays over the passes' own seconds, not the whole call's.
    traced = sum(stats["pass_seconds"].values())
    assert stats["rays_per_second"] == pytest.approx(stats["rays"] / traced, rel=1e-9)
    assert stats["seconds"] >= traced


def hard_edge_scene():
    # A sharp shadow edge along x = 0 (a zero-radius light above the edge of a
    # large blocker) plus a noisy sky.
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor()
    scene.add_mesh(positions, triangles, uvs=uvs)
    blocker = np.array([[-3, -3, 0.5], [0, -3, 0.5], [0, 3, 0.5], [-3, 3, 0.5]], dtype=float)
    scene.add_mesh(blocker, np.array([[0, 1, 2], [0, 2, 3]]), receiver=False)
    scene.add_light("point", energy=30.0, shadow_soft_size=0.0, position=(0, 0, 1.0))
    scene.set_world((0.3, 0.3, 0.3))
    return scene


def test_denoise_reduces_noise_without_blurring_a_shadow_edge():
    scene = hard_edge_scene()
    reference = lmrefine.bake(scene, 32, samples=1024, seed=1)[0][..., 0]
    noisy = lmrefine.bake(scene, 32, samples=4, seed=2)[0][..., 0]
    clean = lmrefine.bake(scene, 32, samples=4, seed=2, denoise=True)[0][..., 0]

    def rmse(a, columns):
        return np.sqrt(np.mean((a[:, columns] - reference[:, columns]) ** 2))

    everywhere = slice(None)
    assert rmse(clean, everywhere) < 0.6 * rmse(noisy, everywhere)
    # The edge is between columns 15 and 16. One texel away from it on either
    # side the denoised map still matches the reference to the noise level.
    shadow, lit = slice(0, 15), slice(17, 32)
    assert abs(clean[:, shadow].mean() - reference[:, shadow].mean()) < 0.02
    assert abs(clean[:, lit].mean() - reference[:, lit].mean()) < 0.02
    step = reference[:, 17].mean() - reference[:, 14].mean()
    assert step > 0.5
    np.testing.assert_allclose(clean[:, 14].mean(), reference[:, 14].mean(), atol=0.05 * step)
    np.testing.assert_allclose(clean[:, 17].mean(), reference[:, 17].mean(), atol=0.05 * step)
