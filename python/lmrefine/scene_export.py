"""A user's .blend as a scene .npz, through headless Blender.

``python3 -m lmrefine export-scene LEVEL.blend -o scene.npz`` and
``python3 -m lmrefine evaluate LEVEL.blend`` run the add-on's headless entry
(addon/lmrefine_blender/export_scene.py, which reads the scene as the add-on's
bake does) in ``blender -b``; nothing here imports bpy.
"""

import json
import os
import subprocess

import numpy as np

from .batch.blender_command import addon_script_candidates, find_blender

SCRIPT = "export_scene.py"
ERROR_PREFIX = "lmrefine: error: "
MESSAGE_PREFIXES = ("lmrefine: note: ", "lmrefine: exported ")


class ExportError(ValueError):
    """The .blend could not be exported; the message says what to do."""


def find_export_script():
    candidates = addon_script_candidates(SCRIPT)
    for candidate in candidates:
        if os.path.isfile(candidate):
            return candidate
    raise OSError(f"the add-on's scene export ({SCRIPT}) was not found; looked in: {', '.join(candidates)}. "
                  "Install the add-on (docs/blender.md) or run from an lmrefine checkout")


def check_blend(path):
    """The path of an existing .blend file, or an OSError/ValueError saying what is wrong."""
    if not os.path.exists(path):
        raise OSError(f"no such file: '{path}' (give the path of a .blend file)")
    if not os.path.isfile(path):
        raise OSError(f"'{path}' is a folder, not a .blend file")
    if not path.lower().endswith(".blend"):
        raise ValueError(f"'{path}' is not a .blend file: give a .blend (or, to evaluate, a scene .npz or a "
                         "bundled sample's name)")
    return os.path.abspath(path)


def export_blend(blend, out, objects="all", uv_map=None, blender=None, echo=print):
    """Export `blend` into the scene .npz `out` (see the module's doc);
    `echo` gets the export's notes and its one-line summary. Returns `out`.
    Raises ExportError (a ValueError) with the script's message for a scene
    that cannot be exported, OSError when the file or Blender is missing or
    Blender fails."""
    blend = check_blend(blend)
    folder = os.path.dirname(os.path.abspath(out))
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as error:
        raise OSError(f"cannot write '{out}': {error.strerror or error}; give -o a path in a folder you can write")
    if not os.access(folder, os.W_OK):
        raise OSError(f"cannot write '{out}': folder '{folder}' is not writable; give -o a path in a folder you "
                      "can write")
    command = [find_blender(blender), "-b", blend, "--factory-startup", "--python-exit-code", "1",
               "--python", find_export_script(), "--", "--out", os.path.abspath(out), "--objects", objects]
    if uv_map:
        command += ["--uv-map", uv_map]
    echo(f"exporting {blend} with headless Blender ({command[0]})")
    run = subprocess.run(command, capture_output=True, text=True, errors="replace", stdin=subprocess.DEVNULL)
    for line in run.stdout.splitlines():
        if line.startswith(MESSAGE_PREFIXES):
            echo(line[len("lmrefine: "):])
    errors = [line[len(ERROR_PREFIX):] for line in run.stderr.splitlines() if line.startswith(ERROR_PREFIX)]
    if errors:
        raise ExportError(f"cannot export '{blend}': {errors[-1]}")
    if run.returncode != 0 or not os.path.isfile(out):
        tail = [line for line in (run.stderr + run.stdout).splitlines() if line.strip()][-6:]
        raise OSError(f"Blender could not export '{blend}' (exit status {run.returncode}); its last words:\n  "
                      + "\n  ".join(tail))
    from .sample_scenes import load_sample

    problem = shared_atlas_problem(load_sample(out))
    if problem:
        os.remove(out)
        raise ExportError(f"cannot export '{blend}': {problem}")
    return out


# Objects that share one atlas: their lightmap UV maps must not cover the same
# texels (checked at a resolution, with a tolerance for charts that merely
# touch: a shared texel count up to this fraction of the smaller map's).
ATLAS_CHECK_RESOLUTION = 256
ATLAS_OVERLAP_FRACTION = 0.02


def atlas_masks(layouts, resolution=ATLAS_CHECK_RESOLUTION):
    """The texels each layout `(uvs, triangles)` covers at `resolution`
    (lmrefine.coverage_mask), None for a layout without triangles."""
    from . import _native

    return [_native.coverage_mask(uvs, triangles, resolution) if len(triangles) else None
            for uvs, triangles in layouts]


def overlaps(shared, count_a, count_b, tolerance=ATLAS_OVERLAP_FRACTION):
    """The rule: two objects whose maps cover `count_a` and `count_b` texels,
    `shared` of them in common, cover the same part of the atlas when they
    share more than `tolerance` times the smaller count (charts that merely
    touch share a texel column, within the tolerance)."""
    return shared > tolerance * min(count_a, count_b)


def overlap(mask_a, mask_b, tolerance=ATLAS_OVERLAP_FRACTION):
    """`overlaps` for two coverage masks (None, an empty layout, overlaps nothing)."""
    if mask_a is None or mask_b is None:
        return False
    return overlaps(np.count_nonzero(mask_a & mask_b), np.count_nonzero(mask_a), np.count_nonzero(mask_b),
                    tolerance)


def atlas_groups(layouts, resolution=ATLAS_CHECK_RESOLUTION, tolerance=ATLAS_OVERLAP_FRACTION):
    """Which objects share one atlas: lists of indices into `layouts` (each
    `(uvs, triangles)` of one object's lightmap UV map), every index in
    exactly one list.

    Greedy in the given order: each object joins the first group none of
    whose members it overlaps (`overlaps`), else starts a group of its own.
    Objects laid out together (one Lightmap Pack or Smart UV Project of all
    of them) form one group; objects each laid out on its own lightmap (each
    map filling [0, 1]) form one group each.

    Each group keeps one map of which member covers each texel, so an object
    is checked against a group in time proportional to its own texels, not
    to the group's members (a level of hundreds of objects in one atlas);
    a texel two members share within the tolerance counts for the first."""
    from . import _native

    groups = []  # (members, texel owner map (flat, -1 = free), {member: covered texels})
    for index, (uvs, triangles) in enumerate(layouts):
        covered = (np.flatnonzero(_native.coverage_mask(uvs, triangles, resolution)) if len(triangles)
                   else np.zeros(0, dtype=np.intp))
        home = None
        for members, owner, counts in groups:
            # Every 16th texel first: its shared counts are lower bounds, so an overlap they already
            # show is one (objects each on its own lightmap are told apart at a sixteenth of the cost).
            if not any(_overlapping(owner, sample, len(covered), counts, members, tolerance)
                       for sample in (covered[::16], covered)):
                home = (members, owner, counts)
                break
        if home is None:
            height, width = (resolution, resolution) if np.isscalar(resolution) else resolution
            label = np.int16 if len(layouts) < np.iinfo(np.int16).max else np.int32
            home = ([], np.full(int(height) * int(width), -1, dtype=label), {})
            groups.append(home)
        members, owner, counts = home
        members.append(index)
        counts[index] = len(covered)
        free = covered[owner[covered] < 0]
        owner[free] = index
    return [members for members, _, _ in groups]


def _overlapping(owner, texels, count, counts, members, tolerance):
    """Whether an object covering `count` texels overlaps a member of a group, counting only its `texels`."""
    hit = owner[texels]
    hit = hit[hit >= 0]
    if not len(hit):
        return False
    shared = np.bincount(hit)
    return any(overlaps(shared[member], count, counts[member], tolerance)
               for member in members if member < len(shared) and shared[member])


def shared_atlas_problem(scene):
    """None when the receivers of an exported scene share one atlas, else a
    message naming objects whose lightmap UV maps cover the same part of
    [0, 1] (each object laid out on its own lightmap) and what to do."""
    uvs, triangles = scene.layout("own")
    if len(scene.objects) < 2:
        return None
    layouts = [(uvs, triangles[scene.object_id == index]) for index in range(len(scene.objects))]
    masks = atlas_masks(layouts)
    overlapping = [(scene.objects[a], scene.objects[b]) for a in range(len(masks)) for b in range(a + 1, len(masks))
                   if overlap(masks[a], masks[b])]
    if not overlapping:
        return None
    a, b = overlapping[0]
    more = f" (and {len(overlapping) - 1} more pairs)" if len(overlapping) > 1 else ""
    # The largest set laid out together, when there is one: most often the level's atlas, and an object or
    # two whose automatic map choice took a texture map (a map not named like "Lightmap").
    largest = max(atlas_groups(layouts), key=len)
    shared = ""
    if len(largest) > 1:
        maps = scene.uv_maps or {}
        others = [f"'{name}'" + (f" (its map '{maps[name]}')" if name in maps else "")
                  for index, name in enumerate(scene.objects) if index not in largest]
        shared = (f"; these share one atlas: --objects {','.join(scene.objects[index] for index in largest)} "
                  f"(leaving out {', '.join(others)})")
    return (f"the lightmap UV maps of '{a}' and '{b}'{more} cover the same part of the UV square: objects evaluated "
            f"together must share one atlas{shared}; pack their lightmap UV maps into one in Blender (select them, "
            "Edit Mode, UV > Pack Islands), pick their lightmap map with --uv-map, or evaluate one object at a time "
            "with --objects NAME")


def _source_stamp(blend, objects, uv_map):
    stat = os.stat(blend)
    return {"blend": os.path.abspath(blend), "mtime_ns": stat.st_mtime_ns, "size": stat.st_size, "objects": objects,
            "uv_map": uv_map, "script": os.path.getmtime(find_export_script())}


def cached_export(blend, folder, objects="all", uv_map=None, blender=None, echo=print):
    """The scene .npz of `blend` in `folder` (<name>.npz), exported again only
    when the .blend, the options or the export script changed since the last
    time (a <name>.source.json beside it says what it was made from)."""
    blend = check_blend(blend)
    name = os.path.splitext(os.path.basename(blend))[0]
    out = os.path.join(folder, name + ".npz")
    stamp_path = os.path.join(folder, name + ".source.json")
    stamp = _source_stamp(blend, objects, uv_map)
    try:
        with open(stamp_path) as handle:
            if json.load(handle) == stamp and os.path.isfile(out):
                echo(f"scene of {blend}: {out} (exported before, unchanged)")
                return out
    except (OSError, ValueError):
        pass
    os.makedirs(folder, exist_ok=True)
    export_blend(blend, out, objects=objects, uv_map=uv_map, blender=blender, echo=echo)
    with open(stamp_path, "w") as handle:
        json.dump(stamp, handle, indent=2)
    return out
