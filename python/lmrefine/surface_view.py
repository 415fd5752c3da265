"""Pictures of the lit surface: what a player sees, not the lightmap in UV space.

A camera (the scene's own, or a default one framing the receivers) casts one
primary ray per pixel through the scene (``lmrefine.trace_rays``, Embree). A
pixel that shows a receiver is lit by a bilinear lookup of a lightmap at the
hit's UV (``metrics.bilinear_lookup``, what a GPU sampler does, the lookup the
error figures use), or by the ground truth at the hit point
(``lmrefine.evaluate``), and drawn as base colour x light. Back faces of
receivers are culled, as a game engine culls them: a single-sided wall does
not hide the room behind it. Occluders (casters without a lightmap) are drawn
in flat grey, the same in every picture.
"""

import math
from dataclasses import dataclass

import numpy as np

from . import metrics
from .baker import trace_rays

# Field of view (horizontal) and aspect of the default camera, and where it
# looks from: south-west of the receivers, 35 degrees above the horizon.
DEFAULT_FOV = math.radians(50.0)
DEFAULT_ASPECT = 1.5
DEFAULT_VIEW_DIRECTION = (-0.55, -0.72, 0.58)   # from the target towards the camera
# A back face is stepped over this often at most (a ray through a closed
# room's walls crosses two).
MAX_BACK_FACES = 8
# The exposure (the 99.5th percentile of the lit truth) is shown at this
# linear level, so bright sunlit floors keep some shading instead of clipping.
DISPLAY_WHITE = 0.8


@dataclass
class Camera:
    """A pinhole camera. `rotation` columns are the camera's x (right), y (up)
    and z (backwards: it looks along -z) in world space, as Blender's camera
    matrix_world has them; `frame` = (x_min, x_max, y_min, y_max, z) is the
    image plane in camera space (Blender's Camera.view_frame)."""

    position: np.ndarray
    rotation: np.ndarray
    frame: tuple
    name: str = "default"

    @property
    def aspect(self):
        x0, x1, y0, y1, _ = self.frame
        return (x1 - x0) / (y1 - y0)

    def size(self, width):
        """(width, height) in pixels for a picture `width` pixels wide."""
        return int(width), max(1, int(round(width / self.aspect)))

    def rays(self, width, height):
        """(origins, directions), (height * width, 3) float32 each, row 0 at
        the top of the picture, through pixel centres."""
        x0, x1, y0, y1, z = self.frame
        xs = x0 + (np.arange(width) + 0.5) / width * (x1 - x0)
        ys = y1 - (np.arange(height) + 0.5) / height * (y1 - y0)
        local = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], np.float64(z)), axis=-1).reshape(-1, 3)
        directions = local @ np.asarray(self.rotation, np.float64).T
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.broadcast_to(np.asarray(self.position, np.float64), directions.shape)
        return np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32)

    def to_dict(self):
        return {"name": self.name, "position": [float(c) for c in self.position],
                "rotation": [[float(c) for c in row] for row in self.rotation], "frame": [float(c) for c in self.frame]}


def look_at(position, target, fov=DEFAULT_FOV, aspect=DEFAULT_ASPECT, name="default"):
    """A camera at `position` looking at `target` (world +Z up), `fov` wide."""
    position, target = np.asarray(position, np.float64), np.asarray(target, np.float64)
    back = position - target
    back /= np.linalg.norm(back)
    right = np.cross((0.0, 0.0, 1.0), back)
    if np.linalg.norm(right) < 1e-6:  # looking straight down
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    half = math.tan(fov / 2)
    return Camera(position, np.stack([right, up, back], axis=1), (-half, half, -half / aspect, half / aspect, -1.0),
                  name)


def default_camera(positions, fov=DEFAULT_FOV, aspect=DEFAULT_ASPECT, direction=DEFAULT_VIEW_DIRECTION):
    """A camera framing `positions` (the receivers' vertices): it looks along
    -`direction`, centred on them and just far enough back that every one is
    in the picture."""
    positions = np.asarray(positions, np.float64)
    direction = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    target = (positions.min(axis=0) + positions.max(axis=0)) / 2
    camera = look_at(target + direction, target, fov, aspect)
    half_x, half_y = camera.frame[1], camera.frame[3]
    for _ in range(3):  # fit, then centre the picture on what it shows and fit again
        local = (positions - target) @ camera.rotation  # right, up, back
        # A point at (x, y, z) is in the picture from distance d when
        # |x| <= half_x (d - z) and |y| <= half_y (d - z).
        distance = 1.03 * max(float(np.max(local[:, 2] + np.maximum(np.abs(local[:, 0]) / half_x,
                                                                     np.abs(local[:, 1]) / half_y))), 1e-3)
        depth = distance - local[:, 2]
        x, y = local[:, 0] / depth, local[:, 1] / depth
        shift = ((x.min() + x.max()) / 2 * camera.rotation[:, 0] + (y.min() + y.max()) / 2 * camera.rotation[:, 1])
        target = target + shift * distance
    return look_at(target + distance * direction, target, fov, aspect)


def camera_from_dict(data):
    """A camera as the scene .npz stores it (Camera.to_dict; export-scene
    writes the .blend's active camera)."""
    try:
        camera = Camera(np.asarray(data["position"], np.float64).reshape(3),
                        np.asarray(data["rotation"], np.float64).reshape(3, 3),
                        tuple(float(c) for c in data["frame"]), str(data.get("name", "camera")))
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"the scene's camera is not readable ({error}): export the scene again") from None
    x0, x1, y0, y1, z = camera.frame
    if not (x1 > x0 and y1 > y0 and z < 0 and np.isfinite(camera.rotation).all() and np.isfinite(camera.position).all()):
        raise ValueError(f"the scene's camera '{camera.name}' has an empty or invalid frame {camera.frame}: "
                         "export the scene again")
    return camera


def scene_camera(sample):
    """The scene's own camera if it has one, else the default framing its receivers."""
    if getattr(sample, "camera", None):
        return camera_from_dict(sample.camera)
    return default_camera(sample.positions)


@dataclass
class SurfaceHits:
    """What every pixel of a view shows (arrays over height * width pixels)."""

    width: int
    height: int
    receiver: np.ndarray     # bool: a receiver's front face
    occluder: np.ndarray     # bool: an occluder (no lightmap)
    triangle: np.ndarray     # int: the receiver triangle, -1 elsewhere
    bary: np.ndarray         # (N, 3) weights of the triangle's corners 0, 1, 2
    points: np.ndarray       # (N, 3) world hit points (receivers)
    normals: np.ndarray      # (N, 3) unit shading normals of the lit side (receivers)
    facing: np.ndarray       # (N,) |cos| between ray and surface (for the occluders' grey)
    distance: np.ndarray     # (N,) distance from the camera, inf on a miss

    def lookup(self, lightmap, uvs):
        """(N, 3) light from `lightmap` (H, W, C) read bilinearly at each
        receiver pixel's UV in layout `uvs` (per corner, (3T, 2)); 0 elsewhere."""
        values = np.zeros((len(self.receiver), 3))
        where = self.receiver
        if where.any():
            uv = metrics.interpolate_corners(uvs, self.triangle[where], self.bary[where])
            values[where] = metrics.bilinear_lookup(lightmap, uv)[:, :3]
        return values

    def per_triangle(self, values):
        """(N,) `values` (T,) of each receiver pixel's triangle; NaN elsewhere."""
        out = np.full(len(self.receiver), np.nan)
        out[self.receiver] = np.asarray(values, np.float64)[self.triangle[self.receiver]]
        return out


def trace_view(sample, scene, camera, width, progress=None):
    """Trace `camera`'s pixels through `scene` (sample.to_scene: receivers
    are mesh 0, occluders mesh 1). Returns SurfaceHits."""
    width, height = camera.size(width)
    origins, directions = camera.rays(width, height)
    count = len(origins)
    hits = SurfaceHits(width, height, np.zeros(count, bool), np.zeros(count, bool), np.full(count, -1, np.int64),
                       np.zeros((count, 3)), np.zeros((count, 3)), np.zeros((count, 3)), np.zeros(count),
                       np.full(count, np.inf))
    corner_normals = np.asarray(sample.normals, np.float64)
    extent = float(np.abs(np.concatenate([sample.positions.ravel(), camera.position])).max()) + 1.0
    pending = np.arange(count)
    start = origins.astype(np.float64)
    travelled = np.zeros(count)
    for _ in range(MAX_BACK_FACES + 1):
        if not len(pending):
            break
        mesh, triangle, bary2, distance = trace_rays(
            scene, np.ascontiguousarray(start[pending], np.float32), directions[pending], progress=progress)
        hit = mesh >= 0
        total = travelled[pending] + np.where(hit, distance, np.inf)
        bary = np.stack([1 - bary2[:, 0] - bary2[:, 1], bary2[:, 0], bary2[:, 1]], axis=1).astype(np.float64)
        ray = directions[pending].astype(np.float64)
        on_receiver = mesh == 0
        normals = np.zeros((len(pending), 3))
        if on_receiver.any():
            normals[on_receiver] = metrics.interpolate_corners(corner_normals, triangle[on_receiver],
                                                               bary[on_receiver])
            normals[on_receiver] /= np.maximum(np.linalg.norm(normals[on_receiver], axis=1, keepdims=True), 1e-12)
        back = on_receiver & (np.einsum("ij,ij->i", normals, ray) > 0)
        front = on_receiver & ~back
        done = pending[front]
        hits.receiver[done] = True
        hits.triangle[done] = triangle[front]
        hits.bary[done] = bary[front]
        hits.normals[done] = normals[front]
        hits.distance[done] = total[front]
        hits.facing[done] = -np.einsum("ij,ij->i", normals[front], ray[front])
        other = hit & (mesh != 0)
        done = pending[other]
        hits.occluder[done] = True
        hits.distance[done] = total[other]
        hits.facing[done] = 0.6  # flat grey: no lightmap, nothing to compare
        # Step over back faces and trace on from just behind them.
        step = np.where(back, distance + 1e-5 * extent, 0.0)
        start[pending[back]] = start[pending[back]] + ray[back] * step[back, None]
        travelled[pending[back]] = travelled[pending[back]] + step[back]
        pending = pending[back]
    where = hits.receiver
    hits.points[where] = origins[where] + directions[where] * hits.distance[where, None]
    return hits


def truth_at(hits, scene, passes, samples, seed=0, progress=None):
    """(N, 3) ground-truth light at every receiver pixel (lmrefine.evaluate at
    the hit point), 0 elsewhere."""
    from .baker import evaluate

    values = np.zeros((len(hits.receiver), 3))
    where = hits.receiver
    if where.any():
        values[where] = evaluate(scene, hits.points[where], hits.normals[where], passes=passes, samples=samples,
                                 seed=seed, progress=progress)
    return values


def lit_surface(hits, light, base_color, exposure):
    """(H, W, 3) display picture in [0, 1]: base colour x light on receivers,
    `exposure` shown at DISPLAY_WHITE, sRGB-like gamma; occluders flat grey, background dark."""
    picture = np.empty((len(hits.receiver), 3))
    picture[:] = (0.10, 0.11, 0.13)
    if hits.occluder.any():
        picture[hits.occluder] = 0.32
    where = hits.receiver
    if where.any():
        colour = np.asarray(base_color, np.float64)[hits.triangle[where]] * light[where]
        picture[where] = np.clip(DISPLAY_WHITE * colour / max(exposure, 1e-12), 0.0, 1.0) ** (1 / 2.2)
    return picture.reshape(hits.height, hits.width, 3)


def strongest_transitions(hits, truth_picture, count=3, size=None):
    """Up to `count` square windows (row, column, size) over the view, where
    the ground truth picture changes most (summed gradient of its luminance
    between neighbouring receiver pixels at about the same depth), not
    overlapping each other."""
    height, width = hits.height, hits.width
    size = int(size or max(8, min(height, width) // 4))
    if size > min(height, width):
        return []
    luma = metrics.luminance(truth_picture.reshape(-1, 3)).reshape(height, width)
    # A 3 x 3 box first: a noisy truth's single bright pixels are not edges.
    padded = np.pad(luma, 1, mode="edge")
    luma = sum(padded[i:i + height, j:j + width] for i in range(3) for j in range(3)) / 9.0
    receiver = hits.receiver.reshape(height, width)
    depth = np.where(receiver, hits.distance.reshape(height, width), 0.0)
    normal = hits.normals.reshape(height, width, 3)
    energy = np.zeros((height, width))
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(0, -1), slice(1, None)
        a, b = tuple(a), tuple(b)
        # Neighbours on one smooth surface: no silhouette (a depth jump) and
        # no crease (a turn of the normal) between them, which are edges of
        # the geometry, not of the light.
        same_surface = (receiver[a] & receiver[b] & (np.abs(depth[a] - depth[b]) < 0.02 * np.minimum(depth[a], depth[b]))
                        & (np.einsum("ijk,ijk->ij", normal[a], normal[b]) > 0.95))
        energy[a] += np.where(same_surface, np.abs(luma[a] - luma[b]), 0.0)
    table = np.pad(energy, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    sums = table[size:, size:] - table[:-size, size:] - table[size:, :-size] + table[:-size, :-size]
    windows = []
    best = float(sums.max()) if sums.size else 0.0
    for _ in range(count):
        # A window with a tenth of the strongest one's change shows no edge worth a close-up.
        if not np.isfinite(sums).any() or best <= 0 or np.nanmax(sums) < 0.1 * best:
            break
        row, column = np.unravel_index(int(np.nanargmax(sums)), sums.shape)
        windows.append((int(row), int(column), size))
        sums[max(0, row - size + 1):row + size, max(0, column - size + 1):column + size] = -np.inf
    return windows


def picture_error(values, truth, where):
    """RMSE of lit values against the truth over the selected pixels (every channel)."""
    return metrics.error_stats(values[where], truth[where])["rmse"] if where.any() else float("nan")


def render_views(sample, scene, maps, passes, truth_samples, width, base_color=None, seed=0, progress=None):
    """Everything the surface pictures of an evaluation show, for the scene's
    camera: `maps` is {label: (lightmap (H, W, C), per-corner uvs (3T, 2))};
    the ground truth is lmrefine.evaluate at every receiver pixel with
    `truth_samples` samples. Returns a dict: camera, hits, light {label: (N, 3)}
    with "truth", pictures {label: (H, W, 3) display image, one exposure},
    crops [(row, column, size)] and rmse {label: over all receiver pixels}."""
    camera = scene_camera(sample)
    hits = trace_view(sample, scene, camera, width, progress=progress)
    light = {label: hits.lookup(image, uvs) for label, (image, uvs) in maps.items()}
    light["truth"] = truth_at(hits, scene, passes, truth_samples, seed=seed, progress=progress)
    base_color = sample.base_color if base_color is None else base_color
    lit = light["truth"][hits.receiver] * np.asarray(base_color)[hits.triangle[hits.receiver]]
    exposure = float(np.percentile(lit, 99.5)) if lit.size else 1.0
    pictures = {label: lit_surface(hits, values, base_color, exposure or 1.0) for label, values in light.items()}
    crops = strongest_transitions(hits, pictures["truth"])
    rmse = {label: picture_error(values, light["truth"], hits.receiver) for label, values in light.items()
            if label != "truth"}
    crop_rmse = []
    for row, column, size in crops:
        inside = np.zeros((hits.height, hits.width), bool)
        inside[row:row + size, column:column + size] = True
        where = hits.receiver & inside.ravel()
        crop_rmse.append({label: picture_error(values, light["truth"], where) for label, values in light.items()
                          if label != "truth"})
    return {"camera": camera, "hits": hits, "light": light, "pictures": pictures, "crops": crops, "rmse": rmse,
            "crop_rmse": crop_rmse, "exposure": exposure}
