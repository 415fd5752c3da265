"""lmrefine.dilate, the baker's gutter fill for maps baked elsewhere, against
a plain reference of its rule; and that it is the baker's own."""

import numpy as np
import pytest

import lmrefine
from baker_scenes import floor, quad

REACH = 1.5  # kNearChartReach: a bilinear lookup reads texel centres less than sqrt(2) away


def squared_distance_to_triangle(point, corners):
    """Plain: 0 inside (or on the border), else the nearest of the three edges."""
    sides = [np.cross(corners[(i + 1) % 3] - corners[i], point - corners[i]) for i in range(3)]
    if all(s >= 0 for s in sides) or all(s <= 0 for s in sides):
        return 0.0
    best = np.inf
    for i in range(3):
        a, b = corners[i], corners[(i + 1) % 3]
        ab = b - a
        t = np.clip(np.dot(point - a, ab) / np.dot(ab, ab), 0.0, 1.0) if np.dot(ab, ab) > 0 else 0.0
        q = a + ab * t
        best = min(best, float(np.dot(q - point, q - point)))
    return best


def dilate_reference(image, uvs, triangles, rings):
    """The rule, plainly: covered texels keep their colour (the first chart to cover one owns it); a
    gutter texel whose centre is within REACH of a chart takes the nearest such chart (the smaller
    id on a tie); each ring, every gutter texel touching filled texels takes the float32 mean of its
    neighbours of its near chart if it has any, else of the chart with most neighbours (smaller id on
    a tie), and belongs to that chart for the next ring."""
    height, width = image.shape[:2]
    charts = lmrefine.find_charts(uvs, triangles)
    owner = np.full((height, width), -1)
    for t in range(len(triangles)):
        covered = lmrefine.coverage_mask(uvs, triangles[t:t + 1], (height, width))
        owner[covered & (owner < 0)] = charts[t]
    near = np.full((height, width), -1)
    distance = np.full((height, width), np.inf, dtype=np.float32)
    pixels = np.asarray(uvs, np.float64)[triangles] * [width, -height] + [0.0, height]  # pixel space
    for t in range(len(triangles)):
        for row in range(height):
            for col in range(width):
                if owner[row, col] >= 0:
                    continue
                d = np.float32(squared_distance_to_triangle(np.array([col + 0.5, row + 0.5]), pixels[t]))
                if d < REACH * REACH and (near[row, col] < 0 or d < distance[row, col]
                                          or (d == distance[row, col] and charts[t] < near[row, col])):
                    near[row, col], distance[row, col] = charts[t], d
    out = np.array(image, dtype=np.float32)
    rgb = out[..., :3]
    for _ in range(rings):
        filled = owner.copy()
        for row in range(height):
            for col in range(width):
                if owner[row, col] >= 0:
                    continue
                sums, counts = {}, {}
                for dr in (-1, 0, 1):
                    for dc in (-1, 0, 1):
                        r, c = row + dr, col + dc
                        if (dr, dc) == (0, 0) or not (0 <= r < height and 0 <= c < width) or owner[r, c] < 0:
                            continue
                        chart = owner[r, c]
                        sums[chart] = sums.get(chart, np.zeros(3, np.float32)) + rgb[r, c]
                        counts[chart] = counts.get(chart, 0) + 1
                if not counts:
                    continue
                best = min(counts, key=lambda chart: (-counts[chart], chart))
                if near[row, col] in counts:
                    best = near[row, col]
                rgb[row, col] = sums[best] / np.float32(counts[best])
                filled[row, col] = best
        if (filled == owner).all():
            break
        owner = filled
    return out


def random_charts(rng, count):
    """Triangles and quads at random places in [0.05, 0.95]^2, often a texel or two apart."""
    uvs, triangles = [], []
    for _ in range(count):
        x, y = rng.uniform(0.05, 0.7, 2)
        w, h = rng.uniform(0.08, 0.25, 2)
        corners = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]], np.float32)
        base = len(uvs) * 4
        uvs.append(corners)
        triangles += [[base, base + 1, base + 2]] + ([[base, base + 2, base + 3]] if rng.random() < 0.7 else [])
    return np.concatenate(uvs), np.array(triangles, np.int32)


@pytest.mark.parametrize("seed", range(4))
def test_dilate_follows_its_plain_rule(seed):
    rng = np.random.default_rng(seed)
    uvs, triangles = random_charts(rng, 5)
    channels = 4 if seed % 2 else 3
    image = rng.random((20, 24, channels), dtype=np.float32)
    before = image.copy()
    for rings in (1, 16):
        dilated = lmrefine.dilate(image, uvs, triangles, rings)
        np.testing.assert_array_equal(image, before)  # the input is not modified
        assert dilated.shape == image.shape and dilated.dtype == np.float32
        np.testing.assert_array_equal(dilated[..., :3], dilate_reference(image, uvs, triangles, rings)[..., :3])
        if channels == 4:
            np.testing.assert_array_equal(dilated[..., 3], image[..., 3])  # alpha as given


def test_dilate_is_the_bakers_own_gutter_fill():
    # Charts 2 texels apart, where the nearest-chart rule decides (test_baker_bake), and a third far off.
    scene = lmrefine.Scene()
    layouts = [floor(uv_rect=(0.0, 0.0, 9.05 / 32, 0.6)),
               quad(([3, -1, 0], [3, 1, 0], [5, -1, 0]), (11.05 / 32, 0.0, 0.9, 0.6)),
               quad(([0, 0, 1], [1, 0, 1], [0, 1, 1]), (0.2, 0.75, 0.6, 0.95))]
    for positions, triangles, uvs in layouts:
        scene.add_mesh(positions, triangles, uvs=uvs)
    scene.add_light("sun", energy=2.0, angle=0.1, direction=(0.3, 0.2, -1))
    plain = lmrefine.bake(scene, 32, samples=4, dilation=0, atlas=True)["atlas"]
    baked = lmrefine.bake(scene, 32, samples=4, dilation=16, atlas=True)["atlas"]
    uvs = np.concatenate([layout[2] for layout in layouts]).astype(np.float32)
    triangles = np.arange(len(uvs), dtype=np.int32).reshape(-1, 3)
    np.testing.assert_array_equal(lmrefine.dilate(plain, uvs, triangles, 16)[..., :3], baked[..., :3])


def test_dilate_refuses_bad_input_with_the_fix():
    uvs, triangles = random_charts(np.random.default_rng(0), 2)
    image = np.zeros((8, 8, 4), np.float32)
    with pytest.raises(ValueError, match="astype"):
        lmrefine.dilate(image.astype(np.float64), uvs, triangles)
    with pytest.raises(ValueError, match=r"\(H, W, 3\) or \(H, W, 4\)"):
        lmrefine.dilate(np.zeros((8, 8, 2), np.float32), uvs, triangles)
    with pytest.raises(ValueError, match="image"):
        lmrefine.dilate(np.zeros((8, 8), np.float32), uvs, triangles)
    bad = uvs.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN|finite"):
        lmrefine.dilate(image, bad, triangles)
    with pytest.raises(ValueError, match="texels"):
        lmrefine.dilate(image, uvs, triangles, -1)
    with pytest.raises(ValueError, match="refers to UV 100"):
        lmrefine.dilate(image, uvs, triangles + 100)


def test_dilate_does_not_depend_on_the_thread_count(monkeypatch):
    rng = np.random.default_rng(7)
    uvs, triangles = random_charts(rng, 8)
    image = rng.random((70, 90, 3), dtype=np.float32)  # more rows than one task takes
    every = lmrefine.dilate(image, uvs, triangles)
    monkeypatch.setenv("LMREFINE_THREADS", "1")
    np.testing.assert_array_equal(lmrefine.dilate(image, uvs, triangles), every)
    monkeypatch.setenv("LMREFINE_THREADS", "3")
    np.testing.assert_array_equal(lmrefine.dilate(image, uvs, triangles), every)


def test_dilate_takes_uvs_far_outside_the_map():
    # Corners 1e30 away: no crash and no overflow; covered texels keep their colour, every filled one is finite.
    rng = np.random.default_rng(1)
    image = rng.random((16, 16, 3), dtype=np.float32)
    uvs = np.array([[-1e30, -1e30], [1e30, 0.5], [0.5, 1e30], [0.1, 0.1], [0.3, 0.1], [0.1, 0.3]], np.float32)
    triangles = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    for layout in (uvs, uvs * np.float32(1e-30) + np.float32(40.0)):  # the second: both far off the map
        dilated = lmrefine.dilate(image, layout, triangles)
        covered = lmrefine.coverage_mask(layout, triangles, 16)
        np.testing.assert_array_equal(dilated[covered], image[covered])
        assert np.isfinite(dilated).all()
        np.testing.assert_array_equal(lmrefine.dilate(image, layout, triangles), dilated)
