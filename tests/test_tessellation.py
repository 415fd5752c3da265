"""Tessellation along light transitions (python/lmrefine/tessellation.py):
where it splits, and that the surface and every UV map keep their mapping."""

import numpy as np
import pytest

from lmrefine.tessellation import UV_SLACK, coarse_transitions, peak_strength, tessellate, transition_strength_of

R = 64


def bent_grid(n=4, seam=False):
    """An n x n grid of quads over [0, 1]^2, bent along x (a roof: not planar),
    two triangles per quad; per-corner UVs = (x, y) inset in [0.05, 0.95]
    (with `seam`, the right half's UVs are shifted by +0.01 in v: its edge
    with the left half is a UV seam)."""
    xs = np.linspace(0, 1, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    z = 0.3 * (0.5 - np.abs(x - 0.5))
    positions = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    triangles = []
    for j in range(n):
        for i in range(n):
            v = j * (n + 1) + i
            triangles += [(v, v + 1, v + n + 2), (v, v + n + 2, v + n + 1)]
    triangles = np.array(triangles)
    corners = positions[triangles.ravel()]
    uvs = 0.05 + 0.9 * corners[:, :2]
    if seam:
        right = np.repeat(positions[triangles][:, :, 0].mean(axis=1) > 0.5, 3)
        uvs[right, 1] += 0.01
    return positions, triangles, uvs.astype(np.float32)


def edge_strength(position=0.5):
    """A transition along the vertical line u = position: strength 1 on the
    two texel columns beside it, 0 elsewhere."""
    strength = np.zeros((R, R))
    column = int(position * R)
    strength[:, column - 1:column + 1] = 1.0
    return strength


def barycentric(points, corners):
    """Barycentric coordinates of 3-D points in their triangles (least squares on the plane)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    basis = np.stack([b - a, c - a], axis=2)  # (T, 3, 2)
    out = np.empty((len(points), 3))
    for t in range(len(points)):
        w, *_ = np.linalg.lstsq(basis[t], points[t] - a[t], rcond=None)
        out[t] = (1 - w.sum(), w[0], w[1])
    return out


def test_splits_only_triangles_the_transition_crosses():
    positions, triangles, uvs = bent_grid()
    inputs = [a.copy() for a in (positions, triangles, uvs)]
    result = tessellate(positions, triangles, uvs, edge_strength(0.4), budget=16.0, min_texels=8)
    for before, after in zip(inputs, (positions, triangles, uvs)):
        np.testing.assert_array_equal(before, after)  # the inputs are not modified
    report = result.report
    assert report["vertices_added"] > 0 and report["triangles_after"] > report["triangles_before"]
    # Triangles far from the line u = 0.39 (every corner well away from it) are untouched.
    original_uv = uvs.reshape(-1, 3, 2)
    far = (np.abs(original_uv[..., 0] - 0.39) > 0.25).all(axis=1)
    out_uv = result.uvs.reshape(-1, 3, 2)
    for t in np.nonzero(far)[0]:
        children = np.nonzero(result.parent == t)[0]
        assert len(children) == 1 and np.array_equal(out_uv[children[0]], original_uv[t])
    # Every triangle over the transition was split down to min_texels or below.
    texels = 0.5 * np.abs(np.cross(out_uv[:, 1] - out_uv[:, 0], out_uv[:, 2] - out_uv[:, 0])) * R * R
    band = (out_uv[..., 0].min(axis=1) < 26 / R) & (out_uv[..., 0].max(axis=1) > 24 / R)  # strength 1 columns
    assert band.sum() > 20 and texels[band].max() <= 8 + 1e-9
    assert report["stopped"] == "every triangle a transition crosses is at most min_texels"


@pytest.mark.parametrize("seam", [False, True])
def test_surface_and_every_uv_map_keep_their_mapping(seam):
    positions, triangles, uvs = bent_grid(seam=seam)
    other = np.random.default_rng(1).random((len(uvs), 2))  # a texture map: any per-corner values
    normals = np.tile([0.0, 0.0, 1.0], (len(uvs), 1))
    other_before = other.copy()
    result = tessellate(positions, triangles, uvs, edge_strength(0.37), budget=1.0, min_texels=4,
                        corner_attributes={"texture": other, "normal": normals})
    assert result.report["vertices_added"] > 10
    np.testing.assert_array_equal(other, other_before)
    corners_in = positions[triangles]                    # (T, 3, 3)
    corners_out = result.positions[result.triangles]     # (T', 3, 3)
    parent = result.parent
    # Each output corner lies in its parent triangle's plane, inside it: the surface is unchanged.
    bary = barycentric(corners_out.reshape(-1, 3), np.repeat(corners_in[parent], 3, axis=0))
    assert bary.min() > -1e-9 and bary.max() < 1 + 1e-9
    rebuilt = np.einsum("nk,nkd->nd", bary, np.repeat(corners_in[parent], 3, axis=0))
    np.testing.assert_allclose(rebuilt, corners_out.reshape(-1, 3), atol=1e-12)
    # Every per-corner map is the parent's affine map at the same barycentrics (seams keep their sides).
    for values_in, values_out in ((uvs, result.uvs), (other, result.corner_attributes["texture"]),
                                  (normals, result.corner_attributes["normal"])):
        expected = np.einsum("nk,nkd->nd", bary, np.repeat(values_in.reshape(-1, 3, values_in.shape[1])[parent], 3,
                                                           axis=0))
        np.testing.assert_allclose(values_out, expected, atol=1e-6)
    # Areas (3-D and UV) add up to the parent's, and orientation is kept.
    def areas(c):
        return np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    cross_in, cross_out = areas(corners_in), areas(corners_out)
    np.testing.assert_allclose(np.bincount(parent, weights=np.linalg.norm(cross_out, axis=1)),
                               np.linalg.norm(cross_in, axis=1), rtol=1e-9)
    assert (np.einsum("td,td->t", cross_out, cross_in[parent]) > 0).all()


def test_no_t_junctions():
    positions, triangles, uvs = bent_grid(n=3)
    result = tessellate(positions, triangles, uvs, edge_strength(0.61), budget=2.0, min_texels=2)
    p, tris = result.positions, result.triangles
    assert result.report["vertices_added"] > 5
    # No vertex lies strictly inside another triangle's edge (a crack in the making).
    for a, b in {tuple(sorted((t[k], t[(k + 1) % 3]))) for t in tris.tolist() for k in range(3)}:
        d = p[b] - p[a]
        s = ((p - p[a]) @ d) / (d @ d)
        off = np.linalg.norm(p - p[a] - np.outer(s, d), axis=1)
        inside = (s > 1e-9) & (s < 1 - 1e-9) & (off < 1e-9)
        assert not inside.any(), f"vertex {np.nonzero(inside)[0]} splits edge {(a, b)} without its triangles"
    # A manifold grid stays one: every edge is used by one (border) or two triangles.
    counts = {}
    for t in tris.tolist():
        for k in range(3):
            key = tuple(sorted((t[k], t[(k + 1) % 3])))
            counts[key] = counts.get(key, 0) + 1
    assert set(counts.values()) <= {1, 2}


def test_budget_caps_the_new_vertices():
    positions, triangles, uvs = bent_grid(n=6)
    strength = np.ones((R, R))  # a transition everywhere: only the budget stops it
    for budget in (0.0, 0.1, 0.25):
        result = tessellate(positions, triangles, uvs, strength, budget=budget, min_texels=1)
        allowed = int(np.floor(budget * len(positions)))
        assert result.report["vertices_added"] == allowed
        assert result.report["stopped"] == "the vertex budget is spent"
    untouched = tessellate(positions, triangles, uvs, strength, budget=0.0)
    np.testing.assert_array_equal(untouched.triangles, triangles)
    np.testing.assert_array_equal(untouched.uvs, uvs)


def test_a_one_quad_floor_takes_a_large_budget_until_no_candidate_is_left():
    # A budget is a fraction of the vertices: a floor of one quad (4 vertices) needs
    # hundreds of times its count to split the triangles a shadow edge crosses.
    positions, triangles, uvs = bent_grid(n=1)
    strength = edge_strength(0.4)
    small = tessellate(positions, triangles, uvs, strength, budget=16.0, min_texels=8)
    assert small.report["vertices_added"] == 64 and small.report["stopped"] == "the vertex budget is spent"
    assert small.report["candidates_left"] > 0
    full = tessellate(positions, triangles, uvs, strength, budget=1024.0, min_texels=8)
    assert 64 < full.report["vertices_added"] < 1024 * 4
    assert full.report["candidates_left"] == 0
    assert full.report["stopped"] == "every triangle a transition crosses is at most min_texels"
    with pytest.raises(ValueError, match=r"budget must be a fraction of the vertex count in \[0, 1024\]"):
        tessellate(positions, triangles, uvs, strength, budget=1025.0)


def test_splits_are_held_to_the_lightmap_texels():
    positions, triangles, uvs = bent_grid(n=1)
    tiny = np.ones((4, 4))  # 16 texels, a transition everywhere, no size floor: only the texel count stops it
    result = tessellate(positions, triangles, uvs, tiny, budget=1024.0, min_texels=0)
    assert result.report["vertex_budget"] == 16 and result.report["vertices_added"] == 16


def test_progress_is_reported_and_a_false_cancels():
    import lmrefine
    positions, triangles, uvs = bent_grid(n=1)
    seen = []

    def progress(fraction, stage):
        seen.append((fraction, stage))
        return True

    result = tessellate(positions, triangles, uvs, edge_strength(0.4), budget=1024.0, progress=progress)
    assert len(seen) >= result.report["rounds"] and all(stage == "tessellate" for _, stage in seen)
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and 0 <= fractions[0] and fractions[-1] <= 1
    calls = []
    with pytest.raises(lmrefine.CancelledError):
        tessellate(positions, triangles, uvs, edge_strength(0.4), budget=1024.0,
                   progress=lambda fraction, stage: calls.append(fraction) or len(calls) < 3)
    assert len(calls) == 3


def test_flat_light_and_small_triangles_are_left_alone():
    positions, triangles, uvs = bent_grid()
    flat = tessellate(positions, triangles, uvs, np.zeros((R, R)))
    assert flat.report["vertices_added"] == 0
    assert flat.report["stopped"] == "no triangle crossed by a transition is larger than min_texels"
    small = tessellate(positions, triangles, uvs, edge_strength(), min_texels=1e6)
    assert small.report["vertices_added"] == 0


def test_deterministic():
    positions, triangles, uvs = bent_grid(n=5)
    strength = np.random.default_rng(3).random((R, R))
    first = tessellate(positions, triangles, uvs, strength, budget=0.5)
    second = tessellate(positions, triangles, uvs, strength, budget=0.5)
    np.testing.assert_array_equal(first.triangles, second.triangles)
    np.testing.assert_array_equal(first.splits, second.splits)


def test_peak_strength_sees_a_line_between_the_corners():
    """A thin transition crossing the middle of a big triangle, far from its corners and centroid."""
    strength = np.zeros((R, R))
    strength[:, 20] = 1.0
    corner_uvs = np.array([[[0.05, 0.1], [0.6, 0.1], [0.05, 0.9]],   # crosses column 20 (u = 0.32)
                           [[0.5, 0.1], [0.9, 0.1], [0.5, 0.9]]])    # does not
    np.testing.assert_array_equal(peak_strength(corner_uvs, strength), [1.0, 0.0])


@pytest.mark.parametrize("change, message", [
    (lambda a: a.update(positions=np.zeros((4, 2))), "positions must be a \\(V, 3\\)"),
    (lambda a: a.update(triangles=np.array([[0, 1, 99]])), "triangles index vertices outside"),
    (lambda a: a.update(uvs=np.zeros((5, 2))), "uvs must be per corner"),
    # Beyond float32 the split's UVs came back inf (found by a crash hunt).
    (lambda a: a.update(uvs=a["uvs"] * 1e300), "uvs must lie in \\[0, 1\\], a lightmap layout"),
    (lambda a: a.update(strength=np.zeros(5)), "strength must be an \\(H, W\\)"),
    (lambda a: a.update(budget=-1), "budget must be"),
    (lambda a: a.update(threshold=2), "threshold must be in"),
    (lambda a: a.update(corner_attributes={"n": np.zeros((2, 3))}), "corner attribute 'n' must be per corner"),
])
def test_bad_input_is_named(change, message):
    positions, triangles, uvs = bent_grid(n=1)
    args = {"positions": positions, "triangles": triangles, "uvs": uvs, "strength": np.zeros((R, R))}
    change(args)
    with pytest.raises(ValueError, match=message):
        tessellate(**args)


@pytest.mark.parametrize("far", [3.5e38, 1e300, -4e38])
def test_uvs_past_float32_are_refused_before_they_turn_inf(far):
    # float64 UVs finite here and inf as the split's float32 output (found by a crash hunt): the
    # [0, 1] check (UV_SLACK) refuses them, naming their span.
    positions, triangles, uvs = bent_grid(n=2)
    uvs = uvs.astype(np.float64)
    uvs[4, 1] = far
    with pytest.raises(ValueError) as raised:
        tessellate(positions, triangles, uvs, np.ones((R, R)), budget=1.0)
    low, high = (0.05, far) if far > 0 else (far, 0.95)
    assert str(raised.value) == (f"uvs must lie in [0, 1], a lightmap layout (they span {low:.6g} to {high:.6g}): "
                                 "pass the lightmap's UVs, packed into the unit square")


def test_uvs_within_the_rounding_slack_come_back_finite():
    positions, triangles, uvs = bent_grid(n=2)
    uvs = uvs.astype(np.float64)
    uvs[4] = (1.0 + UV_SLACK, -UV_SLACK)
    result = tessellate(positions, triangles, uvs, np.ones((R, R)), budget=1.0, min_texels=0.0)
    assert result.report["vertices_after"] > result.report["vertices_before"] and np.isfinite(result.uvs).all()


def test_a_triangle_that_repeats_a_vertex_is_left_alone_with_its_edges():
    # Found by the fuzz suite: a triangle (a, b, a) lists edge (a, b) twice.
    positions, triangles, uvs = bent_grid()
    t = 5
    a, b, _ = triangles[t]
    triangles = np.vstack([triangles, [[a, b, a]]])
    uvs = np.vstack([uvs, uvs[3 * t:3 * t + 3][[0, 1, 0]]])
    result = tessellate(positions, triangles, uvs, np.ones((R, R)), budget=16.0, min_texels=8)
    last = len(triangles) - 1
    children = np.nonzero(result.parent == last)[0]
    assert len(children) == 1 and list(result.triangles[children[0]]) == [a, b, a]
    assert result.report["vertices_added"] > 0  # the rest is split
    # Its edge (a, b) is never split (the triangle would then lose b).
    assert {(a, b), (b, a)}.isdisjoint((p, q) for p, q, _ in result.splits)


def _step_lightmap(position=0.4):
    """A lightmap with a hard shadow edge along u = position (dark left, lit right)."""
    lightmap = np.ones((R, R, 3), np.float32)
    lightmap[:, :int(position * R)] = 0.05
    return lightmap


def test_coarse_transitions_counts_what_tessellation_would_split():
    lightmap = _step_lightmap()
    # A 2 x 2 grid at 64^2: 8 triangles of ~260 texels; the edge at u = 0.4 crosses the left column's 4
    # (triangles 0, 1, 4, 5).
    positions, triangles, uvs = bent_grid(n=2)
    corner_triangles = np.arange(3 * len(triangles)).reshape(-1, 3)
    coarse = coarse_transitions(lightmap, uvs, corner_triangles)
    assert coarse["triangles"] == 4 and coarse["texels"] > 4 * 200
    strength = transition_strength_of(lightmap, uvs, corner_triangles)
    first_round = tessellate(positions, triangles, uvs, strength, budget=16.0)
    assert {0, 1, 4, 5} <= set(first_round.parent[len(triangles):])  # the left column's four are split
    # The same light on a fine grid (triangles of ~2 texels): nothing is coarse.
    positions, triangles, uvs = bent_grid(n=40)
    assert coarse_transitions(lightmap, uvs, np.arange(3 * len(triangles)).reshape(-1, 3))["triangles"] == 0
    # No light change: nothing either.
    assert coarse_transitions(np.ones((R, R, 3), np.float32), uvs,
                              np.arange(3 * len(triangles)).reshape(-1, 3))["triangles"] == 0


def test_light_contrast_tells_a_shadow_edge_from_a_falloff():
    from lmrefine.tessellation import COARSE_CONTRAST, light_contrast

    mask = np.ones((64, 64), bool)
    x = (np.arange(64) + 0.5) / 64
    step = np.repeat(np.where(x < 0.5, 1.0, 0.2)[None, :, None], 64, axis=0).repeat(3, axis=2)
    ramp = np.repeat((0.8 + 0.1 * x)[None, :, None], 64, axis=0).repeat(3, axis=2)  # 10% over the map
    assert light_contrast(step, mask) == pytest.approx(0.8 / 0.6)  # a 0.8 step over the median 0.6
    assert light_contrast(ramp, mask) == pytest.approx(0.1 / 64 / 0.85, rel=0.02)
    assert light_contrast(ramp, mask) < COARSE_CONTRAST < light_contrast(step, mask)
    assert light_contrast(np.full((64, 64, 3), 0.5), mask) == 0.0
    lonely = np.zeros((64, 64), bool)
    lonely[::2, ::2] = True  # no two covered texels side by side
    assert light_contrast(step, lonely) == 0.0
    # The step only counts where both texels are covered.
    left = mask.copy()
    left[:, 32:] = False
    assert light_contrast(step, left) == 0.0


def test_the_budget_a_split_needs_reads_as_two_digits_rounded_up():
    from lmrefine.tessellation import budget_to_end
    # +60 vertices to 9: 6.67 -> 6.7; to 16: 2.75 -> 2.8; a budget below it would stop the split short.
    assert [budget_to_end(a, v) for a, v in ((60, 9), (44, 16), (291, 289), (80, 915), (576, 9), (0, 9))] == \
        [6.7, 2.8, 1.1, 0.088, 64.0, 0.0]
    assert all(budget_to_end(a, v) >= a / v for a, v in ((1, 3), (7, 11), (1000, 7), (5, 100000)))


def test_a_round_samples_only_what_the_last_one_split():
    # The candidates after a round, from the peaks kept and the changed rows sampled again,
    # are those a full sampling finds.
    from lmrefine.tessellation import _candidates
    positions, triangles, uvs = bent_grid(n=6)
    strength = np.tile(np.linspace(0.0, 1.0, R) ** 2, (R, 1))  # a ramp: a piece's peak is not its parent's
    first = tessellate(positions, triangles, uvs, strength, budget=0.15, min_texels=1)  # one round
    corner_uvs = first.uvs.astype(np.float64).reshape(-1, 3, 2)
    _, before, _ = _candidates(np.asarray(uvs, np.float64).reshape(-1, 3, 2), strength, 1, 0.25)
    split = np.unique(first.parent[len(triangles):])  # the input rows the split changed in place
    kept = _candidates(corner_uvs, strength, 1, 0.25, previous=before, changed=split)
    full = _candidates(corner_uvs, strength, 1, 0.25)
    assert first.report["rounds"] == 1 and len(split) > 5
    for a, b in zip(kept, full):
        np.testing.assert_array_equal(a, b)


def min_angles(corners):
    """(T,) each triangle's smallest angle in degrees (corners (T, 3, 2) or (T, 3, 3))."""
    angles = []
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        v = corners[:, (k + 2) % 3] - corners[:, k]
        cos = np.einsum("td,td->t", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.min(angles, axis=0)


@pytest.mark.parametrize("position", [0.3, 0.52, 0.77])
def test_every_piece_is_cut_along_its_longest_edge_so_no_sliver_is_made(position):
    # Quads three times longer than wide in the lightmap (a table leg, a beam), a light change
    # across them. Cutting a neighbour along the edge its partner chose, not its own longest,
    # makes slivers; bisecting each triangle along its own longest edge keeps the smallest
    # angle at least half the mesh's (Rivara).
    positions, triangles, uvs = bent_grid(n=4)
    uvs = uvs.copy()
    uvs[:, 1] = 0.05 + (uvs[:, 1] - 0.05) / 3.0
    strength = np.zeros((R, R))
    strength[:, int(position * R) - 1:int(position * R) + 1] = 1.0
    result = tessellate(positions, triangles, uvs, strength, budget=8.0, min_texels=1)
    assert result.report["vertices_added"] > 20
    texel = R * np.asarray(uvs, np.float64).reshape(-1, 3, 2)
    smallest_before = min_angles(texel).min()
    after = min_angles(R * result.uvs.astype(np.float64).reshape(-1, 3, 2))
    assert after.min() >= 0.5 * smallest_before - 1e-6
