"""The lightmap baker's Python API: lmrefine.bake, lmrefine.evaluate and lmrefine.trace_rays.

The work is native (Embree 3, all cores, GIL released); this module only
normalizes arguments and shapes the results. Units, passes and how they match
Blender's Cycles: docs/baker.md.
"""

from . import _native

PASSES = ("direct", "ao", "indirect", "combined")


class BakeResult(dict):
    """``{mesh id: float32 (H, W, 4)}`` (or ``{pass: {mesh id: ...}}`` when
    several passes were asked for), plus ``.stats``: a dict with ``rays``,
    ``rays_per_second``, ``seconds`` (whole call), ``pass_seconds``
    (``{"direct" | "ao" | "indirect": seconds}``), ``texels`` and
    ``degenerate_triangles``."""

    def __init__(self, maps, stats):
        super().__init__(maps)
        self.stats = stats


def _check_scene(scene):
    if not isinstance(scene, _native.Scene):
        raise TypeError(f"scene must be an lmrefine.Scene, got {type(scene).__name__}")


def _pass_names(passes):
    if isinstance(passes, str):
        names = (passes,)
    elif isinstance(passes, (tuple, list)):
        names = tuple(passes)
    else:
        raise TypeError(f"passes must be a str or a tuple of str (some of {PASSES}), got {type(passes).__name__}")
    for name in names:
        if not isinstance(name, str):
            raise TypeError(f"passes must hold str (some of {PASSES}), got {type(name).__name__}")
    if not names:
        raise ValueError(f"passes is empty; ask for some of {PASSES}")
    for name in names:
        if name not in PASSES:
            raise ValueError(f"unknown pass {name!r}; use one of {PASSES}")
    if len(set(names)) != len(names):
        raise ValueError(f"passes {names} names a pass twice")
    return names


def bake(scene, resolution, passes=("direct",), samples=16, seed=0, progress=None, dilation=16,
         denoise=False, bounces=4, ao_distance=10.0, atlas=False):
    """Bake lightmaps of every receiving mesh of ``scene``.

    Args:
        scene (Scene): meshes, lights, world.
        resolution (int | tuple[int, int]): lightmap size, square or (height, width).
        passes (str | tuple[str, ...]): "direct" (lights and world, with shadows),
            "ao" (ambient occlusion up to ``ao_distance``), "indirect" (light after
            1..``bounces`` diffuse bounces, base colours as albedo), "combined"
            (direct + indirect). Values are Cycles' DIFFUSE bake with the colour
            pass off, and Cycles' AO bake.
        samples (int): samples per texel (stratified over the texel).
        seed (int): results depend only on the seed, never on thread count.
        progress (callable | None): ``progress(fraction, stage)``; returning
            False cancels (raises ``lmrefine.CancelledError``, nothing partial).
        dilation (int): texels to fill into the gutter around each chart, from
            that chart's own texels (Blender's bake margin, default 16); a
            gutter texel a bilinear lookup on a chart can read (centre within
            1.5 texels) takes the nearest chart's light (``dilate``).
        denoise (bool): edge-aware a-trous filter guided by position, normal and
            the per-texel noise estimate.
        bounces (int): diffuse bounces of the indirect pass (Cycles' default 4).
        ao_distance (float): AO ray length (Blender's world AO distance).
        atlas (bool): bake every receiver into one shared map, keyed "atlas"
            (their UV layouts must not overlap).

    Returns:
        BakeResult: ``{mesh id: float32 (H, W, 4)}`` with one pass, else
        ``{pass: {mesh id: ...}}``; row 0 at the top (v = 1), RGB linear,
        alpha = coverage (1 where a chart covers the texel, 0 in the gutter).
        ``.stats`` holds rays cast, rays per second and time per pass.

    Raises:
        ValueError: empty scene, bad options, resolution above 32768.
        MemoryError: the bake would need more than half the machine's memory
            (estimated before allocating; the message gives the estimate).
        lmrefine.CancelledError: the progress callback returned False.
    """
    _check_scene(scene)
    names = _pass_names(passes)
    maps, stats = _native._bake(scene, resolution, list(names), samples, seed, progress, dilation,
                                bool(denoise), bounces, ao_distance, bool(atlas))
    by_pass = {name: {} for name in names}
    for mesh, images in maps:
        key = "atlas" if mesh < 0 else mesh
        for name, image in zip(names, images):
            by_pass[name][key] = image
    return BakeResult(by_pass[names[0]] if len(names) == 1 else by_pass, stats)


def dilate(image, uvs, triangles, texels=16):
    """The baker's gutter fill for a map baked elsewhere (a Cycles bake, or
    maps merged into one shared atlas).

    Texels the layout's charts cover (``coverage_mask``) keep their colour.
    Every other texel within ``texels`` rings of a chart takes the mean colour
    of its neighbours of one chart: the chart nearest its centre when one is
    within 1.5 texels (so a bilinear lookup at a chart's border reads only its
    own light when charts are two texels apart), else the chart with most
    such neighbours. Colour never mixes across charts. Charts are
    ``find_charts``' (bit-identical UVs joined).

    Args:
        image (numpy.ndarray): float32 (H, W, 3) or (H, W, 4), row 0 at the top.
        uvs (numpy.ndarray): (N, 2) per-corner UVs of the layout it was baked with.
        triangles (numpy.ndarray): (T, 3) integer indices into ``uvs``.
        texels (int): rings of gutter to fill (Blender's bake margin, default 16).

    Returns:
        numpy.ndarray: a new float32 array of ``image``'s shape; alpha, if
        any, as given. ``image`` is not modified.

    Raises:
        ValueError: bad shapes or dtype, indices out of range, NaN UVs.
    """
    return _native._dilate(image, uvs, triangles, texels)


def evaluate(scene, points, normals, passes=("direct",), samples=64, seed=0, progress=None, bounces=4,
             ao_distance=10.0):
    """The baker's light at arbitrary surface points (ground truth for metrics).

    Args:
        points (numpy.ndarray): (P, 3) world positions on surfaces.
        normals (numpy.ndarray): (P, 3) normals of the lit side (normalized here).
        passes, samples, seed, progress, bounces, ao_distance: as for bake.

    Returns:
        numpy.ndarray: float32 (P, 3) with one pass, else ``{pass: (P, 3)}``.
    """
    _check_scene(scene)
    names = _pass_names(passes)
    values, _stats = _native._evaluate(scene, points, normals, list(names), samples, seed, progress,
                                       bounces, ao_distance)
    return values[0] if len(names) == 1 else dict(zip(names, values))


def trace_rays(scene, origins, directions, progress=None):
    """The closest hit of every ray in ``scene`` (receivers and occluders
    alike): primary rays for pictures of the lit surface (lmrefine.surface_view).

    Args:
        origins (numpy.ndarray): (N, 3) ray origins, inside +-1e9.
        directions (numpy.ndarray): (N, 3) ray directions, any finite
            length from 1e-28 up.
        progress (callable | None): as for bake.

    Returns:
        (mesh, triangle, barycentric, distance): int32 (N,) mesh id (-1: no
        hit), int32 (N,) triangle of that mesh (-1: no hit), float32 (N, 2)
        weights of the triangle's corners 1 and 2 (corner 0 gets 1 minus
        their sum), float32 (N,) distance in units of the direction's length
        (inf: no hit).

    Raises:
        ValueError: NaN/Inf or out-of-scene origins, zero, shorter, NaN or
            Inf directions (a float64 beyond float32's range is Inf),
            mismatched shapes.
    """
    _check_scene(scene)
    return _native._trace_rays(scene, origins, directions, progress)
