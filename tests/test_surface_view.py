"""Pictures of the lit surface (lmrefine.surface_view): primary rays through
Embree, a bilinear lightmap lookup at the hit's UV, the default camera."""

import numpy as np
import pytest

import lmrefine
from lmrefine import metrics, surface_view
from lmrefine.sample_scenes import SampleScene, load_sample
from layouts import floor_grid


def plane_scene(cells=4):
    """A 2 x 2 m floor at z = 0 whose UVs are its x, y mapped onto [0.1, 0.9]."""
    positions, triangles = floor_grid(cells, 1.0)
    uvs = (0.1 + 0.8 * (positions[triangles.reshape(-1)][:, :2] + 1.0) / 2.0).astype(np.float32)
    return SampleScene(
        name="plane", positions=positions, triangles=triangles,
        normals=np.tile(np.array([0, 0, 1], np.float32), (3 * len(triangles), 1)), uvs={"smart": uvs},
        base_color=np.full((len(triangles), 3), 0.5, np.float32), object_id=np.zeros(len(triangles), np.int32),
        objects=["Floor"], lights=[{"name": "Sun", "kind": "sun", "energy": 2.0, "direction": [0, 0, -1]}])


def test_trace_rays_returns_the_closest_hit_and_its_barycentrics():
    scene = lmrefine.Scene()
    triangle = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], np.float32)
    scene.add_mesh(triangle, np.array([[0, 1, 2]]), uvs=np.array([[0, 0], [1, 0], [0, 1]], np.float32))
    scene.add_mesh(triangle + np.float32([0, 0, -1]), np.array([[0, 1, 2]]), receiver=False)
    origins = np.array([[0.5, 0.25, 3.0], [5.0, 5.0, 3.0], [0.5, 0.25, -0.5]], np.float32)
    directions = np.array([[0, 0, -2.0], [0, 0, -1], [0, 0, -1]], np.float32)
    mesh, tri, bary, distance = lmrefine.trace_rays(scene, origins, directions)
    assert mesh.tolist() == [0, -1, 1] and tri.tolist() == [0, -1, 0]
    np.testing.assert_allclose(bary[0], [0.25, 0.125], atol=1e-6)   # x = 2 u, y = 2 v
    np.testing.assert_allclose(distance[[0, 2]], [1.5, 0.5], rtol=1e-6)  # in units of |direction|
    assert np.isinf(distance[1])


@pytest.mark.parametrize("bad, words", [
    ((np.array([[0, 0, np.nan]], np.float32), np.array([[0, 0, -1]], np.float32)), "origins[0]"),
    ((np.zeros((1, 3), np.float32), np.zeros((1, 3), np.float32)), "directions[0] has zero length"),
    ((np.zeros((2, 3), np.float32), np.ones((1, 3), np.float32)), "one row per origin"),
])
def test_trace_rays_refuses_rays_embree_would_abort_on(bad, words):
    scene = plane_scene().to_scene(plane_scene().uvs["smart"])
    with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")):
        lmrefine.trace_rays(scene, *bad)


@pytest.mark.parametrize("direction, message", [
    # Called "zero length" until a crash hunt (with a length whose float32 square overflowed).
    ([0, 0, -1e300], "directions[0] is NaN or Inf (a float32 beyond 3.4e38 is Inf); give every ray a finite "
                     "direction, of any length"),
    ([0, 0, 0], "directions[0] has zero length; give every ray a direction"),
    ([0, -0.0, 0], "directions[0] has zero length; give every ray a direction"),
    ([0, 0, -1e-30], "directions[0] has length 1e-30, too short: a hit's distance, in units of the length, "
                     "would pass float32's 3.4e38; scale it towards length 1 (only the direction counts)"),
])
def test_trace_rays_names_a_direction_it_cannot_trace(direction, message):
    scene = plane_scene().to_scene(plane_scene().uvs["smart"])
    with np.errstate(over="ignore"), pytest.raises(ValueError) as raised:
        lmrefine.trace_rays(scene, np.array([[0, 0, 1.0]]), np.array([direction], np.float64))
    assert str(raised.value).startswith(message)


@pytest.mark.parametrize("length", [1e-28, 1e-22, 1e-12, 1e-6, 1.0, 1e6, 1e18, 1e20, 1e35])
@pytest.mark.parametrize("height", [1e-3, 2.0, 2e6])
def test_trace_rays_takes_any_finite_direction(length, height):
    # A direction of 1e20 was refused as "zero length", one of 1e18 to 1.8e19 missed
    # everything (Embree takes components up to 1e18) and a tiny one missed far hits
    # (Embree takes components below 1e-18 as 1e-18): traced scaled towards length 1.
    scene = plane_scene().to_scene(plane_scene().uvs["smart"])
    direction = (np.array([[0.5 / height, 0.0, -1.0]]) * length).astype(np.float32)  # to (0.6, 0.2, 0)
    mesh, _, bary, distance = lmrefine.trace_rays(scene, np.array([[0.1, 0.2, height]], np.float32), direction)
    assert mesh.tolist() == [0]
    # The distance in units of the direction's length, as float32 holds it.
    np.testing.assert_allclose(np.float64(distance[0]) * np.float64(direction[0, 2]), -height, rtol=1e-5)
    unit = lmrefine.trace_rays(scene, np.array([[0.1, 0.2, height]], np.float32), direction / direction[0, 2] * -1)
    np.testing.assert_allclose(bary, unit[2], atol=1e-5)


def test_a_constant_lightmap_renders_its_constant_on_every_receiver_pixel():
    sample = plane_scene()
    uvs = sample.uvs["smart"]
    scene = sample.to_scene(uvs)
    hits = surface_view.trace_view(sample, scene, surface_view.default_camera(sample.positions), 64)
    assert (hits.width, hits.height) == (64, 43)
    assert 0.2 * hits.receiver.size < hits.receiver.sum() < hits.receiver.size  # floor and background in view
    c = np.array([0.3, 0.6, 1.7], np.float32)
    light = hits.lookup(np.broadcast_to(c, (16, 16, 3)).copy(), uvs)
    np.testing.assert_allclose(light[hits.receiver], np.broadcast_to(c, (hits.receiver.sum(), 3)), rtol=1e-6)
    assert (light[~hits.receiver] == 0).all()


def test_a_linear_uv_to_colour_map_round_trips_through_the_bilinear_lookup():
    """A lightmap holding (u, v) at every texel centre is read back exactly
    by the bilinear lookup inside the texel centres' span, so each pixel
    shows its hit's UV; and the hit's UV is where the pixel's ray meets the
    floor (x, y through the UV mapping of the plane)."""
    size = 32
    centres = (np.arange(size) + 0.5) / size
    lightmap = np.zeros((size, size, 3), np.float32)
    lightmap[..., 0] = centres[None, :]
    lightmap[..., 1] = 1.0 - centres[:, None]  # row 0 = top = v near 1
    sample = plane_scene()
    uvs = sample.uvs["smart"]
    hits = surface_view.trace_view(sample, sample.to_scene(uvs), surface_view.default_camera(sample.positions), 48)
    light = hits.lookup(lightmap, uvs)
    where = hits.receiver
    expected_uv = 0.1 + 0.8 * (hits.points[where, :2] + 1.0) / 2.0
    np.testing.assert_allclose(light[where, :2], expected_uv, atol=2e-5)
    # And the lookup itself at random UVs inside the centres' span.
    uv = np.random.default_rng(1).uniform(0.5 / size, 1 - 0.5 / size, (500, 2))
    np.testing.assert_allclose(metrics.bilinear_lookup(lightmap, uv)[:, :2], uv, atol=1e-6)


def test_back_faces_of_receivers_are_culled_and_occluders_are_not():
    sample = plane_scene()
    sample.occluder_positions = np.array([(-0.3, -0.3, 0.5), (0.3, -0.3, 0.5), (0, 0.3, 0.5)], np.float32)
    sample.occluder_triangles = np.array([(0, 1, 2)], np.int32)
    scene = sample.to_scene(sample.uvs["smart"])
    below = surface_view.look_at((0.0, 0.0, -3.0), (0.0, 0.0, 0.0))   # sees the floor's back face
    hits = surface_view.trace_view(sample, scene, below, 32)
    assert not hits.receiver.any() and hits.occluder.any()   # through the floor to the triangle above it
    above = surface_view.look_at((0.01, 0.0, 3.0), (0.0, 0.0, 0.0))
    hits = surface_view.trace_view(sample, scene, above, 32)
    assert hits.receiver.any() and hits.occluder.any()


def test_a_scene_camera_round_trips_through_the_scene_file(tmp_path):
    sample = plane_scene()
    camera = surface_view.look_at((1.0, -2.0, 1.5), (0.0, 0.0, 0.0), aspect=2.0)
    camera.name = "Camera"
    sample.camera = camera.to_dict()
    sample.save(tmp_path / "plane.npz")
    loaded = surface_view.scene_camera(load_sample(str(tmp_path / "plane.npz")))
    assert loaded.name == "Camera" and loaded.size(100) == (100, 50)
    for a, b in zip(loaded.rays(8, 4), camera.rays(8, 4)):
        np.testing.assert_allclose(a, b, atol=1e-6)
    with pytest.raises(ValueError, match="export the scene again"):
        surface_view.camera_from_dict({"position": [0, 0, 0], "rotation": np.eye(3).tolist(),
                                       "frame": [1, -1, -1, 1, -1]})


def test_the_default_camera_frames_every_receiver():
    sample = load_sample("courtyard")
    camera = surface_view.default_camera(sample.positions)
    points = sample.positions.astype(np.float64)
    local = (points - camera.position) @ camera.rotation
    x, y = local[:, 0] / -local[:, 2], local[:, 1] / -local[:, 2]
    x0, x1, y0, y1, _ = camera.frame
    assert (local[:, 2] < 0).all()
    assert x0 <= x.min() and x.max() <= x1 and y0 <= y.min() and y.max() <= y1
    # Tight: the receivers fill the picture along one axis.
    assert max((x.max() - x.min()) / (x1 - x0), (y.max() - y.min()) / (y1 - y0)) > 0.9


def test_pictures_of_a_real_scene_have_sane_sizes_and_content(tmp_path):
    import matplotlib.image

    from lmrefine.evaluation_report import write_surface_pictures

    sample = load_sample("courtyard")
    uvs, triangles = sample.layout("smart")
    scene = sample.to_scene(uvs)
    lightmap = lmrefine.bake(scene, 64, samples=4)[0][..., :3].copy()
    views = surface_view.render_views(sample, scene, {"plain": (lightmap, uvs), "refined": (lightmap, uvs)},
                                      "direct", 8, 120)
    assert (views["hits"].width, views["hits"].height) == (120, 80)
    assert views["rmse"]["plain"] == views["rmse"]["refined"] > 0
    assert views["crops"] and all(size == 20 for _, _, size in views["crops"])
    density = metrics.texel_density(uvs, triangles, sample.triangle_areas(), 64)
    write_surface_pictures(tmp_path, {"scene": "courtyard", "variant": "smart", "resolution": 64, "truth_samples": 8},
                           views, {"plain": density, "refined": density * 2})
    for name, min_width in (("surface.png", 1000), ("surface_crops.png", 600), ("surface_density.png", 800)):
        image = matplotlib.image.imread(tmp_path / name)
        assert image.shape[1] >= min_width and image.shape[0] >= 200, name
        assert image[..., :3].std() > 0.05, name  # not a blank picture
    picture = views["pictures"]["plain"]
    receiver = views["hits"].receiver.reshape(picture.shape[:2])
    # Sunlit floor and shadows both in view: the lit pixels are far from constant.
    assert picture[receiver].std() > 0.1 and picture.max() <= 1.0
