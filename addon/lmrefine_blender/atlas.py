"""Atlas groups: objects whose lightmap UV maps share one atlas are refined and baked as one map.

Objects laid out together (one Lightmap Pack or Smart UV Project of all of
them) cover disjoint parts of [0, 1]; they form one group, which gets one
refinement of the joined layout and one image per pass. An object laid out
on its own lightmap is a group of its own. Which objects go together is
lmrefine's rule (lmrefine.scene_export.atlas_groups), checked at the run's
resolution.

Plain numpy and lmrefine, no bpy: the rules here are tested without Blender
(tests/test_atlas_groups.py loads this file on its own).
"""

import numpy as np

ATLAS_SUFFIX = "_atlas"


class AtlasGroup:
    """Targets (anything with `.obj.name` and `.layout.uvs`/`.layout.triangles`) that share one atlas.

    `name` names the group's images: the object's name for a group of one
    (as without groups), else "<main object>_atlas", the main object being
    the one with the largest share of the atlas (UV area; ties: the first
    name), so a level's atlas is named after its ground rather than a crate.
    `join()` builds the joined layout from the targets' current layouts
    (tessellation may change them after grouping).
    """

    def __init__(self, targets):
        self.targets = list(targets)
        areas = [uv_area(target.layout.uvs, target.layout.triangles) for target in self.targets]
        main = self.targets[int(np.argmax(areas))].obj.name  # argmax: the first of equal areas
        self.name = main if len(self.targets) == 1 else main + ATLAS_SUFFIX
        self.uvs = self.triangles = self.positions = self.normals = None
        self.slices = []  # per target: its rows of the joined UVs
        self.triangle_slices = []  # per target: its rows of the joined triangles

    @property
    def objects(self):
        return [target.obj.name for target in self.targets]

    @property
    def shared(self):
        return len(self.targets) > 1

    def label(self):
        """How messages name the group: 'Floor', or atlas 'Floor_atlas' (Floor, Box, Wall)."""
        if not self.shared:
            return f"'{self.name}'"
        return f"atlas '{self.name}' ({', '.join(self.objects)})"

    def join(self):
        """Concatenate the targets' layouts (triangle indices offset); returns (uvs, triangles).
        `positions` and `normals` join the loops' world positions and split normals the same way
        (refine_uvs' re-chart route), or are None when a layout has none."""
        layouts = [target.layout for target in self.targets]
        self.uvs, self.triangles, self.slices, self.triangle_slices = join_layouts(
            [(layout.uvs, layout.triangles) for layout in layouts])
        positions = [getattr(layout, "positions", None) for layout in layouts]
        self.positions = None if any(p is None for p in positions) else np.concatenate(positions)
        normals = [getattr(layout, "normals", None) for layout in layouts]
        self.normals = (None if self.positions is None or any(n is None for n in normals)
                        else np.concatenate(normals))
        return self.uvs, self.triangles

    def split(self, uvs):
        """Joined per-corner UVs -> {object name: its own rows}."""
        return {target.obj.name: uvs[rows] for target, rows in zip(self.targets, self.slices)}

    def merge(self, maps, resolution, margin, uvs=None):
        """The group's one map from its members' own bakes (`maps`, in target order) of the joined
        layout, or of the joined `uvs` of the same triangles (a refined layout): merge_maps."""
        uvs = self.uvs if uvs is None else uvs
        return merge_maps(maps, self.masks(resolution, uvs), uvs, self.triangles, margin)

    def masks(self, resolution, uvs=None):
        """Each target's coverage mask (rasterized from its UVs, never from alpha) of the joined
        layout, or of the joined `uvs` of the same triangles (a refined layout)."""
        import lmrefine

        uvs = self.uvs if uvs is None else uvs
        return [lmrefine.coverage_mask(uvs, self.triangles[rows], resolution) for rows in self.triangle_slices]


def uv_area(uvs, triangles):
    """Summed UV area of a layout's triangles (the share of [0, 1]^2 it covers, charts apart)."""
    corners = np.asarray(uvs, dtype=np.float64)[np.asarray(triangles)]
    edges_a, edges_b = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    return float(0.5 * np.abs(edges_a[:, 0] * edges_b[:, 1] - edges_a[:, 1] * edges_b[:, 0]).sum())


def join_layouts(layouts):
    """[(uvs (L_i, 2), triangles (T_i, 3))] -> (uvs, triangles, uv slices, triangle slices)."""
    uvs, triangles, slices, triangle_slices = [], [], [], []
    corners = faces = 0
    for layout_uvs, layout_triangles in layouts:
        uvs.append(np.asarray(layout_uvs, dtype=np.float32))
        triangles.append(np.asarray(layout_triangles, dtype=np.int32) + corners)
        slices.append(slice(corners, corners + len(layout_uvs)))
        triangle_slices.append(slice(faces, faces + len(layout_triangles)))
        corners += len(layout_uvs)
        faces += len(layout_triangles)
    return np.concatenate(uvs), np.concatenate(triangles), slices, triangle_slices


def group_targets(targets, resolution, shared=True):
    """The targets' AtlasGroups: lmrefine's rule (atlas_groups, greedy) at `resolution` over the
    targets in object-name order, so the grouping does not depend on the selection's order; one
    group per target (in target order) when `shared` is off. Names are unique within a run (an
    object named 'Floor_atlas' beside Floor's atlas makes the latter 'Floor_atlas_2')."""
    if not shared or len(targets) < 2:
        return [AtlasGroup([target]) for target in targets]
    from lmrefine.scene_export import atlas_groups

    targets = sorted(targets, key=lambda target: target.obj.name)
    indices = atlas_groups([(t.layout.uvs, t.layout.triangles) for t in targets], resolution)
    groups = [AtlasGroup([targets[index] for index in group]) for group in indices]
    taken = {group.name for group in groups if not group.shared}  # an object's own name stays its own
    for group in groups:
        if group.shared:
            base, number = group.name, 1
            while group.name in taken:
                number += 1
                group.name = f"{base}_{number}"
            taken.add(group.name)
    return groups


def merge_maps(maps, masks, uvs, triangles, margin):
    """One map from the bakes of the layout (`uvs`, `triangles`; the members' rows joined) and of
    each member (`maps`, with `masks` its rasterized coverage): each covered texel from the map of the
    object whose chart covers it (the first, where two touch), and the gutter filled anew from the
    joined layout's charts by lmrefine.dilate, as the baker fills an atlas it bakes at once: within
    `margin` texels, a gutter texel a bilinear lookup on a chart can read from the chart nearest it,
    so two objects' charts two texels apart never lend each other light. Texels further out are 0.
    A single map is dilated the same way: a Cycles bake's margin averages neighbouring charts.
    Coverage comes from the layouts, never from alpha. Inputs are not modified."""
    import lmrefine

    merged = np.zeros(np.shape(maps[0]), dtype=np.float32)
    taken = np.zeros(np.shape(masks[0]), dtype=bool)
    for image, mask in zip(maps, masks):
        mine = mask & ~taken
        merged[mine] = np.asarray(image, dtype=np.float32)[mine]
        taken |= mask
    return lmrefine.dilate(merged, uvs, triangles, margin)
