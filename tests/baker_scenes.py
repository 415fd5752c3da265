"""Small scenes for the baker tests (numpy only; shared by the analytic tests,
the Cycles cross-check and bench/bench_baker.py's checks)."""

import numpy as np


def quad(corners, uv_rect=(0.0, 0.0, 1.0, 1.0)):
    """Two triangles over a parallelogram given by 3 corners (origin, +u edge end,
    +v edge end); the front faces along cross(u, v). Returns positions (4, 3),
    triangles (2, 3) and per-corner UVs (6, 2) filling uv_rect = (u0, v0, u1, v1)."""
    o, pu, pv = (np.asarray(c, dtype=np.float64) for c in corners)
    positions = np.array([o, pu, pu + pv - o, pv])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    u0, v0, u1, v1 = uv_rect
    uv = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]])
    return positions, triangles, uv[triangles.ravel()]


def floor(half=1.0, z=0.0, uv_rect=(0.0, 0.0, 1.0, 1.0)):
    """The square [-half, half]^2 at height z, facing +z, UV u along x, v along y."""
    return quad(([-half, -half, z], [half, -half, z], [-half, half, z]), uv_rect)


def texel_centers(resolution, half=1.0):
    """World (x, y) of the texel centres of floor(half), shaped (R, R) each."""
    centres = (np.arange(resolution) + 0.5) / resolution
    x = -half + 2 * half * centres[None, :].repeat(resolution, 0)
    y = half - 2 * half * centres[:, None].repeat(resolution, 1)  # row 0 is v = 1
    return x, y


def texel_average(function, resolution, half=1.0, supersample=8):
    """Mean of function(x, y) over each texel of floor(half), (R, R)."""
    total = np.zeros((resolution, resolution))
    size = 2 * half / resolution
    for i in range(supersample):
        for j in range(supersample):
            x, y = texel_centers(resolution, half)
            total += function(x + ((j + 0.5) / supersample - 0.5) * size, y - ((i + 0.5) / supersample - 0.5) * size)
    return total / supersample**2


def box_inside(half=1.0):
    """A closed cube [-half, half]^3 seen from inside (fronts face inwards),
    its six faces in six UV cells. Returns positions, triangles, uvs."""
    faces = []
    for axis in range(3):
        for side in (-1.0, 1.0):
            o = np.full(3, -half)
            o[axis] = side * half
            pu, pv = o.copy(), o.copy()
            pu[(axis + 1) % 3] = half
            pv[(axis + 2) % 3] = half
            # The front must face into the box, against `side` along `axis`.
            if np.cross(pu - o, pv - o)[axis] * side > 0:
                pu, pv = pv, pu
            faces.append((o, pu, pv))
    positions, triangles, uvs = [], [], []
    for k, corners in enumerate(faces):
        cell = (k % 3 / 3 + 0.02, k // 3 / 2 + 0.02, (k % 3 + 1) / 3 - 0.02, (k // 3 + 1) / 2 - 0.02)
        p, t, uv = quad(corners, cell)
        triangles.append(t + 4 * k)
        positions.append(p)
        uvs.append(uv)
    return np.concatenate(positions), np.concatenate(triangles), np.concatenate(uvs)


def sample_box_inside(count, rng, half=1.0):
    """Uniform-by-area points on the inside of box_inside(half), with inward normals."""
    axis = rng.integers(0, 3, count)
    side = rng.choice([-1.0, 1.0], count)
    points = rng.uniform(-half, half, (count, 3))
    points[np.arange(count), axis] = side * half
    normals = np.zeros((count, 3))
    normals[np.arange(count), axis] = -side
    return points, normals


def mesh_spec(positions, triangles, uvs=None, base_color=(0.8, 0.8, 0.8), receiver=True):
    """One mesh of a scene spec: plain lists, so the same spec is read by
    lmrefine (scene_from_spec) and by Blender (tests/blender/cycles_bake.py)."""
    return dict(positions=np.asarray(positions, float).tolist(), triangles=np.asarray(triangles, int).tolist(),
                uvs=None if uvs is None else np.asarray(uvs, float).tolist(), base_color=list(base_color),
                receiver=receiver)


def scene_from_spec(spec):
    """An lmrefine.Scene from a spec (meshes, lights, world)."""
    import lmrefine

    scene = lmrefine.Scene()
    for mesh in spec["meshes"]:
        scene.add_mesh(np.array(mesh["positions"]), np.array(mesh["triangles"]),
                       uvs=None if mesh["uvs"] is None else np.array(mesh["uvs"]),
                       base_color=mesh["base_color"], receiver=mesh["receiver"])
    for light in spec.get("lights", []):
        light = dict(light)
        scene.add_light(light.pop("kind"), **light)
    if spec.get("world"):
        scene.set_world(spec["world"])
    return scene
