"""A light's full orientation: an area light's spin about its axis (axis_x)
and a Blender world matrix with scale (matrix=), against the closed-form
light of a Lambertian polygon (Lambert's contour formula).

A texel holds irradiance / pi; an area light of power P and area A has
radiance P / (4 A) (docs/baker.md), so a point sees P / (4 A) times its form
factor to the light's polygon.
"""

import numpy as np
import pytest

import lmrefine

ENERGY = 20.0
UP = np.array([0.0, 0.0, 1.0])


def blender_axis_x(direction):
    """The local X Blender gives a light aimed along `direction` by
    Vector.to_track_quat('-Z', 'Y'): local Y is world +Z made perpendicular
    to the light's Z; X = Y x Z."""
    z = -np.asarray(direction, float) / np.linalg.norm(direction)
    y = UP - UP.dot(z) * z
    return np.cross(y / np.linalg.norm(y), z)


def outline(position, direction, axis_x, size, size_y, shape, count=256):
    """The light's polygon in world space (an ellipse as `count` corners)."""
    z = -np.asarray(direction, float) / np.linalg.norm(direction)
    x = np.asarray(axis_x, float)
    x = x - x.dot(z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    if shape == "RECTANGLE":
        local = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    else:
        angle = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
        local = 0.5 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    local = local * [size, size_y]
    return np.asarray(position, float) + local[:, :1] * x + local[:, 1:] * y


def area_value(corners, points, normal=UP):
    """Lambert's formula: the form factor from each point (facing `normal`)
    to the polygon, times the radiance P / (4 A); the value a texel holds."""
    area = 0.5 * np.linalg.norm(np.cross(corners, np.roll(corners, -1, axis=0)).sum(0))
    values = []
    for p in np.asarray(points, float):
        r = corners - p
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        s = np.roll(r, -1, axis=0)
        gamma = np.arccos(np.clip((r * s).sum(1), -1.0, 1.0))
        edge_normal = np.cross(r, s)
        edge_normal /= np.linalg.norm(edge_normal, axis=1, keepdims=True)
        values.append(abs((gamma * (edge_normal @ normal)).sum()) / (2 * np.pi))
    return ENERGY / (4 * area) * np.array(values)


def light_values(points, samples=2048, **params):
    scene = lmrefine.Scene()
    scene.add_light("area", energy=ENERGY, **params)
    normals = np.tile(UP, (len(points), 1))
    return lmrefine.evaluate(scene, np.asarray(points, float), normals, samples=samples, seed=1)[:, 0]


# A 1.6 m x 0.1 m strip light 0.5 m above the floor, facing down.
STRIP = dict(shape="RECTANGLE", size=1.6, size_y=0.1, position=(0.0, 0.0, 0.5), direction=(0.0, 0.0, -1.0))
ALONG_X = [(0.0, 0.0, 0.0), (0.4, 0.0, 0.0), (0.7, 0.0, 0.0), (-0.9, 0.0, 0.0)]


def test_a_strip_light_spun_90_degrees_turns_its_light_90_degrees():
    along_y = [(-y, x, z) for x, y, z in ALONG_X]  # ALONG_X turned +90 degrees about z
    default = light_values(ALONG_X + along_y, **STRIP)
    spun = light_values(ALONG_X + along_y, axis_x=(0.0, 1.0, 0.0), **STRIP)
    # The default strip runs along world x (straight down keeps world X): the
    # floor is lit along x and falls off fast across it. Spun, the other way round.
    default_corners = outline(STRIP["position"], STRIP["direction"], (1, 0, 0), 1.6, 0.1, "RECTANGLE")
    spun_corners = outline(STRIP["position"], STRIP["direction"], (0, 1, 0), 1.6, 0.1, "RECTANGLE")
    np.testing.assert_allclose(default, area_value(default_corners, ALONG_X + along_y), rtol=0.01)
    np.testing.assert_allclose(spun, area_value(spun_corners, ALONG_X + along_y), rtol=0.01)
    np.testing.assert_allclose(spun[4:], default[:4], rtol=0.01)
    np.testing.assert_allclose(spun[:4], default[4:], rtol=0.01)
    # 0.7 m out along the strip vs across it: a strong, unmistakable difference.
    assert default[2] > 3 * default[6] and spun[6] > 3 * spun[2]


@pytest.mark.parametrize("shape", ["RECTANGLE", "ELLIPSE"])
def test_a_tilted_light_is_oriented_as_blender_orients_it(shape):
    """Without axis_x, Blender's to_track_quat('-Z', 'Y') frame (the
    orientation before axis_x existed); with it, the given spin, 60 degrees off."""
    position, direction = np.array([0.1, -0.1, 0.6]), np.array([0.3, -0.4, -1.0])
    points = [(x, y, 0.0) for x in (-0.6, 0.0, 0.5) for y in (-0.5, 0.0, 0.4)]
    params = dict(shape=shape, size=1.2, size_y=0.15, position=position, direction=direction)
    x = blender_axis_x(direction)
    z = -direction / np.linalg.norm(direction)
    spun_x = np.cos(np.pi / 3) * x + np.sin(np.pi / 3) * np.cross(z, x)
    default = light_values(points, **params)
    spun = light_values(points, axis_x=spun_x, **params)
    np.testing.assert_allclose(default, area_value(outline(position, direction, x, 1.2, 0.15, shape), points),
                               rtol=0.015)
    np.testing.assert_allclose(spun, area_value(outline(position, direction, spun_x, 1.2, 0.15, shape), points),
                               rtol=0.015)
    assert np.abs(spun / default - 1).max() > 0.3  # the spin matters here
    np.testing.assert_allclose(light_values(points, axis_x=x, **params), default, rtol=1e-5)


def test_axis_x_keeps_only_its_spin_about_the_direction():
    direction = np.array([0.2, 0.1, -1.0])
    x = blender_axis_x(direction)
    params = dict(shape="RECTANGLE", size=1.0, size_y=0.2, position=(0, 0, 0.5), direction=direction)
    points = [(0.3, 0.2, 0.0), (-0.4, 0.1, 0.0), (0.0, -0.5, 0.0)]
    exact = light_values(points, axis_x=x, **params)
    # Scaled and leaning along the direction: the same light.
    np.testing.assert_allclose(light_values(points, axis_x=3 * x - 2 * direction, **params), exact, rtol=1e-5)


def blender_matrix(spin, scale, position=(0.1, -0.2, 0.7), tilt_x=0.3):
    """A world matrix as Blender's matrix_world (rows, translation in the last
    column): scaled, spun by `spin` about the light's own axis, then tilted
    by `tilt_x` about world x."""
    cx, sx, cz, sz = np.cos(tilt_x), np.sin(tilt_x), np.cos(spin), np.sin(spin)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rx @ rz @ np.diag(scale)
    m[:3, 3] = position
    return m


@pytest.mark.parametrize("shape, scaled", [("SQUARE", "RECTANGLE"), ("DISK", "ELLIPSE"), ("RECTANGLE", "RECTANGLE")])
def test_matrix_places_and_scales_an_area_light_as_cycles(shape, scaled):
    """Cycles: axis u = column 0 x size, axis v = column 1 x size_y (size for
    a square or disk); measured in Blender 3.4, a square scaled (2, 0.5, 1)
    bakes bit-identical to a 2 x 0.5 rectangle."""
    m = blender_matrix(0.7, (2.0, 0.5, 3.0))
    points = [(x, y, 0.0) for x in (-0.5, 0.1, 0.6) for y in (-0.4, 0.3)]
    size_y = 0.3 if shape == "RECTANGLE" else 0.4
    placed = light_values(points, shape=shape, size=0.4, size_y=0.3, matrix=m)
    explicit = light_values(points, shape=scaled, size=0.8, size_y=0.5 * size_y, position=m[:3, 3],
                            direction=-m[:3, 2], axis_x=m[:3, 0])
    np.testing.assert_allclose(placed, explicit, rtol=1e-5)
    corners = outline(m[:3, 3], -m[:3, 2], m[:3, 0], 0.8, 0.5 * size_y, scaled)
    np.testing.assert_allclose(placed, area_value(corners, points), rtol=0.015)
    # Accepted as nested lists too (a mathutils.Matrix converts the same way).
    np.testing.assert_array_equal(light_values(points, shape=shape, size=0.4, size_y=0.3, matrix=m.tolist()), placed)


def test_a_mirrored_matrix_turns_an_area_light_round():
    """A negative Z scale flips the emitting side, as in Cycles (measured: the
    floor under such a light bakes black)."""
    points = [(0.0, 0.0, 0.0), (0.3, 0.2, 0.0)]
    down = light_values(points, shape="SQUARE", size=0.5, matrix=blender_matrix(0.0, (1, 1, 1), tilt_x=0.0))
    up = light_values(points, shape="SQUARE", size=0.5, matrix=blender_matrix(0.0, (1, 1, -1), tilt_x=0.0))
    assert down.min() > 0.5 and np.all(up == 0.0)


@pytest.mark.parametrize("kind", ["point", "spot", "sun"])
def test_spin_and_scale_leave_round_lights_alone(kind):
    """Cycles 3.4's point, spot and sun lights are round: a spot scaled (2, 1, 1)
    and spun bakes bit-identical to the plain one (measured in Blender 3.4)."""
    params = dict(energy=30.0, shadow_soft_size=0.05)
    params.update(dict(spot_size=1.0, spot_blend=0.2) if kind == "spot" else {})
    params.update(dict(angle=0.1) if kind == "sun" else {})
    if kind == "sun":
        params.pop("shadow_soft_size")
    points = np.array([(x, y, 0.0) for x in (-0.4, 0.0, 0.35) for y in (-0.3, 0.25)])
    normals = np.tile(UP, (len(points), 1))

    def values(**placement):
        scene = lmrefine.Scene()
        scene.add_light(kind, **params, **placement)
        return lmrefine.evaluate(scene, points, normals, samples=64, seed=2)

    plain = values(matrix=blender_matrix(0.0, (1, 1, 1)))
    assert plain.max() > 0
    np.testing.assert_allclose(values(matrix=blender_matrix(1.1, (2.0, 1.0, 0.5))), plain, rtol=1e-5)
    m = blender_matrix(0.0, (1, 1, 1))
    np.testing.assert_allclose(values(position=m[:3, 3], direction=-m[:3, 2], axis_x=m[:3, 1]), plain, rtol=1e-5)


@pytest.mark.parametrize("params, message", [
    (dict(direction=(0, 0, -1), axis_x=(0, 0, 2)), "axis_x is parallel to direction"),
    (dict(axis_x=(0, 0, 0)), "axis_x must not be zero"),
    (dict(axis_x=(np.nan, 1, 0)), "axis_x must be finite"),
    (dict(axis_x=(1, 0)), "axis_x must be 3 numbers"),
    (dict(matrix=np.eye(3)), "matrix must be a 4x4"),
    (dict(matrix=np.eye(4), position=(0, 0, 1)), "pass either matrix= or position/direction/axis_x"),
    (dict(matrix=np.diag([1.0, 0.0, 1.0, 1.0])), "zero scale"),
    (dict(matrix=np.full((4, 4), 0.5)), "bottom row (0, 0, 0, 1)"),
    (dict(matrix=np.where(np.eye(4) > 0, np.inf, 0.0)), "light matrix must be finite"),
])
def test_bad_orientation_is_a_clear_error(params, message):
    scene = lmrefine.Scene()
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        scene.add_light("area", energy=1.0, **params)
    assert scene.light_count == 0
