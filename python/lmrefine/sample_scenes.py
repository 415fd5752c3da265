"""The bundled sample scenes (blend_samples/*.npz) without Blender.

``blend_samples/make_samples.py`` builds each scene in headless Blender, saves
the .blend and exports the same scene as an .npz (world-space receiver
triangles, per-corner normals, two lightmap UV variants, base colours, object
ids, the face each triangle was cut from, occluder-only casters, lights with
Blender's properties, world colour).
:func:`load_sample` reads one; :meth:`SampleScene.to_scene` turns it into an
:class:`lmrefine.Scene` with the UV layout to bake.
"""

import json
import os
from dataclasses import dataclass, field

import numpy as np

# The repository's blend_samples/ beside python/; LMREFINE_SAMPLES names another
# (a copy of python/ elsewhere, such as a baseline build for bench/compare_*.py).
SAMPLES_DIR = os.path.normpath(os.environ.get("LMREFINE_SAMPLES") or
                               os.path.join(os.path.dirname(__file__), "..", "..", "blend_samples"))

# Constants of the refiner are chosen on the tuning scenes only; the others
# report (docs/evaluation.md, "Tuning scenes and holdout scenes").
TUNING_SCENES = ("courtyard", "game_level", "fence_and_tree")
REPORTING_SCENES = ("room", "atrium", "plaza", "alley", "village", "cloister", "depot", "stairs", "hillside")

# UV variant name -> array name in the .npz.
# "own": the lightmap UV map of a scene exported from a user's .blend
# (python3 -m lmrefine export-scene), the only variant such a scene has.
UV_VARIANTS = {"smart": "uv_smart", "lightmap": "uv_lightmap", "own": "uv_own"}

# Light properties lmrefine.Scene.add_light understands, per kind (Blender's names).
LIGHT_PROPERTIES = {
    "point": ("energy", "color", "position", "matrix", "shadow_soft_size"),
    "spot": ("energy", "color", "position", "direction", "axis_x", "matrix", "shadow_soft_size", "spot_size",
             "spot_blend"),
    "sun": ("energy", "color", "direction", "axis_x", "matrix", "angle"),
    "area": ("energy", "color", "position", "direction", "axis_x", "matrix", "shape", "size", "size_y"),
}
# A light's world matrix (make_samples.py writes Blender's matrix_world) places
# it completely, spin and scale included; these keys stay in the file for
# readers but must not reach add_light beside it. Files without a matrix
# (older ones) place lights by position and direction, with Blender's default spin.
PLACEMENT = ("position", "direction", "axis_x")


def light_arguments(light):
    """(kind, add_light keyword arguments) of one light dict of a scene file."""
    kind = light["kind"]
    if kind not in LIGHT_PROPERTIES:
        raise ValueError(f"light '{light.get('name')}' has unknown kind '{kind}'")
    skip = PLACEMENT if "matrix" in light else ()
    params = {k: (tuple(map(tuple, v)) if k == "matrix" else tuple(v) if isinstance(v, list) else v)
              for k, v in light.items() if k in LIGHT_PROPERTIES[kind] and k not in skip}
    if "shape" in params:
        params["shape"] = params["shape"].upper()  # older files wrote Blender's shape in lower case
    return kind, params


@dataclass
class SampleScene:
    """One scene: every receiver joined into one mesh that shares one atlas.

    Per-corner arrays put corner k of triangle t at row 3t + k (the baker's
    and refine_uvs' convention, with ``corner_triangles`` as the indices)."""

    name: str
    positions: np.ndarray            # (V, 3) float32, world space
    triangles: np.ndarray            # (T, 3) int32 into positions
    normals: np.ndarray              # (3T, 3) float32 per corner
    uvs: dict                        # variant -> (3T, 2) float32 per corner
    base_color: np.ndarray           # (T, 3) float32
    object_id: np.ndarray            # (T,) int32 into objects
    objects: list                    # receiver object names
    lights: list                     # dicts: kind, name + Blender's light properties
    world: tuple = (0.0, 0.0, 0.0)
    passes: tuple = ("direct",)
    occluder_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    occluder_triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int32))
    description: str = ""
    camera: dict = None              # the scene's own camera (surface_view.Camera.to_dict), if it has one
    uv_maps: dict = None             # exported scenes: receiver name -> the Blender UV map of variant "own"
    polygons: np.ndarray = None      # (T,) int32: the face of its mesh each triangle was cut from, or None

    @property
    def corner_triangles(self):
        """(T, 3) int32 indices into the per-corner UV arrays: 3t, 3t+1, 3t+2."""
        from .charting import corner_triangles

        return corner_triangles(len(self.triangles))

    @property
    def corner_positions(self):
        """(3T, 3) world positions per corner."""
        return self.positions[self.triangles.reshape(-1)]

    def layout(self, variant="smart"):
        """(uvs (3T, 2), triangles (T, 3)) of one UV variant, ready for
        refine_uvs, check_layout and coverage_mask."""
        if variant not in self.uvs:
            raise ValueError(f"scene '{self.name}' has no UV variant '{variant}'; it has: {', '.join(self.uvs)}")
        return self.uvs[variant], self.corner_triangles

    def to_scene(self, uvs):
        """An lmrefine.Scene: the receivers as mesh 0 with lightmap UVs `uvs`
        (3T, 2), the occluders as a non-receiving mesh, the lights, the world."""
        from . import _native

        uvs = np.asarray(uvs, np.float32)
        if uvs.shape != (3 * len(self.triangles), 2):
            raise ValueError(f"uvs must be per corner, shape ({3 * len(self.triangles)}, 2); got {uvs.shape}")
        scene = _native.Scene()
        scene.add_mesh(self.positions, self.triangles, uvs=uvs, normals=self.normals,
                       base_color=self.base_color, receiver=True)
        if len(self.occluder_triangles):
            scene.add_mesh(self.occluder_positions, self.occluder_triangles, receiver=False)
        for light in self.lights:
            try:
                kind, params = light_arguments(light)
            except ValueError as error:
                raise ValueError(f"scene '{self.name}': {error}") from None
            scene.add_light(kind, **params)
        if any(c > 0 for c in self.world):
            scene.set_world(tuple(self.world))
        return scene

    def save(self, path, **extra_meta):
        """Write the scene as an .npz that load_sample reads (as
        blend_samples/make_samples.py and `export-scene` do); `extra_meta`
        goes into meta for readers (load_sample ignores it)."""
        meta = {"name": self.name, "description": self.description, "objects": list(self.objects),
                "lights": list(self.lights), "world": [float(c) for c in self.world], "passes": list(self.passes),
                **extra_meta}
        if self.camera:
            meta["camera"] = self.camera
        if self.uv_maps:
            meta["uv_maps"] = dict(self.uv_maps)
        np.savez_compressed(
            path, positions=self.positions, triangles=self.triangles, normals=self.normals,
            base_color=self.base_color, object_id=self.object_id, occluder_positions=self.occluder_positions,
            occluder_triangles=self.occluder_triangles, meta=np.array(json.dumps(meta)),
            **({} if self.polygons is None else {"polygons": self.polygons}),
            **{UV_VARIANTS[variant]: uvs for variant, uvs in self.uvs.items()})

    def triangle_areas(self):
        """(T,) world-space area of every receiver triangle."""
        p = self.positions[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def sample_names(directory=SAMPLES_DIR):
    """Names of the bundled scenes (the .npz files that make_samples.py wrote)."""
    if not os.path.isdir(directory):
        return []
    names = []
    for entry in sorted(os.listdir(directory)):
        if entry.endswith(".npz") and os.path.exists(os.path.join(directory, entry[:-4] + ".blend")):
            names.append(entry[:-4])
    return names


def load_sample(name_or_path):
    """Read a scene .npz: a bundled sample's name ("courtyard") or a path."""
    path = name_or_path
    if not os.path.exists(path):
        path = os.path.join(SAMPLES_DIR, name_or_path + ".npz")
    if not os.path.exists(path):
        raise ValueError(f"no sample scene '{name_or_path}': give a path to a scene .npz or one of "
                         f"{', '.join(sample_names()) or '(none found: run `make samples`)'}")
    try:
        data = np.load(path)
    except (OSError, ValueError) as error:  # a .fbx, a text file, a pickle: "Cannot load file containing pickled data"
        raise ValueError(f"'{path}' is not a scene .npz ({error}): give a bundled sample's name, a .blend, or a "
                         "scene .npz written by `python3 -m lmrefine export-scene`") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(f"'{path}' holds one numpy array, not a scene .npz: write one with `python3 -m lmrefine "
                         "export-scene`")
    with data:
        try:
            meta = json.loads(str(data["meta"]))
            uvs = {variant: data[key].astype(np.float32) for variant, key in UV_VARIANTS.items() if key in data}
            return SampleScene(
                name=meta.get("name", os.path.splitext(os.path.basename(path))[0]),
                positions=data["positions"].astype(np.float32),
                triangles=data["triangles"].astype(np.int32),
                normals=data["normals"].astype(np.float32),
                uvs=uvs,
                base_color=data["base_color"].astype(np.float32),
                object_id=data["object_id"].astype(np.int32),
                objects=list(meta["objects"]),
                lights=list(meta["lights"]),
                world=tuple(meta.get("world", (0.0, 0.0, 0.0))),
                passes=tuple(meta.get("passes", ("direct",))),
                occluder_positions=data["occluder_positions"].astype(np.float32),
                occluder_triangles=data["occluder_triangles"].astype(np.int32),
                description=meta.get("description", ""),
                camera=meta.get("camera"),
                uv_maps=meta.get("uv_maps"),
                polygons=_polygons(data, path),
            )
        except KeyError as error:
            raise ValueError(f"'{path}' is not a scene .npz (missing {error}); make one with "
                             "`python3 -m lmrefine export-scene LEVEL.blend`") from None


def _polygons(data, path):
    """The file's face id per triangle, or None (files written before it)."""
    if "polygons" not in data:
        return None
    polygons = data["polygons"]
    if polygons.shape != data["triangles"].shape[:1] or not np.issubdtype(polygons.dtype, np.integer):
        raise ValueError(f"'{path}' has polygons {polygons.dtype} {polygons.shape}, not one integer face id per "
                         "triangle: write it again with `python3 -m lmrefine export-scene`")
    return polygons.astype(np.int32)
