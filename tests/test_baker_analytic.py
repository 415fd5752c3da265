"""The baker against closed-form light: inverse-square and cosine laws, an
umbra's shape, AO next to a wall, and the energy balance of a closed box.

Values are Cycles' DIFFUSE bake with the colour pass off: irradiance / pi.
A point light of power P has radiant intensity P / (4 pi) (docs/baker.md).
"""

import numpy as np
import pytest

import lmrefine
from baker_scenes import box_inside, floor, sample_box_inside, texel_average, texel_centers


def floor_scene(**kwargs):
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor()
    scene.add_mesh(positions, triangles, uvs=uvs, **kwargs)
    return scene


def test_point_light_follows_inverse_square_cosine_law():
    scene = floor_scene()
    light = np.array([0.3, -0.2, 1.5])
    scene.add_light("point", energy=50.0, shadow_soft_size=0.0, position=light)
    image = lmrefine.bake(scene, 32, samples=64)[0]

    def law(x, y):
        d2 = (x - light[0]) ** 2 + (y - light[1]) ** 2 + light[2] ** 2
        return 50.0 / (4 * np.pi**2) * light[2] / d2**1.5

    expected = texel_average(law, 32)
    assert image.dtype == np.float32 and image.shape == (32, 32, 4)
    np.testing.assert_allclose(image[..., 3], 1.0)
    for channel in range(3):
        np.testing.assert_allclose(image[..., channel], expected, rtol=4e-3)  # 64 samples over a texel
    # evaluate() at exact points: no texel averaging, no noise for a point light.
    x, y = texel_centers(32)
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (x.size, 1))
    values = lmrefine.evaluate(scene, points, normals, samples=4)
    np.testing.assert_allclose(values[:, 1], law(x, y).ravel(), rtol=1e-4)


def test_light_colour_scales_each_channel():
    scene = floor_scene()
    scene.add_light("point", energy=10.0, color=(1.0, 0.5, 0.0), shadow_soft_size=0.0, position=(0, 0, 1))
    image = lmrefine.bake(scene, 8, samples=4)[0]
    np.testing.assert_allclose(image[..., 1], 0.5 * image[..., 0], rtol=1e-5)
    np.testing.assert_array_equal(image[..., 2], 0.0)


def test_sun_follows_cosine_law():
    scene = floor_scene()
    direction = np.array([0.5, 0.2, -0.7])
    scene.add_light("sun", energy=3.0, angle=0.0, direction=direction)
    image = lmrefine.bake(scene, 16, samples=4)[0]
    cosine = -direction[2] / np.linalg.norm(direction)
    np.testing.assert_allclose(image[..., :3], 3.0 * cosine / np.pi, rtol=1e-5)


def test_sun_from_below_leaves_the_front_dark():
    scene = floor_scene()
    scene.add_light("sun", energy=3.0, direction=(0.0, 0.0, 1.0))
    assert lmrefine.bake(scene, 8, samples=4)[0][..., :3].max() == 0.0


def test_blocker_casts_an_umbra_of_the_projected_shape():
    scene = floor_scene()
    # A 0.54 x 0.54 occluder at z = 1 under a point light at z = 2 projects to
    # the square [-0.54, 0.54]^2 on the floor, whose edges cross texels
    # (texel size 1/16). The blocker is an occluder only: it bakes no map.
    positions, triangles, _ = floor(half=0.27, z=1.0)
    scene.add_mesh(positions, triangles, receiver=False)
    scene.add_light("point", energy=100.0, shadow_soft_size=0.0, position=(0, 0, 2))
    result = lmrefine.bake(scene, 32, samples=64)
    assert list(result) == [0]
    direct = result[0][..., 0]
    unshadowed = texel_average(lambda x, y: 100.0 / (4 * np.pi**2) * 2.0 / (x * x + y * y + 4.0) ** 1.5, 32)
    x, y = texel_centers(32)
    half_texel = 1.0 / 32
    inside = (np.abs(x) + half_texel < 0.54) & (np.abs(y) + half_texel < 0.54)
    outside = (np.abs(x) - half_texel > 0.54) | (np.abs(y) - half_texel > 0.54)
    assert inside.sum() == 16 * 16
    np.testing.assert_array_equal(direct[inside], 0.0)
    np.testing.assert_allclose(direct[outside], unshadowed[outside], rtol=4e-3)
    # Texels the shadow's edge crosses are lit in proportion to their lit area:
    # (0.5625 - 0.54) / 0.0625 = 36% on the sides, 1 - 0.64^2 = 59% at the corners.
    border = ~inside & ~outside
    corner = border & (np.abs(x) > 0.5) & (np.abs(y) > 0.5)
    side = border & ~corner
    assert corner.sum() == 4 and side.sum() == 4 * 16
    np.testing.assert_allclose(direct[side] / unshadowed[side], 0.36, atol=0.05)
    np.testing.assert_allclose(direct[corner] / unshadowed[corner], 0.59, atol=0.05)


def test_ao_of_an_open_plane_is_one():
    scene = floor_scene()
    image = lmrefine.bake(scene, 16, passes="ao", samples=16, ao_distance=5.0)[0]
    np.testing.assert_array_equal(image[..., :3], 1.0)


def test_ao_falls_towards_an_inner_corner_as_the_disk_segment_law():
    # A floor and a tall wall at x = 0. A cosine-weighted direction projects
    # uniformly onto the unit disk; with AO distance D, it hits the wall from
    # distance x when its x component is below -x / D: the blocked fraction is
    # the disk segment beyond a = x / D, (acos(a) - a sqrt(1 - a^2)) / pi.
    scene = lmrefine.Scene()
    positions, triangles, uvs = floor(half=4.0)
    scene.add_mesh(positions, triangles, uvs=uvs)
    wall = np.array([[0, -4, 0], [0, 4, 0], [0, 4, 4], [0, -4, 4]], dtype=float)
    scene.add_mesh(wall, np.array([[0, 1, 2], [0, 2, 3]]), receiver=False)
    x = np.array([0.02, 0.1, 0.3, 0.6, 0.9, 1.5])
    points = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    ao = lmrefine.evaluate(scene, points, normals, passes="ao", samples=8192, ao_distance=1.0)[:, 0]
    a = np.minimum(x, 1.0)
    expected = 1.0 - (np.arccos(a) - a * np.sqrt(1 - a**2)) / np.pi
    np.testing.assert_allclose(ao, expected, atol=0.015)
    assert np.all(np.diff(ao) > 0)


@pytest.mark.parametrize("albedo,bounces", [(0.5, 1), (0.5, 8), (0.8, 3)])
def test_closed_box_indirect_matches_the_energy_balance(albedo, bounces, rng):
    # In a closed enclosure every reflected watt lands on another wall, so the
    # power arriving after k bounces is albedo^k times the direct power, and
    # area means obey indirect / direct = sum_{k=1..N} albedo^k (-> a / (1 - a)).
    scene = lmrefine.Scene()
    positions, triangles, uvs = box_inside()
    scene.add_mesh(positions, triangles, uvs=uvs, base_color=(albedo,) * 3)
    scene.add_light("point", energy=100.0, shadow_soft_size=0.1, position=(0.2, -0.3, 0.4))
    points, normals = sample_box_inside(3000, rng)
    values = lmrefine.evaluate(scene, points, normals, passes=("direct", "indirect"), samples=32, bounces=bounces)
    ratio = values["indirect"].mean() / values["direct"].mean()
    expected = sum(albedo**k for k in range(1, bounces + 1))
    assert ratio == pytest.approx(expected, rel=0.03)


def test_combined_is_direct_plus_indirect():
    scene = lmrefine.Scene()
    positions, triangles, uvs = box_inside()
    scene.add_mesh(positions, triangles, uvs=uvs, base_color=(0.6, 0.5, 0.4))
    scene.add_light("point", energy=100.0, shadow_soft_size=0.1, position=(0.2, -0.3, 0.4))
    maps = lmrefine.bake(scene, 16, passes=("direct", "indirect", "combined"), samples=4)
    np.testing.assert_allclose(maps["combined"][0], maps["direct"][0] + maps["indirect"][0] * [1, 1, 1, 0], rtol=1e-5)
    # Coloured walls tint the bounced light: red bounces most.
    indirect = maps["indirect"][0]
    covered = indirect[..., 3] > 0
    assert indirect[covered, 0].mean() > indirect[covered, 1].mean() > indirect[covered, 2].mean()


def test_world_light_is_the_sky_colour_where_open():
    scene = floor_scene()
    scene.set_world((0.2, 0.4, 0.6))
    image = lmrefine.bake(scene, 8, samples=8)[0]
    np.testing.assert_allclose(image[..., :3], np.broadcast_to([0.2, 0.4, 0.6], (8, 8, 3)), rtol=1e-6)
