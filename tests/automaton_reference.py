"""The automaton's rule in plain numpy: one synchronous step, guards off.

The rule as docs/refiner.md ("The automaton") and docs/method.md (section 4)
state it; the fast native version is `apply_rule` in
native/src/automaton/automaton_step.cpp. Every quantity of the new state is
computed from the old one only:

1. per cell: area (of the quadrilateral of its four nodes), the move radius
   (a cell's corners may move c / (2 (|a| + |b|)) at a corner with edges a, b
   and cross product c; 0 for a cell that is not convex), the diffusion
   density energy / area (0 outside chart cells) and the pressure per axis
   (the energies of the axis plus the reference density times the cell's
   uncovered area, over its area);
2. per edge between 4-neighbours: a flux diffusion x min(area) x (density
   difference of the two channels facing the edge), between chart cells
   only, and a push (p_a - p_b) / (p_a + p_b) from the pressures across it;
3. new energies (each flux leaves one cell and enters the other, clipped at
   0 for rounding) and node moves: rate / 2 x sqrt(mean area of the node's
   cells) x (sum of the pushes of the two edges along x, along y), shortened
   to the smallest move radius of its cells, border nodes sliding along the
   border (or fixed: corners, `border_rule`, `extra_ring`), clamped to the
   grid's rectangle.

Operations are written in the native code's order so the results can be
compared to the last bit where the compiler does not fuse them.
"""

import numpy as np

MATERIAL, GUTTER, RING = 0, 1, 2


def cross(ax, ay, bx, by):
    return ax * by - ay * bx


def sequential_sum(values):
    """Left to right, as a C loop adds (numpy's sum adds pairwise)."""
    return float(np.cumsum(np.asarray(values, np.float64))[-1]) if len(values) else 0.0


def cell_shapes(nodes):
    """Area and move radius of every cell of (R + 1, C + 1, 2) nodes."""
    q = [nodes[:-1, :-1], nodes[:-1, 1:], nodes[1:, 1:], nodes[1:, :-1]]  # around the cell
    d1, d2 = q[2] - q[0], q[3] - q[1]
    area = 0.5 * cross(d1[..., 0], d1[..., 1], d2[..., 0], d2[..., 1])
    e = [q[(k + 1) % 4] - q[k] for k in range(4)]
    l2 = [ek[..., 0] * ek[..., 0] + ek[..., 1] * ek[..., 1] for ek in e]
    convex = np.ones(area.shape, bool)
    r2 = np.full(area.shape, np.inf)
    for k in range(4):
        p = (k + 3) % 4
        c = cross(e[p][..., 0], e[p][..., 1], e[k][..., 0], e[k][..., 1])
        convex &= c > 0
        r2 = np.minimum(r2, (c * c) / (8 * (l2[p] + l2[k])))
    return area, np.where(convex, np.sqrt(r2), 0.0)


def push(a, b):
    total = a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, (a - b) / np.where(total > 0, total, 1.0), 0.0)


def rule_step(energy, mask, nodes, *, diffusion, rate, border):
    """One step of the rule on a level of one-texel cells.

    energy: float32 (H, W) or (H, W, 4) (r facing down, g right, b up, a
    left); mask: bool (H, W), True = covered, or None; nodes: float64
    (R + 1, C + 1, 2) in pixel space, with R = H + 2 and C = W + 2 for
    border='extra_ring' (its ring of neutral cells), else R = H, C = W.
    Returns (new nodes, new energies (R, C[, 4]) float64, difference).
    """
    energy = np.asarray(energy, np.float32)
    height, width = energy.shape[:2]
    channels = 4 if energy.ndim == 3 else 1
    axes = 2 if channels == 4 else 1
    # The channel facing each side: down, right, up, left.
    down, right, up, left = (0, 1, 2, 3) if channels == 4 else (0, 0, 0, 0)
    covered = np.ones((height, width), bool) if mask is None else np.asarray(mask, bool)
    pad = 1 if border == "extra_ring" else 0
    rows, cols = height + 2 * pad, width + 2 * pad
    inner = (slice(pad, pad + height), slice(pad, pad + width))

    e = level_energy(energy, mask, border).reshape(rows, cols, channels)
    uncovered = np.zeros((rows, cols))
    uncovered[inner] = ~covered
    kind = np.full((rows, cols), MATERIAL)
    kind[uncovered >= 1] = GUTTER
    if pad:
        uncovered[[0, -1], :] = uncovered[:, [0, -1]] = 1.0
        kind[[0, -1], :] = kind[:, [0, -1]] = RING
    material = kind == MATERIAL
    # Reference density per channel: energy of the chart cells over their
    # (original, one-texel) area; per axis the sum of the axis' channels.
    reference_density = [sequential_sum(e[..., k][material]) / material.sum() if material.any() else 0.0
                         for k in range(channels)]
    reference = [sequential_sum([reference_density[k] for k in range(axis, channels, axes)])
                 for axis in range(axes)]

    area, radius = cell_shapes(nodes)
    diffusion_density = np.where(material[..., None], e / area[..., None], 0.0)
    pressure = np.stack([(sequential_sum_axis(e, range(axis, channels, axes)) + reference[axis] * uncovered) / area
                         for axis in range(axes)], axis=-1)
    py, px = pressure[..., 0], pressure[..., axes - 1]  # across horizontal edges (y), vertical edges (x)

    # Vertical edges (R, C + 1) between cells (i, j - 1) and (i, j); horizontal
    # edges (R + 1, C) between cells (i - 1, j) and (i, j); border edges 0.
    push_v, flux_v = np.zeros((rows, cols + 1)), np.zeros((rows, cols + 1))
    push_h, flux_h = np.zeros((rows + 1, cols)), np.zeros((rows + 1, cols))
    push_v[:, 1:-1] = push(px[:, :-1], px[:, 1:])
    both = material[:, :-1] & material[:, 1:]
    flux_v[:, 1:-1] = np.where(both, diffusion * np.minimum(area[:, :-1], area[:, 1:])
                               * (diffusion_density[:, :-1, right] - diffusion_density[:, 1:, left]), 0.0)
    push_h[1:-1, :] = push(py[:-1, :], py[1:, :])
    both_h = material[:-1, :] & material[1:, :]
    flux_h[1:-1, :] = np.where(both_h, diffusion * np.minimum(area[:-1, :], area[1:, :])
                               * (diffusion_density[:-1, :, down] - diffusion_density[1:, :, up]), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        relative_x = np.abs(px[:, :-1] - px[:, 1:])[both].max(initial=0.0)
        relative_y = np.abs(py[:-1, :] - py[1:, :])[both_h].max(initial=0.0)
    difference = max(relative_x / reference[axes - 1] if reference[axes - 1] > 0 else 0.0,
                     relative_y / reference[0] if reference[0] > 0 else 0.0)

    new_energy = e.copy()
    new_energy[..., left] += flux_v[:, :-1]
    new_energy[..., right] -= flux_v[:, 1:]
    new_energy[..., up] += flux_h[:-1, :]
    new_energy[..., down] -= flux_h[1:, :]
    new_energy = np.maximum(new_energy, 0.0)

    # Node (i, j): the vertical edges above and below it move it in x, the
    # horizontal edges left and right of it in y; missing ones (outside) add 0.
    fx = np.zeros((rows + 2, cols + 1))
    fx[1:-1] = push_v
    fx = fx[:-1] + fx[1:]
    fy = np.zeros((rows + 1, cols + 2))
    fy[:, 1:-1] = push_h
    fy = fy[:, :-1] + fy[:, 1:]
    padded_area = np.zeros((rows + 2, cols + 2))
    padded_area[1:-1, 1:-1] = area
    padded_radius = np.full((rows + 2, cols + 2), np.inf)
    padded_radius[1:-1, 1:-1] = radius
    present = np.zeros((rows + 2, cols + 2))
    present[1:-1, 1:-1] = 1
    # The node's cells in the order (i - 1, j - 1), (i - 1, j), (i, j - 1), (i, j).
    around = [(slice(0, -1), slice(0, -1)), (slice(0, -1), slice(1, None)),
              (slice(1, None), slice(0, -1)), (slice(1, None), slice(1, None))]
    area_sum = np.zeros((rows + 1, cols + 1))
    smallest_radius = np.full((rows + 1, cols + 1), np.inf)
    adjacent = np.zeros((rows + 1, cols + 1))
    for cell in around:
        area_sum = area_sum + padded_area[cell]
        smallest_radius = np.minimum(smallest_radius, padded_radius[cell])
        adjacent = adjacent + present[cell]
    size = np.sqrt(np.where(adjacent == 4, area_sum * 0.25, area_sum / adjacent))
    scale = 0.5 * rate * size
    move_x, move_y = scale * fx, scale * fy

    top_bottom = np.zeros((rows + 1, cols + 1), bool)
    top_bottom[[0, -1], :] = True
    left_right = np.zeros((rows + 1, cols + 1), bool)
    left_right[:, [0, -1]] = True
    fixed = top_bottom & left_right
    if pad or border == "border_rule":
        fixed |= top_bottom | left_right
    move_y = np.where(top_bottom & ~fixed, 0.0, move_y)  # slides along x
    move_x = np.where(left_right & ~fixed, 0.0, move_x)  # slides along y
    length2 = move_x * move_x + move_y * move_y
    with np.errstate(invalid="ignore", divide="ignore"):
        shorten = np.where(length2 > smallest_radius * smallest_radius,
                           smallest_radius / np.sqrt(length2), 1.0)
    move_x = np.where(length2 > smallest_radius * smallest_radius, move_x * shorten, move_x)
    move_y = np.where(length2 > smallest_radius * smallest_radius, move_y * shorten, move_y)

    lo = np.array([-pad, -pad], np.float64)
    hi = np.array([width + pad, height + pad], np.float64)
    new_nodes = nodes.copy()
    new_nodes[..., 0] = np.clip(nodes[..., 0] + move_x, lo[0], hi[0])
    new_nodes[..., 1] = np.clip(nodes[..., 1] + move_y, lo[1], hi[1])
    new_nodes[fixed] = nodes[fixed]
    return new_nodes, new_energy.reshape((rows, cols) + energy.shape[2:]), difference


def level_energy(energy, mask, border):
    """The level's energies, float64 (R, C[, 4]): the texels' energies, 0 on
    uncovered texels and on the ring of extra_ring."""
    energy = np.asarray(energy, np.float32)
    height, width = energy.shape[:2]
    covered = np.ones((height, width), bool) if mask is None else np.asarray(mask, bool)
    pad = 1 if border == "extra_ring" else 0
    e = np.zeros((height + 2 * pad, width + 2 * pad) + energy.shape[2:])
    covered = covered if energy.ndim == 2 else covered[..., None]
    e[pad:pad + height, pad:pad + width] = np.where(covered, energy, 0.0)
    return e


def sequential_sum_axis(e, channels):
    """Per cell, the energies of `channels` added left to right from 0."""
    total = np.zeros(e.shape[:2])
    for k in channels:
        total = total + e[..., k]
    return total


def rest_nodes(height, width, border):
    """The level's nodes at rest, in pixel space (ring included for extra_ring)."""
    pad = 1 if border == "extra_ring" else 0
    xs = np.arange(-pad, width + pad + 1, dtype=np.float64)
    ys = np.arange(-pad, height + pad + 1, dtype=np.float64)
    return np.stack(np.meshgrid(xs, ys), axis=-1)
