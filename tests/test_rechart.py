"""Re-charting (lmrefine.rechart, docs/refiner.md "Re-charting"): charts of a
mesh by face normals, least-squares conformal unwraps, packed into a valid
layout. The charting is checked against a plain reference beside it."""

import collections

import numpy as np
import pytest

import lmrefine
from lmrefine import _native
from lmrefine.charting import corner_triangles


# --- meshes -------------------------------------------------------------------

def cube(split=False):
    """A unit cube, 12 triangles wound outwards; split: every face its own
    4 vertices (coincident positions, as a UV split leaves them)."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    if not split:
        return corners, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int32)
    positions, triangles = [], []
    for quad in quads:
        base = len(positions)
        positions += [corners[i] for i in quad]
        triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(positions), np.array(triangles, np.int32)


def grid(n, size=1.0, jitter=0.0, seed=0):
    """An n x n quad grid in the z = 0 plane, interior vertices jittered."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.linspace(0, size, n + 1), np.linspace(0, size, n + 1))
    positions = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    interior = (xs.ravel() > 0) & (xs.ravel() < size) & (ys.ravel() > 0) & (ys.ravel() < size)
    positions[interior, :2] += rng.uniform(-jitter, jitter, (interior.sum(), 2)) * size / n
    triangles = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j
            triangles += [(a, b, c), (a, c, d)]
    return positions, np.array(triangles, np.int32)


def cylinder(segments, height=2.0, radius=1.0, rings=1):
    """An open tube around z, wound outwards; segment k is triangles 2k, 2k+1 of each ring."""
    angles = 2 * np.pi * np.arange(segments) / segments
    positions = np.array([[radius * np.cos(a), radius * np.sin(a), height * r / rings]
                          for r in range(rings + 1) for a in angles])
    triangles = []
    for r in range(rings):
        for k in range(segments):
            a, b = r * segments + k, r * segments + (k + 1) % segments
            triangles += [(a, b, b + segments), (a, b + segments, a + segments)]
    return positions, np.array(triangles, np.int32)


def turned(positions, seed=3):
    """The same mesh under a random rotation and offset (a chart's shape must not care)."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return positions @ q.T + rng.normal(size=3)


def split_per_triangle(positions, triangles):
    """Every triangle its own three vertices (Lightmap Pack's cut, on the mesh)."""
    return positions[triangles.reshape(-1)], np.arange(3 * len(triangles), dtype=np.int32).reshape(-1, 3)


# --- a plain reference of the charting ----------------------------------------

def reference_charts(positions, triangles, angle, polygons=None):
    """Chart id per triangle, as grow_charts defines it: exact weld, edges of
    two oppositely wound faces, largest area class (log2 in 64ths) first,
    then index; a chart takes every face reachable across such edges whose
    normal is within `angle` of its seed's, and with a face every face of
    its polygon (`polygons`: an id per triangle, None: each its own)."""
    positions = np.asarray(positions, np.float32).astype(np.float64)
    keys = {}
    weld = np.array([keys.setdefault(tuple(p), i) for i, p in enumerate(positions)])
    tris = weld[triangles]
    cross = np.cross(positions[tris[:, 1]] - positions[tris[:, 0]], positions[tris[:, 2]] - positions[tris[:, 0]])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    uses = collections.defaultdict(list)
    for t, tri in enumerate(tris):
        for k in range(3):
            a, b = int(tri[k]), int(tri[(k + 1) % 3])
            uses[(min(a, b), max(a, b))].append((t, a < b))
    neighbours = collections.defaultdict(list)
    for edge_uses in uses.values():
        if len(edge_uses) == 2 and edge_uses[0][1] != edge_uses[1][1]:
            neighbours[edge_uses[0][0]].append(edge_uses[1][0])
            neighbours[edge_uses[1][0]].append(edge_uses[0][0])
    polygons = np.arange(len(tris)) if polygons is None else np.asarray(polygons)
    mates = collections.defaultdict(list)
    for t, polygon in enumerate(polygons.tolist()):
        mates[polygon].append(t)
    order = sorted(range(len(tris)), key=lambda t: (-np.floor(np.log2(area[t]) * 64), t))
    chart = np.full(len(tris), -1)
    count = 0
    for seed in order:
        if chart[seed] >= 0:
            continue
        stack = []
        for g in mates[polygons[seed]]:
            chart[g] = count
            stack.append(g)
        while stack:
            f = stack.pop()
            for g in neighbours[f]:
                if chart[g] < 0 and normal[g] @ normal[seed] >= np.cos(np.radians(angle)):
                    for h in mates[polygons[g]]:
                        if chart[h] < 0:
                            chart[h] = count
                            stack.append(h)
        count += 1
    return chart


def same_partition(a, b):
    pairs = set(zip(a.tolist(), b.tolist()))
    return len(pairs) == len(set(a.tolist())) == len(set(b.tolist()))


def overlapping_pairs(uvs, triangles):
    """Pairs of triangles whose interiors intersect (separating-axis test on
    every pair: the plain check, no grid)."""
    corners = np.asarray(uvs, np.float64)[triangles]
    scale = np.ptp(corners.reshape(-1, 2), axis=0).max()
    found = []
    for i in range(len(corners)):
        for j in range(i + 1, len(corners)):
            p, q = corners[i], corners[j]
            separated = False
            for shape in (p, q):
                for k in range(3):
                    e = shape[(k + 1) % 3] - shape[k]
                    axis = np.array([-e[1], e[0]])
                    a, b = p @ axis, q @ axis
                    if min(a.max(), b.max()) - max(a.min(), b.min()) <= 1e-6 * scale * np.linalg.norm(axis):
                        separated = True
            if not separated:
                found.append((i, j))
    return found


def corner_angles(corners):
    angles = []
    for k in range(3):
        a = corners[:, (k + 1) % 3] - corners[:, k]
        b = corners[:, (k + 2) % 3] - corners[:, k]
        cosine = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cosine, -1, 1))))
    return np.stack(angles, axis=1)


# --- chart counts -------------------------------------------------------------

@pytest.mark.parametrize("angle", [10.0, 45.0, 66.0, 89.0])
@pytest.mark.parametrize("split", [False, True])
def test_cube_makes_six_charts(angle, split):
    positions, triangles = cube(split)
    _, charts, report = _native.rechart_mesh(positions, triangles, angle)
    assert report["charts"] == 6 and report["split_charts"] == 0
    # The two triangles of each side share a chart, no two sides do.
    np.testing.assert_array_equal(charts[0::2], charts[1::2])
    assert len(set(charts[0::2].tolist())) == 6


@pytest.mark.parametrize("angle", [1.0, 66.0])
def test_plane_is_one_chart_even_split_per_triangle(angle):
    positions, triangles = split_per_triangle(*grid(6, jitter=0.3))
    _, charts, report = _native.rechart_mesh(turned(positions), triangles, angle)
    assert report["charts"] == 1
    assert report["welded_vertices"] == len(positions) - 49


def test_weld_tolerance_joins_nearly_coincident_vertices():
    positions, triangles = split_per_triangle(*grid(4))
    rng = np.random.default_rng(5)
    noisy = positions + rng.uniform(-1e-8, 1e-8, positions.shape)
    assert _native.rechart_mesh(noisy, triangles, 66.0)[2]["charts"] == 1   # default: 1e-6 of the size
    assert _native.rechart_mesh(noisy, triangles, 66.0, weld_tolerance=0.0)[2]["charts"] == len(triangles)


@pytest.mark.parametrize("angle,expected", [(10.0, 24), (20.0, 12), (40.0, 8), (66.0, 4), (80.0, 4)])
def test_cylinder_chart_count(angle, expected):
    # 24 segments, 15 degrees apart, equal faces: seeds in index order. At
    # 20 degrees segment 0 takes -1..1, then 2 takes 2..3, ..., 20 takes
    # 20..21 and 22 is left: 12 charts. At 40 segment 0 takes -2..2, then 3 takes 3..5, ...,
    # 18 takes 18..20 and 21 is left alone: 8 charts. At 66: 0 takes -4..4,
    # then 5..9, 10..14, 15..19: 4.
    positions, triangles = cylinder(24)
    _, charts, report = _native.rechart_mesh(positions, triangles, angle)
    assert report["charts"] == expected
    assert same_partition(charts, reference_charts(positions, triangles, angle))


def radial_normals(positions):
    """A tube's smooth shading normals, per vertex: outwards from its axis."""
    normals = positions.copy()
    normals[:, 2] = 0.0
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def test_smooth_shaded_edges_join_within_the_smooth_angle():
    # The 24-segment tube smooth-shaded: its edges join within smooth_angle
    # (40: 8 charts, as test_cylinder_chart_count at 40), not the angle (10: 24).
    positions, triangles = cylinder(24)
    smooth = radial_normals(positions)
    _, charts, report = _native.rechart_mesh(positions, triangles, 10.0, normals=smooth, smooth_angle=40.0)
    assert report["charts"] == 8
    assert same_partition(charts, reference_charts(positions, triangles, 40.0))
    # Per corner gives the same; flat-shaded normals (each face's own) are hard edges, as no normals.
    per_corner = _native.rechart_mesh(positions, triangles, 10.0, normals=smooth[triangles].reshape(-1, 3),
                                      smooth_angle=40.0)
    assert np.array_equal(per_corner[1], charts)
    corners = positions[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flat = np.repeat(face / np.linalg.norm(face, axis=1, keepdims=True), 3, axis=0)
    assert _native.rechart_mesh(positions, triangles, 10.0, normals=flat, smooth_angle=40.0)[2]["charts"] == 24
    # A zero or non-finite normal makes its edges hard: never an error.
    for bad in (0.0, np.nan, np.inf, 1e38):
        broken = smooth.copy()
        broken[::2] = bad
        _, parts, _ = _native.rechart_mesh(positions, triangles, 10.0, normals=broken, smooth_angle=40.0)
        assert len(np.unique(parts)) >= 8
    # Through the public entry: a valid packed layout that reports the angle used.
    uvs, report = lmrefine.rechart(positions, triangles, 10.0, 64, normals=smooth, smooth_angle=40.0)
    assert report["charts"] == 8 and report["smooth_angle"] == 40.0 and report["layout"]["valid"]
    assert lmrefine.rechart(positions, triangles, 10.0, 64)[1]["smooth_angle"] is None


@pytest.mark.parametrize("angle", [15.0, 40.0, 66.0])
def test_charting_matches_the_reference_on_a_bumpy_surface(angle):
    positions, triangles = grid(14)
    x, y = positions[:, 0], positions[:, 1]
    positions[:, 2] = 0.15 * np.sin(7 * x) * np.cos(5 * y) + 0.3 * x * y
    _, charts, report = _native.rechart_mesh(positions, triangles, angle)
    if report["split_charts"] == 0:
        assert same_partition(charts, reference_charts(positions, triangles, angle))
    assert report["charts"] >= report["grown_charts"]


def quad_polygons(count):
    """grid()'s polygons: triangles 2k and 2k + 1 are quad k."""
    return np.arange(count) // 2


def split_polygons(charts, polygons):
    """How many polygons have triangles in more than one chart."""
    pairs = {(p, c) for p, c in zip(polygons.tolist(), charts.tolist())}
    return len(pairs) - len(set(polygons.tolist()))


@pytest.mark.parametrize("angle", [15.0, 20.0, 40.0])
def test_a_polygons_triangles_stay_in_one_chart(angle):
    # The bumpy quad grid: its angle cuts run through quads' diagonals unless the
    # quads are given as polygons (the triangles of a quad share two corners' UVs
    # in Blender, so a cut there cannot be written to a UV map).
    positions, triangles = grid(14)
    x, y = positions[:, 0], positions[:, 1]
    positions[:, 2] = 0.15 * np.sin(7 * x) * np.cos(5 * y) + 0.3 * x * y
    polygons = quad_polygons(len(triangles))
    _, alone, _ = _native.rechart_mesh(positions, triangles, angle)
    assert split_polygons(alone, polygons) > 0  # the cut the polygons prevent
    _, charts, report = _native.rechart_mesh(positions, triangles, angle, polygons=polygons)
    assert split_polygons(charts, polygons) == 0
    if report["split_charts"] == 0:
        assert same_partition(charts, reference_charts(positions, triangles, angle, polygons))
    # Ids are labels: any int32 values, in any order.
    _, relabelled, _ = _native.rechart_mesh(positions, triangles, angle, polygons=7 - 3 * polygons)
    assert same_partition(charts, relabelled)
    packed, packed_report = lmrefine.rechart(positions, triangles, angle, 128, 2.0, polygons=polygons)
    assert packed_report["layout"]["valid"] and split_polygons(packed_report["chart_ids"], polygons) == 0


def test_a_split_chart_is_cut_between_polygons():
    # test_a_chart_that_would_overlap_itself_is_split's helical fan, its triangles
    # paired into polygons: the chart that overlaps itself is split between pairs.
    turns = np.radians(30.0) * np.arange(16)
    rim = np.stack([np.cos(turns), np.sin(turns), 0.02 * np.arange(16)], axis=1)
    positions = np.concatenate([[[0.0, 0.0, 0.0]], rim])
    triangles = np.array([(0, k, k + 1) for k in range(1, 16)], np.int32)
    polygons = np.arange(15) // 2
    _, alone, _ = _native.rechart_mesh(positions, triangles, 66.0)
    assert split_polygons(alone, polygons) > 0
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 66.0, polygons=polygons)
    assert report["split_charts"] >= 1 and report["charts"] >= 2 and split_polygons(charts, polygons) == 0
    for c in range(report["charts"]):
        mine = np.flatnonzero(charts == c)
        assert overlapping_pairs(uvs, corner_triangles(len(triangles))[mine]) == [], c
    # The fan flat (every normal +z: no angle tells its triangles apart, so the
    # chart is bisected at once) and widening: the halves still end between pairs.
    rim[:, 2] = 0.0
    rim[:, :2] *= (1 + 0.03 * np.arange(16))[:, None]
    positions = np.concatenate([[[0.0, 0.0, 0.0]], rim])
    _, alone, _ = _native.rechart_mesh(positions, triangles, 66.0)
    assert split_polygons(alone, polygons) > 0
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 66.0, polygons=polygons)
    assert report["charts"] >= 2 and split_polygons(charts, polygons) == 0
    for c in range(report["charts"]):
        mine = np.flatnonzero(charts == c)
        assert overlapping_pairs(uvs, corner_triangles(len(triangles))[mine]) == [], c
    # The folded grid with its quads as polygons: still a layout that overlaps nowhere.
    positions, triangles = grid(20, jitter=0.45, seed=0)
    polygons = quad_polygons(len(triangles))
    packed, packed_report = lmrefine.rechart(positions, triangles, 10.0, 128, 2.0, polygons=polygons)
    assert packed_report["layout"]["valid"] and split_polygons(packed_report["chart_ids"], polygons) == 0


@pytest.mark.parametrize("polygons,words", [
    (np.zeros(5, np.int32), "polygons must have shape (12,)"),
    (np.zeros((12, 1), np.int32), "polygons must have shape (12,)"),
    (np.zeros(12) + 0.5, "polygons must be an integer array"),
    (np.full(12, 1 << 40), "outside the int32 range"),
])
def test_bad_polygons_raise_a_clear_error(polygons, words):
    positions, triangles = cube()
    with pytest.raises(ValueError) as caught:
        lmrefine.rechart(positions, triangles, 66.0, 64, polygons=polygons)
    assert words in str(caught.value)


# --- the conformal map --------------------------------------------------------

def test_planar_chart_is_an_isometry():
    # Jittered grid, turned into a random plane: the unwrap (scaled to world
    # area) keeps every angle and every length.
    positions, triangles = grid(8, size=3.0, jitter=0.35, seed=2)
    positions = turned(positions)
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 66.0)
    assert report["charts"] == 1
    uv = uvs.astype(np.float64).reshape(-1, 3, 2)
    world = positions[triangles]
    np.testing.assert_allclose(corner_angles(uv), corner_angles(world), atol=1e-3)
    uv_lengths = np.linalg.norm(uv - np.roll(uv, 1, axis=1), axis=2)
    world_lengths = np.linalg.norm(world - np.roll(world, 1, axis=1), axis=2)
    np.testing.assert_allclose(uv_lengths, world_lengths, rtol=1e-4)
    # Counter-clockwise, as the faces are wound seen from their front.
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    assert np.all(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0)


def test_developable_chart_keeps_its_angles():
    # A cylinder strip is developable: its conformal map is an isometry too.
    positions, triangles = cylinder(24, rings=3)
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 66.0)
    uv = uvs.astype(np.float64).reshape(-1, 3, 2)
    np.testing.assert_allclose(corner_angles(uv), corner_angles(positions[triangles]), atol=1e-3)


def test_curved_chart_is_nearly_conformal_and_keeps_world_area():
    # A sphere cap is not developable: angles stay close, the chart's area
    # is its world area.
    positions, triangles = grid(12, size=1.0)
    x, y = positions[:, 0] - 0.5, positions[:, 1] - 0.5
    positions[:, 2] = np.sqrt(4.0 - x * x - y * y)
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 66.0)
    assert report["charts"] == 1
    uv = uvs.astype(np.float64).reshape(-1, 3, 2)
    error = np.abs(corner_angles(uv) - corner_angles(positions[triangles]))
    assert error.mean() < 0.5 and error.max() < 3.0
    uv_area = 0.5 * np.abs(np.cross(uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0])).sum()
    world = positions[triangles]
    world_area = 0.5 * np.linalg.norm(np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0]), axis=1).sum()
    assert uv_area == pytest.approx(world_area, rel=1e-5)


def test_a_chart_that_would_overlap_itself_is_split():
    # A helical fan: 15 near-horizontal triangles around one vertex turning
    # 450 degrees. Its normals are within a few degrees of each other, so it
    # grows into one chart, but flattened it overlaps itself.
    turns = np.radians(30.0) * np.arange(16)
    rim = np.stack([np.cos(turns), np.sin(turns), 0.02 * np.arange(16)], axis=1)
    positions = np.concatenate([[[0.0, 0.0, 0.0]], rim])
    triangles = np.array([(0, k, k + 1) for k in range(1, 16)], np.int32)
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 66.0)
    assert report["grown_charts"] == 1 and report["split_charts"] >= 1 and report["charts"] >= 2
    for c in range(report["charts"]):
        mine = np.flatnonzero(charts == c)
        assert overlapping_pairs(uvs, corner_triangles(len(triangles))[mine]) == [], c


def test_a_folded_input_is_cut_around_the_fold_not_into_single_faces():
    # A grid jittered so far that 4 of its 800 triangles turned over: the
    # plane folds onto itself there. No angle separates the fold from the
    # rest of its chart, so the chart is cut in halves until it unwraps.
    positions, triangles = grid(20, jitter=0.45, seed=0)
    corners = positions[triangles]
    flipped = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2] < 0
    assert flipped.sum() == 4
    uvs, charts, report = _native.rechart_mesh(positions, triangles, 10.0)
    assert report["split_charts"] > 0 and report["charts"] < 50
    for c in range(report["charts"]):
        mine = np.flatnonzero(charts == c)
        assert overlapping_pairs(uvs, corner_triangles(len(triangles))[mine]) == [], c
    packed, packed_report = lmrefine.rechart(positions, triangles, 10.0, 128, 2.0)
    assert packed_report["layout"]["valid"]


# --- the packed layout --------------------------------------------------------

def meshes():
    bumpy = grid(10)
    bumpy[0][:, 2] = 0.2 * np.sin(5 * bumpy[0][:, 0])
    return {"cube": cube(), "cylinder": cylinder(16, rings=2), "plane": grid(5, jitter=0.3), "bumpy": bumpy,
            "cube_split": cube(split=True)}


@pytest.mark.parametrize("name", sorted(meshes()))
@pytest.mark.parametrize("resolution,padding", [(64, 2.0), ((48, 80), 1.0)])
def test_layout_is_valid_with_the_padding(name, resolution, padding):
    positions, triangles = meshes()[name]
    before = positions.copy(), triangles.copy()
    uvs, report = lmrefine.rechart(positions, triangles, 66.0, resolution, padding)
    np.testing.assert_array_equal(positions, before[0])  # inputs untouched
    np.testing.assert_array_equal(triangles, before[1])
    assert uvs.shape == (3 * len(triangles), 2) and uvs.dtype == np.float32
    check = lmrefine.check_layout(uvs, corner_triangles(len(triangles)), resolution, padding)
    assert check["valid"] and check["min_gutter_texels"] >= padding, check
    assert report["layout"]["valid"]
    assert overlapping_pairs(uvs, corner_triangles(len(triangles))) == []
    # Uniform texel density: every triangle's UV area over its world area is one number.
    world = positions[triangles]
    world_area = 0.5 * np.linalg.norm(np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0]), axis=1)
    uv = uvs.astype(np.float64).reshape(-1, 3, 2)
    uv_area = 0.5 * np.abs(np.cross(uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]))
    if name != "bumpy":  # developable: exactly uniform
        np.testing.assert_allclose(uv_area / world_area, np.median(uv_area / world_area), rtol=1e-3)
    assert report["density_spread"] < 1.5


def test_deterministic():
    positions, triangles = meshes()["bumpy"]
    first = lmrefine.rechart(positions, triangles, 40.0, 128, 2.0)
    second = lmrefine.rechart(positions, triangles, 40.0, 128, 2.0)
    assert first.uvs.tobytes() == second.uvs.tobytes()
    np.testing.assert_array_equal(first.report["chart_ids"], second.report["chart_ids"])


def test_sample_scene_layout_is_valid():
    from lmrefine.sample_scenes import load_sample

    scene = load_sample("room")
    uvs, report = lmrefine.rechart(scene.positions, scene.triangles, resolution=256, padding=2.0)
    assert report["layout"]["valid"] and report["charts"] == report["layout"]["charts"]
    assert report["utilisation"] > 0.8


# --- bad input ----------------------------------------------------------------

def test_degenerate_triangles_get_charts_of_their_own():
    positions, triangles = cube()
    positions = np.concatenate([positions, [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0], [7.0, 7.0, 7.0]]])
    extra = np.array([(0, 0, 1), (8, 9, 10), (2, 3, 3)], np.int32)  # repeated corner, collinear, repeated
    triangles = np.concatenate([triangles, extra])
    uvs, report = lmrefine.rechart(positions, triangles, 66.0, 64, 2.0)
    assert report["degenerate_triangles"] == 3 and report["charts"] == 9
    assert report["layout"]["valid"]


def test_a_pile_of_copies_welds_without_quadratic_cost():
    # 60,000 copies of three positions (Lightmap Pack's split, taken to the
    # extreme) weld into one triangle's worth of vertices.
    positions = np.tile(np.array([[0, 0, 0], [1, 0, 0], [0, 1, -0.0]], np.float32), (20000, 1))
    positions[3::3, 2] = 0.0  # -0 and 0 are one position
    triangles = np.arange(60000, dtype=np.int32).reshape(-1, 3)
    _, charts, report = _native.rechart_mesh(positions, triangles, 10.0)
    assert report["welded_vertices"] == 59997
    # Every edge is shared by all 20,000 faces: no neighbours, a chart each.
    assert report["charts"] == 20000 and report["degenerate_triangles"] == 0


def test_loose_vertices_are_ignored_even_when_not_finite():
    positions, triangles = cube()
    positions = np.concatenate([positions, [[np.nan, 0.0, np.inf]]])
    uvs, report = lmrefine.rechart(positions, triangles, 66.0, 64, 2.0)
    assert report["charts"] == 6 and report["layout"]["valid"]


@pytest.mark.parametrize("change,error,words", [
    (lambda p, t: (p, t[:0]), ValueError, "triangles"),
    (lambda p, t: (p, np.concatenate([t, [[0, 1, 99]]])), ValueError, "triangles"),
    (lambda p, t: (p, np.concatenate([t, [[0, 1, -1]]])), ValueError, "triangles"),
    (lambda p, t: (np.where(np.arange(len(p))[:, None] == 3, np.nan, p), t), ValueError, "positions[3]"),
    (lambda p, t: (p[:, :2], t), ValueError, "positions"),
    (lambda p, t: (p, np.concatenate([t, t[:, :1]], axis=1)), ValueError, "triangles"),  # quads: triangulate first
    (lambda p, t: (p, t.astype(np.float64) + 0.5), (ValueError, TypeError), "triangles"),
    (lambda p, t: (np.zeros_like(p), t), ValueError, "degenerate"),
])
def test_bad_mesh_raises_a_clear_error(change, error, words):
    positions, triangles = change(*cube())
    with pytest.raises(error, match=None) as caught:
        lmrefine.rechart(positions, triangles, 66.0, 64, 2.0)
    assert words in str(caught.value)


@pytest.mark.parametrize("kwargs,error,words", [
    ({"angle": 0.0}, ValueError, "angle"),
    ({"angle": 90.0}, ValueError, "angle"),
    ({"angle": float("nan")}, ValueError, "angle"),
    ({"angle": True}, TypeError, "angle"),
    ({"angle": "66"}, TypeError, "angle"),
    ({"smooth_angle": 0.0}, ValueError, "smooth_angle"),
    ({"smooth_angle": 95.0}, ValueError, "smooth_angle"),
    ({"normals": np.ones((5, 3))}, ValueError, "normals must be per vertex (8, 3) or per corner (36, 3)"),
    ({"normals": np.full((8, 3), "x")}, ValueError, "normals must hold real numbers"),
    ({"weld_tolerance": -1.0}, ValueError, "weld_tolerance"),
    ({"weld_tolerance": 0.5}, ValueError, "weld_tolerance"),  # half the cube: would merge its corners
    ({"resolution": 0}, ValueError, "resolution"),
    ({"padding": -1.0}, ValueError, "padding"),
    ({"resolution": 4, "padding": 8.0}, ValueError, ""),
])
def test_bad_settings_raise_a_clear_error(kwargs, error, words):
    positions, triangles = cube()
    with pytest.raises(error) as caught:
        lmrefine.rechart(positions, triangles, **{"resolution": 64, **kwargs})
    assert words in str(caught.value)


@pytest.mark.parametrize("scale, weld_tolerance, message", [
    # A weld tolerance given for a tiny mesh: the size was printed as 0.000000 (std::to_string).
    (1e-10, 1e-6, "weld_tolerance 1e-06 is more than 1% of the mesh's size (1.73e-10 across): it would merge "
                  "distinct vertices; give a distance far below the smallest modelled detail, or None (1e-6 of "
                  "the mesh's size)"),
    # Every corner at one point: the weld tolerance was blamed.
    (0.0, 1e-6, "every one of the 12 triangles is degenerate, all corners at one position: the mesh has no "
                "extent (give the object a non-zero scale), so there is no surface to chart"),
    (0.0, None, "every one of the 12 triangles is degenerate, all corners at one position"),
    # A mesh too small for the packer to scale up: the padding, the resolution and the scales were blamed.
    (1e-13, None, "the mesh is too small to lay out: its 12 triangles hold 6e-26 square units of surface, its "
                  "widest chart is 1e-13 units across, and charts keep their world size until the packer scales "
                  "them up, by at most 1e+12; scale the mesh up (apply its object scale, or model in larger units)"),
    (1e-20, None, "the mesh is too small to lay out"),
])
def test_a_mesh_too_small_or_without_extent_is_named(scale, weld_tolerance, message):
    positions, triangles = cube()
    with pytest.raises(ValueError) as caught:
        lmrefine.rechart(positions * scale, triangles, 66.0, 64, weld_tolerance=weld_tolerance)
    assert str(caught.value).startswith(message)


@pytest.mark.parametrize("scale", [1e-12, 5e-13, 1e30])
def test_a_small_or_large_mesh_the_packer_can_scale_is_laid_out(scale):
    positions, triangles = cube()
    uvs, report = lmrefine.rechart(positions * scale, triangles, 66.0, 64)
    assert report["layout"]["valid"] and report["utilisation"] > 0.3


def test_progress_reports_and_cancels():
    positions, triangles = cylinder(32, rings=4)
    stages = []
    lmrefine.rechart(positions, triangles, 66.0, 128, 2.0, progress=lambda f, s: stages.append(s) or True)
    assert any("rechart" in s for s in stages)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.rechart(positions, triangles, 66.0, 128, 2.0, progress=lambda f, s: False)
