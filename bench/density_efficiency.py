"""What a texel of the refined map is worth: at the evaluation's transition
points, the refined map's equal-error resolution against the plain bakes
read at the same points, beside the resolution its texel density there
would be worth in a uniform layout (the square root of its area gain),
binned by that gain, by the texels' anisotropy on the surface and by the
gain across the light change (docs/evaluation.md, "What a texel of the
refined map is worth").

    PYTHONPATH=python /usr/bin/python3 bench/density_efficiency.py fence_and_tree [--variant smart] [--resolution 256]

Bakes and points are `lmrefine evaluate`'s (20000 points, truth 2 x 256
samples, transitions the top decile of the truth's gradient, the plain
bakes at R x {1, 1.5, 2, 3, 4}), the refinement `refine_uvs`' defaults
with the re-chart route given the mesh, so the overall ratio is
evaluate's. "worth" is the ratio over sqrt(area gain): 1 where the
refined map does as well as a uniform bake of the density it has there.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))

import lmrefine  # noqa: E402
from lmrefine import metrics, sample_scenes  # noqa: E402
from lmrefine.evaluation import EvaluationOptions, _bake_map, _route_mesh  # noqa: E402
from option_sweep import plain_parts  # noqa: E402


def texel_axes(corner_positions, corner_uvs, resolution):
    """(T, 2) the singular values of each triangle's map from its surface
    plane to texels (texels per unit length along the map's two principal
    directions, largest first); 0 for triangles without area."""
    positions = np.asarray(corner_positions, np.float64)
    uvs = np.asarray(corner_uvs, np.float64) * resolution
    e1, e2 = positions[:, 1] - positions[:, 0], positions[:, 2] - positions[:, 0]
    length = np.linalg.norm(e1, axis=1)
    normal = np.cross(e1, e2)
    good = (length > 0) & (np.linalg.norm(normal, axis=1) > 0)
    x = np.where(good[:, None], e1, 1.0) / np.where(good, length, 1.0)[:, None]
    y = np.cross(normal, x)
    y /= np.maximum(np.linalg.norm(y, axis=1), 1e-300)[:, None]
    plane = np.stack([np.stack([(e1 * x).sum(1), (e1 * y).sum(1)], 1),
                      np.stack([(e2 * x).sum(1), (e2 * y).sum(1)], 1)], 2)  # columns: the edges in the plane
    texels = np.stack([uvs[:, 1] - uvs[:, 0], uvs[:, 2] - uvs[:, 0]], 2)
    good &= np.abs(np.linalg.det(plane)) > 0
    out = np.zeros((len(positions), 2))
    out[good] = np.linalg.svd(texels[good] @ np.linalg.inv(plane[good]), compute_uv=False)
    return out


def measure(sample, options):
    """Per point: squared errors of the refined map and of the plain bakes
    (one row per multiplier), the transition mask, and the refined layout's
    area gain, texel anisotropy and gains across and along the light
    change at the point, plus the refinement's report."""
    resolution = options.resolution
    uvs, triangles = sample.layout(options.variant)
    parts = plain_parts(sample, options)
    baseline, density, points, stencil = parts["baseline"], parts["density"], parts["points"], parts["stencil"]
    truth, neighbours, transitions, sweep = parts["truth"], parts["neighbours"], parts["transitions"], parts["sweep"]
    areas = sample.triangle_areas()
    padding = min(float(options.padding),
                  float(lmrefine.check_layout(uvs, triangles, resolution, options.padding)["min_gutter_texels"]))
    refined = lmrefine.refine_uvs(baseline, uvs, triangles, resolution, padding=padding,
                                  **_route_mesh(sample, options))
    refined_map = _bake_map(sample, refined.uvs, resolution, options, None)
    lookup = metrics.bilinear_lookup(refined_map, metrics.interpolate_corners(refined.uvs, points.triangle,
                                                                               points.bary))

    def squared(values):
        return ((values[:, :3] - truth) ** 2).mean(axis=1)

    corners = sample.positions[sample.triangles]
    gain = (metrics.texel_density(refined.uvs, triangles, areas, resolution) / np.maximum(density, 1e-300))
    axes = texel_axes(corners, np.asarray(refined.uvs)[triangles], resolution)
    anisotropy = axes[:, 0] / np.maximum(axes[:, 1], 1e-300)
    across = metrics.surface_gradient_direction(points.points, truth, stencil, neighbours)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[points.triangle]
    normals /= np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
    along = np.cross(normals, across)

    def linear_gain(direction):
        before = metrics.texels_across(corners, np.asarray(uvs)[triangles], points.triangle, direction, resolution)
        after = metrics.texels_across(corners, np.asarray(refined.uvs)[triangles], points.triangle, direction,
                                      resolution)
        return after / np.maximum(before, 1e-300)

    return {"refined": squared(lookup), "plain": np.array([squared(s["lookup"]) for s in sweep]),
            "transitions": transitions, "gain": gain[points.triangle],
            "anisotropy": anisotropy[points.triangle], "across": linear_gain(across),
            "along": linear_gain(along), "has_direction": np.linalg.norm(across, axis=1) > 0,
            "report": refined.report}


def worth(parts, where, multipliers):
    """(points, share of the transition points' refined error, equal-error
    ratio of the refined map over the points `where`, sqrt(median area gain))."""
    if not where.any():
        return 0, 0.0, float("nan"), float("nan")
    errors = [float(np.sqrt(row[where].mean())) for row in parts["plain"]]
    ratio, _ = metrics.equal_error_resolution(multipliers, errors, float(np.sqrt(parts["refined"][where].mean())))
    share = parts["refined"][where].sum() / max(parts["refined"][parts["transitions"]].sum(), 1e-300)
    return int(where.sum()), float(share), ratio, float(np.sqrt(np.median(parts["gain"][where])))


def table(parts, title, key, edges, multipliers):
    print(f"\n{title}\n{'bin':>12} {'points':>7} {'error share':>12} {'ratio':>7} {'sqrt(gain)':>11} {'worth':>7}")
    transitions = parts["transitions"] & parts["has_direction"]
    for low, high in zip(edges[:-1], edges[1:]):
        count, share, ratio, expected = worth(parts, transitions & (parts[key] >= low) & (parts[key] < high),
                                              multipliers)
        if count >= 10:
            print(f"{f'{low:g}-{high:g}':>12} {count:>7} {share:>12.1%} {ratio:>7.2f} {expected:>11.2f} "
                  f"{ratio / expected:>7.2f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene")
    parser.add_argument("--variant", default="smart")
    parser.add_argument("--resolution", type=int, default=256)
    args = parser.parse_args(argv)
    sample = sample_scenes.load_sample(args.scene)
    options = EvaluationOptions(resolution=args.resolution, variant=args.variant)
    parts = measure(sample, options)
    multipliers = options.multipliers
    everywhere = np.ones(len(parts["refined"]), bool)
    count, _, ratio, _ = worth(parts, everywhere, multipliers)
    print(f"{args.scene} ({args.variant}) at {args.resolution}^2: equal-error ratio {ratio:.2f}x over {count} points")
    transitions = parts["transitions"] & parts["has_direction"]
    count, _, ratio, expected = worth(parts, transitions, multipliers)
    print(f"transition points: {count}, ratio {ratio:.2f}x, sqrt(median area gain) {expected:.2f}, worth "
          f"{ratio / expected:.2f}; median gain across the light change {np.median(parts['across'][transitions]):.2f}, "
          f"along it {np.median(parts['along'][transitions]):.2f}; texel anisotropy median "
          f"{np.median(parts['anisotropy'][transitions]):.2f}")
    table(parts, "by area gain", "gain", [0, 1, 2, 3, 4, 6, 9, 16, 1e9], multipliers)
    table(parts, "by texel anisotropy (largest over smallest texels per unit length; 1 = square on the surface)",
          "anisotropy", [1, 1.3, 1.7, 2.5, 4, 1e9], multipliers)
    table(parts, "by gain across the light change (texels per unit length)", "across",
          [0, 1, 1.5, 2, 2.5, 3, 4, 1e9], multipliers)


if __name__ == "__main__":
    main()
