"""Fuzz cases for every public function of lmrefine (the names in
lmrefine.__all__, and the methods of Scene and LayoutChecker).

A case is built from a numpy Generator: a valid call of one function with
small inputs, then (most of the time) one or two arguments replaced by
hostile values (hostile.py). `build(index, rng)` returns a Case; running it
returns the function's result. Cases for one function always draw the same
way, so (seed, index) reproduces a case exactly.
"""

import os
import tempfile
from dataclasses import dataclass, field

import numpy as np

import hostile

# Names of lmrefine's public callables each case exercises (the suite checks it covers all of them).
COVERED = ("check_layout", "coverage_mask", "dwt", "dwt2", "find_charts", "gradient_map", "grid_cell_areas",
           "idwt", "idwt2", "read_image", "run_automaton", "warp_uvs", "write_image", "LayoutChecker", "Scene",
           "bake", "evaluate", "identity_grid", "refine_uvs", "CancelledError", "BakeResult", "RefineResult",
           "pack_charts", "PackResult", "CHART_TOLERANCE", "trace_rays", "tessellate", "TessellationResult",
           "transition_strength_of", "tessellated_refine_options", "rechart", "RechartResult", "dilate")

VALID_FRACTION = 0.2  # cases left entirely valid: the ok path must hold its promises too
WAVELETS = ("haar", "d4", "d12", "d20", "cdf53", "cdf97")
MODES = ("periodic", "symmetric", "zero")


@dataclass
class Case:
    function: str
    call: object  # call() -> result
    inputs: list = field(default_factory=list)  # everything the caller passed (checked for modification)
    layout: tuple = None  # (uvs, triangles, resolution, padding) when the result must be a valid layout
    packed: bool = False  # the layout promise is pack_charts's (passes check_layout), not refine_uvs's
    recharted: bool = False  # the layout is new (rechart's, per corner): it must pass check_layout
    description: str = ""


# ----------------------------------------------------------------- inputs

def random_layout(rng, resolution):
    """A small valid-ish layout: a few grid charts apart, or random triangles, or grid charts beside a
    chart that overlaps itself (a fold, as on Suzanne)."""
    from layouts import fan_chart, grid_chart, merge

    kind = rng.integers(4)
    if kind == 3:
        folded = fan_chart((0.25, 0.75), 0.2, float(rng.uniform(370.0, 600.0)), int(rng.integers(5, 9)))
        uvs, triangles = merge(folded, grid_chart(int(rng.integers(1, 6)), (0.5, 0.05), (0.95, 0.5)),
                               grid_chart(int(rng.integers(1, 4)), (0.05, 0.05), (0.4, 0.4)))
        return uvs.astype(np.float32), triangles.astype(np.int32)
    if kind == 0:
        n = int(rng.integers(1, 4))
        margin = 3.0 / resolution
        cell = (1 - margin) / n
        charts = [grid_chart(int(rng.integers(1, 4)), (margin + j * cell, margin + i * cell),
                             (j * cell + cell, i * cell + cell)) for i in range(n) for j in range(n)]
        uvs, triangles = merge(*charts)
    elif kind == 1:
        uvs, triangles = grid_chart(int(rng.integers(1, 6)), (0.1, 0.1), (0.9, 0.9))
    else:
        count = int(rng.integers(1, 12))
        uvs = rng.uniform(0.0, 1.0, (count * 3, 2)).astype(np.float32)
        triangles = np.arange(count * 3, dtype=np.int32).reshape(-1, 3)
    return uvs.astype(np.float32), triangles.astype(np.int32)


def lightmap(rng, resolution):
    channels = (None, 1, 3, 4)[rng.integers(4)]
    shape = (resolution, resolution) if channels is None else (resolution, resolution, channels)
    image = rng.uniform(0.0, 1.0, shape).astype(np.float32)
    if rng.random() < 0.5:  # a shadow edge, what the refiner looks for
        image[:, : resolution // 2] *= 0.05
    return image


def maybe(rng, valid, make_hostile, p=0.5):
    return make_hostile(valid, rng) if rng.random() < p else valid


def mutate(kwargs, rng, makers, valid_fraction=VALID_FRACTION):
    """Replace one or two arguments of a valid call by hostile values (or none, valid_fraction of the time)."""
    if rng.random() < valid_fraction:
        return kwargs, []
    names = list(makers)
    chosen = list(rng.choice(names, size=min(len(names), int(rng.integers(1, 3))), replace=False))
    out = dict(kwargs)
    if "progress" in makers and rng.random() < 0.3:  # cancelling and raising callbacks, beside other hostility
        chosen.append("progress")
    for name in dict.fromkeys(chosen):
        out[name] = makers[name](kwargs.get(name), rng)
    return out, chosen


def as_array(value, rng):
    return hostile.array_like(value, rng) if value is not None else hostile.scalar(rng)


def as_number(value, rng):
    return hostile.scalar(rng)


def as_string(value, rng):
    return hostile.string(rng)


def as_progress(value, rng):
    return hostile.progress(rng)


def as_resolution(value, rng):
    return hostile.scalar(rng)


def _call(function, kwargs):
    positional = kwargs.pop("__args__", ())
    return lambda: function(*positional, **kwargs)


def _case(name, function, kwargs, rng, makers, **extra):
    kwargs, chosen = mutate(kwargs, rng, makers)
    inputs = [v for v in kwargs.values()]
    call_kwargs = dict(kwargs)
    return Case(name, _call(function, call_kwargs), inputs, description=f"{name} hostile: {chosen}", **extra)


# ------------------------------------------------------------------ cases

def case_gradient_map(lm, rng):
    r = int(rng.choice([4, 8, 16, 32]))
    image = lightmap(rng, r)
    kwargs = {"image": image, "mask": rng.random((r, r)) < 0.8 if rng.random() < 0.5 else None,
              "wavelet": str(rng.choice(WAVELETS)), "progress": None}
    return _case("gradient_map", lm.gradient_map, kwargs, rng,
                 {"image": as_array, "mask": as_array, "wavelet": as_string, "progress": as_progress})


def case_dwt2(lm, rng):
    r = int(rng.choice([2, 4, 8, 16]))
    kwargs = {"image": rng.standard_normal((r, r)).astype(np.float32), "wavelet": str(rng.choice(WAVELETS)),
              "mode": str(rng.choice(MODES)), "progress": None}
    return _case("dwt2", lm.dwt2, kwargs, rng,
                 {"image": as_array, "wavelet": as_string, "mode": as_string, "progress": as_progress})


def case_idwt2(lm, rng):
    r = int(rng.choice([2, 4, 8]))
    wavelet = str(rng.choice(WAVELETS))
    coeffs = lm.dwt2(rng.standard_normal((r, r)).astype(np.float32), wavelet) if rng.random() < 0.8 else \
        tuple(rng.standard_normal((r // 2, r // 2)).astype(np.float32) for _ in range(4))
    kwargs = {"coeffs": coeffs, "wavelet": wavelet, "mode": "periodic", "progress": None}

    def bad_coeffs(value, rng):
        parts = list(value) if isinstance(value, (tuple, list)) else [value]
        if rng.random() < 0.3:
            return hostile.junk(rng)
        if rng.random() < 0.3:
            return tuple(parts[: int(rng.integers(0, len(parts) + 1))])
        index = int(rng.integers(len(parts)))
        part = parts[index]
        parts[index] = tuple(hostile.array_like(p, rng) for p in part) if isinstance(part, tuple) \
            else hostile.array_like(part, rng)
        return tuple(parts)

    return _case("idwt2", lm.idwt2, kwargs, rng,
                 {"coeffs": bad_coeffs, "wavelet": as_string, "mode": as_string, "progress": as_progress})


def case_dwt(lm, rng):
    n = int(rng.choice([1, 2, 4, 8, 16, 17]))
    kwargs = {"signal": rng.standard_normal(n).astype(np.float32), "wavelet": str(rng.choice(WAVELETS)),
              "mode": str(rng.choice(MODES))}
    return _case("dwt", lm.dwt, kwargs, rng, {"signal": as_array, "wavelet": as_string, "mode": as_string})


def case_idwt(lm, rng):
    n = int(rng.choice([2, 4, 8]))
    wavelet = str(rng.choice(WAVELETS))
    kwargs = {"coeffs": lm.dwt(rng.standard_normal(n).astype(np.float32), wavelet), "wavelet": wavelet}

    def bad_coeffs(value, rng):
        if rng.random() < 0.3:
            return hostile.junk(rng)
        parts = list(value)
        index = int(rng.integers(len(parts)))
        parts[index] = hostile.array_like(parts[index], rng)
        return tuple(parts)

    return _case("idwt", lm.idwt, kwargs, rng, {"coeffs": bad_coeffs, "wavelet": as_string, "mode": as_string})


def case_layout_function(name):
    def build(lm, rng):
        r = int(rng.choice([8, 16, 32, 64]))
        uvs, triangles = random_layout(rng, r)
        kwargs = {"uvs": uvs, "triangles": triangles}
        makers = {"uvs": as_array, "triangles": as_array}
        if name in ("check_layout", "coverage_mask", "LayoutChecker"):
            kwargs["resolution"] = r if rng.random() < 0.7 else (r, r // 2 or 1)
            makers["resolution"] = as_resolution
        if name in ("check_layout", "LayoutChecker"):
            kwargs["padding"] = float(rng.choice([0, 1, 2, 4]))
            makers["padding"] = as_number
        if name == "check_layout" and rng.random() < 0.5:
            kwargs["reference_uvs"] = uvs + np.float32(rng.uniform(-0.01, 0.01))
            kwargs["relative_gutter"] = bool(rng.random() < 0.5)
            kwargs["failing_charts"] = bool(rng.random() < 0.5)
            makers.update(reference_uvs=as_array, relative_gutter=as_number, failing_charts=as_number)
        if name == "LayoutChecker":
            function = _layout_checker(lm, rng)
        else:
            function = getattr(lm, name)
        return _case(name, function, kwargs, rng, makers)
    return build


def _layout_checker(lm, rng):
    """LayoutChecker(...) then one or more of its methods, some with hostile arguments."""
    method = int(rng.integers(4))
    hostile_check = rng.random() < 0.5
    check_uvs_seed = int(rng.integers(1 << 30))

    def run(uvs, triangles, resolution, padding):
        checker = lm.LayoutChecker(uvs, triangles, resolution, padding)
        if method == 0:
            return checker.charts()
        if method == 1:
            return checker.coverage_mask()
        if method == 2:
            return checker.gutter_texels()
        inner = np.random.default_rng(check_uvs_seed)
        other = hostile.array_like(np.asarray(uvs), inner) if hostile_check else None
        return checker.check(other, failing_charts=bool(inner.random() < 0.5),
                             relative_gutter=bool(inner.random() < 0.5))
    return run


def case_grid_cell_areas(lm, rng):
    r = int(rng.choice([1, 2, 4, 8]))
    grid = lm.identity_grid(r) + rng.uniform(-0.2, 0.2, (r + 1, r + 1, 2)).astype(np.float32) / r
    return _case("grid_cell_areas", lm.grid_cell_areas, {"grid": grid.astype(np.float32)}, rng, {"grid": as_array})


def case_warp_uvs(lm, rng):
    r = int(rng.choice([1, 2, 4, 8, 16]))
    grid = lm.identity_grid(r).astype(np.float32)
    uvs = rng.uniform(0, 1, (int(rng.integers(0, 20)), 2)).astype(np.float32)
    return _case("warp_uvs", lm.warp_uvs, {"uvs": uvs, "grid": grid}, rng, {"uvs": as_array, "grid": as_array})


def case_identity_grid(lm, rng):
    kwargs = {"resolution": int(rng.choice([1, 2, 8])) if rng.random() < 0.5 else (2, 3)}
    return _case("identity_grid", lm.identity_grid, kwargs, rng, {"resolution": as_resolution})


def case_run_automaton(lm, rng):
    r = int(rng.choice([2, 4, 8, 16]))
    energy = rng.uniform(0, 1, (r, r) if rng.random() < 0.7 else (r, r, 4)).astype(np.float32)
    kwargs = {"energy": energy, "mask": rng.random((r, r)) < 0.8 if rng.random() < 0.5 else None,
              "rigid": rng.random((r, r)) < 0.2 if rng.random() < 0.3 else None,
              "max_steps": int(rng.integers(1, 6)), "border": str(rng.choice(["same", "free", "fixed"])),
              "passes": int(rng.integers(1, 3)), "progress": None}
    makers = {"energy": as_array, "mask": as_array, "rigid": as_array, "max_steps": as_number,
              "border": as_string, "passes": as_number, "progress": as_progress}
    for name in ("diffusion", "rate", "delta", "min_shrink", "max_magnification", "edge_shrink"):
        makers[name] = as_number
    for name in ("coarse_to_fine", "check_invariants"):
        makers[name] = as_number
    return _case("run_automaton", lm.run_automaton, kwargs, rng, makers)


def case_refine_uvs(lm, rng):
    r = int(rng.choice([8, 16, 32]))
    uvs, triangles = random_layout(rng, r)
    kwargs = {"lightmap": lightmap(rng, r), "uvs": uvs, "triangles": triangles, "resolution": r,
              "padding": float(rng.choice([0, 1, 2])), "strength": float(rng.choice([1.0, 24.0])),
              "max_steps": int(rng.integers(1, 5)), "progress": None}
    makers = {"lightmap": as_array, "uvs": as_array, "triangles": as_array, "resolution": as_resolution,
              "padding": as_number, "mask": as_array, "gradient": as_array, "strength": as_number,
              "max_magnification": as_number, "min_shrink": as_number, "edge_shrink": as_number,
              "delta": as_number, "passes": as_number, "border": as_string, "directional": as_number,
              "wavelet": as_string, "diffusion": as_number, "max_steps": as_number, "progress": as_progress,
              "repack": as_number, "min_chart_scale": as_number, "max_chart_scale": as_number,
              "max_stretch": as_number, "triangle_stretch": as_number}
    kwargs, chosen = mutate(kwargs, rng, makers)
    layout = (kwargs["uvs"], kwargs["triangles"], kwargs["resolution"], kwargs["padding"])
    return Case("refine_uvs", _call(lm.refine_uvs, dict(kwargs)), list(kwargs.values()), layout=layout,
                description=f"refine_uvs hostile: {chosen}")


def case_pack_charts(lm, rng):
    r = int(rng.choice([16, 32, 64]))
    uvs, triangles = random_layout(rng, r)
    charts = lm.find_charts(uvs, triangles)
    count = int(charts.max()) + 1 if len(charts) else 0
    kwargs = {"uvs": uvs, "triangles": triangles, "charts": charts if rng.random() < 0.5 else None,
              "scales": rng.uniform(0.3, 2.0, count) if rng.random() < 0.5 else None, "resolution": r,
              "padding": float(rng.choice([0, 1, 2])), "rotations": bool(rng.random() < 0.5), "progress": None,
              "fixed_scale": float(rng.uniform(0.01, 3.0)) if rng.random() < 0.3 else None}
    makers = {"uvs": as_array, "triangles": as_array, "charts": as_array, "scales": as_array,
              "resolution": as_resolution, "padding": as_number, "rotations": as_number,
              "progress": as_progress, "tolerance": as_number, "subdivision": as_number, "fixed_scale": as_number}
    kwargs, chosen = mutate(kwargs, rng, makers)
    layout = (kwargs["uvs"], kwargs["triangles"], kwargs["resolution"], kwargs["padding"])
    return Case("pack_charts", _call(lm.pack_charts, dict(kwargs)), list(kwargs.values()), layout=layout,
                packed=True, description=f"pack_charts hostile: {chosen}")


def random_mesh(rng):
    """A small mesh: a bent grid, a closed box, or random triangles (slivers and repeats included)."""
    kind = rng.integers(3)
    if kind == 0:
        n = int(rng.integers(1, 6))
        xs, ys = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
        positions = np.stack([xs.ravel(), ys.ravel(), rng.uniform(0, 0.5) * np.sin(4 * xs.ravel())], axis=1)
        quads = [(i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j)
                 for i in range(n) for j in range(n)]
        triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    elif kind == 1:
        positions = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    else:
        count = int(rng.integers(1, 10))
        positions = rng.uniform(-1, 1, (count + 2, 3))
        triangles = rng.integers(0, count + 2, (count, 3))
    return positions.astype(np.float32), np.asarray(triangles, np.int32)


def shading_normals(rng, positions):
    """Shading normals for `positions`: smooth (a function of the position, so corners at one
    position agree), random per row (hard everywhere), or with zero and non-finite rows."""
    positions = np.asarray(positions, np.float64)
    kind = rng.integers(3)
    if kind == 0:
        with np.errstate(all="ignore"):
            return np.column_stack([np.sin(positions[:, 0]), np.cos(positions[:, 1]), np.ones(len(positions))])
    normals = rng.normal(size=(len(positions), 3))
    if kind == 2 and len(normals):
        normals[rng.integers(len(normals), size=3)] = rng.choice([0.0, np.nan, np.inf, 1e300])
    return normals


def case_rechart(lm, rng):
    positions, triangles = random_mesh(rng)
    r = int(rng.choice([16, 32, 64]))
    kwargs = {"positions": positions, "triangles": triangles, "angle": float(rng.uniform(5, 85)), "resolution": r,
              "padding": float(rng.choice([0, 1, 2])), "progress": None}
    if rng.random() < 0.5:
        kwargs["normals"] = shading_normals(rng, positions)
        kwargs["smooth_angle"] = float(rng.uniform(5, 85))
    if rng.random() < 0.4 and len(np.shape(triangles)) == 2:
        # Polygon labels: pairs, a few large ones, or any ints (negative, huge).
        count = len(triangles)
        kwargs["polygons"] = [np.arange(count) // 2, rng.integers(0, 3, count),
                              rng.integers(-2 ** 31, 2 ** 31 - 1, count)][int(rng.integers(3))]
    makers = {"positions": as_array, "triangles": as_array, "angle": as_number, "resolution": as_resolution,
              "padding": as_number, "weld_tolerance": as_number, "rotations": as_number, "progress": as_progress,
              "normals": as_array, "smooth_angle": as_number, "polygons": as_array}
    kwargs, chosen = mutate(kwargs, rng, makers)
    return Case("rechart", _call(lm.rechart, dict(kwargs)), list(kwargs.values()),
                layout=(None, kwargs["triangles"], kwargs["resolution"], kwargs["padding"]), recharted=True,
                description=f"rechart hostile: {chosen}")


def case_refine_uvs_rechart(lm, rng):
    """refine_uvs' re-chart route: a small mesh with one chart per triangle (no room), its positions."""
    positions, triangles = random_mesh(rng)
    r = int(rng.choice([16, 32, 64]))
    count = len(triangles)
    across = int(np.ceil(np.sqrt(max(count, 1))))
    cell = 1.0 / across
    inset = np.array([(0.2, 0.2), (0.8, 0.2), (0.2, 0.8)])
    if rng.random() < 0.5:
        inset = inset[::-1]  # mirrored charts, as Lightmap Pack leaves some
    uvs = np.concatenate([(np.array([k % across, k // across]) + inset) * cell for k in range(count)])
    corner_positions = positions[triangles.ravel() % len(positions)] if len(positions) else positions
    return _route_case(lm, rng, r, uvs, corner_positions, "re-chart route", {"strength": as_number})


def _route_case(lm, rng, r, uvs, positions, what, extra_makers, normals=False):
    """A hostile refine_uvs call on per-corner `uvs` with the mesh `positions` (the re-chart route's
    input); with `normals`, shading normals half the time."""
    kwargs = {"lightmap": lightmap(rng, r), "uvs": uvs.astype(np.float32),
              "triangles": np.arange(len(uvs), dtype=np.int32).reshape(-1, 3), "resolution": r,
              "padding": float(rng.choice([0, 1, 2])), "positions": positions, "max_steps": 2, "progress": None}
    if normals and rng.random() < 0.5:
        kwargs["normals"] = shading_normals(rng, positions)
    if rng.random() < 0.5:  # faces of the triangles: pairs (quads), random ids, or one face
        count = len(kwargs["triangles"])
        kwargs["polygons"] = [np.arange(count) // 2, rng.integers(-3, 3, count), np.zeros(count, np.int64)][
            int(rng.integers(0, 3))]
    makers = {"lightmap": as_array, "positions": as_array, "rechart": as_number, "resolution": as_resolution,
              "padding": as_number, "progress": as_progress, "polygons": as_array, **extra_makers}
    kwargs, chosen = mutate(kwargs, rng, makers)
    layout = (kwargs["uvs"], kwargs["triangles"], kwargs["resolution"], kwargs["padding"])
    return Case("refine_uvs", _call(lm.refine_uvs, dict(kwargs)), list(kwargs.values()), layout=layout,
                description=f"refine_uvs ({what}) hostile: {chosen}")



def case_refine_uvs_folds(lm, rng):
    """refine_uvs' re-chart route on a layout with room whose one chart folds over creases: a grid chart
    whose mesh bends along random lines (sharp or not), its positions, hostile ones."""
    n = int(rng.integers(2, 9))
    r = int(rng.choice([16, 32, 64]))
    ticks = np.linspace(0.1, 0.9, n + 1)
    quads = [((ticks[j], ticks[i]), (ticks[j + 1], ticks[i]), (ticks[j + 1], ticks[i + 1]), (ticks[j], ticks[i + 1]))
             for i in range(n) for j in range(n)]
    uvs = np.array([corner for a, b, c, d in quads for corner in (a, b, c, a, c, d)], np.float64)
    fold = rng.uniform(0.1, 0.9, 2)
    height = rng.uniform(-3, 3) * np.abs(uvs[:, 0] - fold[0]) + rng.uniform(-3, 3) * np.abs(uvs[:, 1] - fold[1])
    positions = np.column_stack([uvs, height]) * rng.choice([1e-6, 1.0, 1e6])
    return _route_case(lm, rng, r, uvs, positions, "folded chart", {"normals": as_array}, normals=True)

# ---------------------------------------------------------------- images

PNG_HUGE_HEADER = (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + (100000).to_bytes(4, "big") * 2
                   + b"\x08\x06\x00\x00\x00" + b"\x00\x00\x00\x00")
HDR_HUGE_HEADER = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n" + b"\x02\x02\x00\x10" * 64


def case_write_image(lm, rng):
    folder = tempfile.mkdtemp(prefix="lmrefine_fuzz_")
    ext = str(rng.choice([".png", ".exr", ".hdr", ".tif", ".jpg", ".xyz", ""]))
    path = os.path.join(folder, "out" + ext)
    r = int(rng.choice([1, 4, 8]))
    shape = [(r, r), (r, r, 1), (r, r, 2), (r, r, 3), (r, r, 4)][rng.integers(5)]
    kwargs = {"path": path, "array": rng.uniform(0, 1, shape).astype(np.float32)}
    if rng.random() < 0.3:
        kwargs["format"] = str(rng.choice(["half", "float", "uint8", "uint16"]))
    if rng.random() < 0.3:
        kwargs["srgb"] = bool(rng.random() < 0.5)

    def bad_path(value, rng):
        choices = [os.path.join(folder, "a\x00b.png"), folder, os.path.join(folder, "no", "dir.png"),
                   os.path.join(folder, "x" * 5000 + ".png"), "/dev/null", "/dev/full",
                   os.path.join(folder, "out.png").encode(), "", 3, None, ["x.png"]]
        return choices[rng.integers(len(choices))]

    return _case("write_image", lm.write_image, kwargs, rng,
                 {"path": bad_path, "array": as_array, "format": as_string, "srgb": as_number})


def case_read_image(lm, rng):
    folder = tempfile.mkdtemp(prefix="lmrefine_fuzz_")
    kind = int(rng.integers(11))
    ext = str(rng.choice([".png", ".exr", ".hdr", ".tif", ".jpg"]))
    path = os.path.join(folder, "in" + ext)
    if kind == 0:  # a valid image
        lm.write_image(path, rng.uniform(0, 1, (4, 4, 3)).astype(np.float32))
    elif kind == 1:  # truncated
        lm.write_image(path, rng.uniform(0, 1, (16, 16, 3)).astype(np.float32))
        size = os.path.getsize(path)
        with open(path, "r+b") as file:
            file.truncate(int(rng.integers(0, max(size, 1))))
    elif kind == 2:  # random bytes
        with open(path, "wb") as file:
            file.write(rng.bytes(int(rng.integers(0, 2000))))
    elif kind == 3:  # corrupted in the middle
        lm.write_image(path, rng.uniform(0, 1, (16, 16, 3)).astype(np.float32))
        data = bytearray(open(path, "rb").read())
        for _ in range(8):
            data[int(rng.integers(len(data)))] = int(rng.integers(256))
        open(path, "wb").write(bytes(data))
    elif kind == 4:
        path = os.path.join(folder, "huge.png")
        open(path, "wb").write(PNG_HUGE_HEADER)
    elif kind == 5:
        path = os.path.join(folder, "huge.hdr")
        open(path, "wb").write(HDR_HUGE_HEADER)
    elif kind == 6:
        path = str(rng.choice(["/dev/zero", "/dev/null", "/proc/self/status", folder, "/nonexistent/x.png"]))
    elif kind == 7:
        path = os.path.join(folder, "fifo.png")
        os.mkfifo(path)
    elif kind == 8:
        path = os.path.join(folder, "loop.png")
        os.symlink(path, path)
    elif kind == 9:
        path = hostile.junk(rng)
    else:
        path = os.path.join(folder, "in\x00.png")
    return Case("read_image", lambda: lm.read_image(path), [], description=f"read_image kind {kind}: {path!r}")


# ----------------------------------------------------------------- baker

def _scene_call(lm, rng):
    """Build a Scene with hostile meshes, lights and world; returns (scene, description of what went in)."""
    from baker_scenes import floor

    scene = lm.Scene()
    notes = []
    for _ in range(int(rng.integers(1, 3))):
        positions, triangles, uvs = floor(half=float(rng.uniform(0.5, 2)), z=float(rng.uniform(-1, 1)))
        kwargs = {"positions": positions.astype(np.float32), "triangles": triangles, "uvs": uvs.astype(np.float32),
                  "receiver": bool(rng.random() < 0.8)}
        if rng.random() < 0.3:
            kwargs["normals"] = np.tile(np.float32([0, 0, 1]), (6, 1))
        if rng.random() < 0.3:  # a degenerate triangle beside the real ones
            kwargs["positions"] = np.vstack([kwargs["positions"], [[3, 3, 0], [4, 3, 0], [5, 3, 0]]]).astype(np.float32)
            kwargs["triangles"] = np.vstack([triangles, [[4, 5, 6]]])
            kwargs["uvs"] = np.vstack([kwargs["uvs"], rng.uniform(0, 1, (3, 2))]).astype(np.float32)
            if "normals" in kwargs:
                kwargs["normals"] = np.tile(np.float32([0, 0, 1]), (9, 1))
        # Mostly valid meshes, so the bake itself runs often enough to be tested.
        kwargs, chosen = mutate(kwargs, rng, {"positions": as_array, "triangles": as_array, "uvs": as_array,
                                              "normals": as_array, "base_color": as_array, "receiver": as_number},
                                valid_fraction=0.6)
        notes.append(f"add_mesh {chosen}")
        try:
            scene.add_mesh(**kwargs)
        except (ValueError, TypeError, MemoryError):
            pass  # a refused mesh: the scene goes on without it
    if rng.random() < 0.8:
        scene.add_light("point", energy=50.0, position=(0.0, 0.0, 2.0))
    for _ in range(int(rng.integers(0, 3))):
        kind = str(rng.choice(["point", "spot", "sun", "area"]))
        params = {"energy": float(rng.uniform(1, 100)), "position": (0.0, 0.0, 2.0)}
        if kind == "sun":
            params = {"energy": 3.0, "direction": (0.1, 0.2, -1.0)}
        if rng.random() < 0.4:
            key = str(rng.choice(["energy", "color", "position", "direction", "axis_x", "matrix", "shape", "size",
                                  "size_y", "angle", "spot_size", "spot_blend", "shadow_soft_size", "bogus"]))
            params[key] = hostile.scalar(rng) if rng.random() < 0.7 else hostile.array_like(np.eye(4), rng)
            notes.append(f"add_light {kind} {key}")
        if rng.random() < 0.1:
            kind = hostile.string(rng)
        try:
            scene.add_light(kind, **params)
        except (ValueError, TypeError, MemoryError):
            pass
    if rng.random() < 0.5:
        color = (0.1, 0.1, 0.1) if rng.random() < 0.5 else hostile.array_like(np.float32([0.1, 0.1, 0.1]), rng)
        try:
            scene.set_world(color)
        except (ValueError, TypeError, MemoryError):
            pass
    return scene, notes


def case_scene(lm, rng):
    """The Scene methods themselves, on hostile arguments (errors escape: they are the outcome)."""
    scene = lm.Scene()
    which = int(rng.integers(4))
    if which == 0:
        positions, triangles, uvs = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.int32([[0, 1, 2]]), \
            np.float32([[0, 0], [1, 0], [0, 1]])
        kwargs, chosen = mutate({"positions": positions, "triangles": triangles, "uvs": uvs}, rng,
                                {"positions": as_array, "triangles": as_array, "uvs": as_array,
                                 "normals": as_array, "base_color": as_array, "receiver": as_number})
        return Case("Scene.add_mesh", lambda: scene.add_mesh(**kwargs), list(kwargs.values()),
                    description=f"Scene.add_mesh hostile: {chosen}")
    if which == 1:
        kind = str(rng.choice(["point", "spot", "sun", "area"])) if rng.random() < 0.8 else hostile.string(rng)
        params = {str(rng.choice(["energy", "color", "position", "direction", "axis_x", "matrix", "shape", "size",
                                  "size_y", "angle", "spot_size", "spot_blend", "shadow_soft_size", "x"])):
                  hostile.scalar(rng) if rng.random() < 0.7 else hostile.array_like(np.eye(4), rng)}
        if rng.random() < 0.5:
            params.setdefault("energy", 10.0)
        return Case("Scene.add_light", lambda: scene.add_light(kind, **params), list(params.values()),
                    description=f"Scene.add_light {kind!r} {sorted(params)}")
    if which == 2:
        color = hostile.array_like(np.float32([0.1, 0.2, 0.3]), rng)
        return Case("Scene.set_world", lambda: scene.set_world(color), [color], description="Scene.set_world")
    mesh = hostile.scalar(rng)
    return Case("Scene.degenerate_triangles", lambda: (scene.degenerate_triangles(mesh), scene.mesh_count,
                                                        scene.light_count),
                description=f"Scene.degenerate_triangles({mesh!r})")


def case_bake(lm, rng):
    scene, notes = _scene_call(lm, rng)
    kwargs = {"scene": scene, "resolution": int(rng.choice([4, 8, 16])),
              "passes": tuple(rng.choice(["direct", "ao", "indirect", "combined"], size=int(rng.integers(1, 3)),
                                         replace=False)),
              "samples": int(rng.integers(1, 3)), "seed": int(rng.integers(100)), "dilation": int(rng.integers(0, 4)),
              "bounces": int(rng.integers(0, 3)), "denoise": bool(rng.random() < 0.3),
              "atlas": bool(rng.random() < 0.2), "progress": None}
    makers = {"scene": lambda v, r: hostile.scalar(r), "resolution": as_resolution,
              "passes": lambda v, r: hostile.string(r) if r.random() < 0.5 else (hostile.string(r),),
              "samples": as_number, "seed": as_number, "dilation": as_number, "bounces": as_number,
              "denoise": as_number, "ao_distance": as_number, "atlas": as_number, "progress": as_progress}
    case = _case("bake", lm.bake, kwargs, rng, makers)
    case.description += f"; scene: {notes}"
    case.inputs = [v for v in case.inputs if not isinstance(v, lm.Scene)]
    return case


def case_evaluate(lm, rng):
    scene, notes = _scene_call(lm, rng)
    count = int(rng.integers(0, 10))
    points = np.column_stack([rng.uniform(-1, 1, (count, 2)), np.zeros(count)]).astype(np.float32)
    normals = np.tile(np.float32([0, 0, 1]), (count, 1))
    kwargs = {"scene": scene, "points": points, "normals": normals, "samples": int(rng.integers(1, 4)),
              "passes": ("direct",), "progress": None}
    makers = {"points": as_array, "normals": as_array, "samples": as_number, "seed": as_number,
              "passes": lambda v, r: hostile.string(r), "bounces": as_number, "ao_distance": as_number,
              "progress": as_progress, "scene": lambda v, r: hostile.scalar(r)}
    case = _case("evaluate", lm.evaluate, kwargs, rng, makers)
    case.description += f"; scene: {notes}"
    case.inputs = [v for v in case.inputs if not isinstance(v, lm.Scene)]
    return case


def case_trace_rays(lm, rng):
    scene, notes = _scene_call(lm, rng)
    count = int(rng.integers(0, 10))
    origins = np.column_stack([rng.uniform(-1, 1, (count, 2)), np.full(count, 2.0)]).astype(np.float32)
    directions = np.column_stack([rng.uniform(-0.3, 0.3, (count, 2)), -np.ones(count)]).astype(np.float32)
    kwargs = {"scene": scene, "origins": origins, "directions": directions, "progress": None}
    makers = {"origins": as_array, "directions": as_array, "progress": as_progress,
              "scene": lambda v, r: hostile.scalar(r)}
    case = _case("trace_rays", lm.trace_rays, kwargs, rng, makers)
    case.description += f"; scene: {notes}"
    case.inputs = [v for v in case.inputs if not isinstance(v, lm.Scene)]
    return case


def case_tessellate(lm, rng):
    r = int(rng.choice([8, 16, 32]))
    uvs, triangles = random_layout(rng, r)
    corners = len(uvs)
    positions = rng.uniform(-1, 1, (corners, 3))
    # Corner k of triangle t is vertex 3t + k, except where two triangles are made to share an edge.
    vertex_triangles = np.arange(corners).reshape(-1, 3)
    if len(vertex_triangles) > 1:
        vertex_triangles[1, :2] = vertex_triangles[0, 1::-1]
    kwargs = {"positions": positions, "triangles": vertex_triangles, "uvs": uvs,
              "strength": rng.uniform(0, 1, (r, r)), "budget": float(rng.choice([0.0, 0.25, 4.0])),
              "corner_attributes": {"other": rng.random((corners, 2))} if rng.random() < 0.5 else None}
    makers = {"positions": as_array, "triangles": as_array, "uvs": as_array, "strength": as_array,
              "budget": as_number, "min_texels": as_number, "threshold": as_number,
              "corner_attributes": lambda v, r: {"x": hostile.array_like(np.zeros((3, 2)), r)}
              if r.random() < 0.5 else hostile.scalar(r)}
    return _case("tessellate", lm.tessellate, kwargs, rng, makers)


def case_transition_strength_of(lm, rng):
    r = int(rng.choice([8, 16, 32]))
    uvs, triangles = random_layout(rng, r)
    kwargs = {"lightmap": lightmap(rng, r), "uvs": uvs, "triangles": triangles,
              "wavelet": str(rng.choice(WAVELETS))}
    makers = {"lightmap": as_array, "uvs": as_array, "triangles": as_array, "wavelet": as_string}
    return _case("transition_strength_of", lm.transition_strength_of, kwargs, rng, makers)


def case_dilate(lm, rng):
    r = int(rng.choice([8, 16, 32]))
    uvs, triangles = random_layout(rng, r)
    image = rng.uniform(0.0, 1.0, (r, r, int(rng.choice([3, 4])))).astype(np.float32)
    kwargs = {"image": image, "uvs": uvs, "triangles": triangles, "texels": int(rng.choice([0, 1, 16]))}
    makers = {"image": as_array, "uvs": as_array, "triangles": as_array, "texels": as_number}
    return _case("dilate", lm.dilate, kwargs, rng, makers)


def case_tessellated_refine_options(lm, rng):
    r = int(rng.choice([8, 16, 32]))
    uvs, triangles = random_layout(rng, r)
    kwargs = {"options": {"strength": 24.0, "rechart": bool(rng.random() < 0.8)}, "uvs": uvs, "triangles": triangles}
    makers = {"options": lambda v, r: hostile.scalar(r), "uvs": as_array, "triangles": as_array}
    return _case("tessellated_refine_options", lm.tessellated_refine_options, kwargs, rng, makers)


BUILDERS = (
    case_gradient_map, case_dwt2, case_idwt2, case_dwt, case_idwt,
    case_layout_function("check_layout"), case_layout_function("coverage_mask"),
    case_layout_function("find_charts"), case_layout_function("LayoutChecker"),
    case_grid_cell_areas, case_warp_uvs, case_identity_grid, case_run_automaton,
    case_refine_uvs, case_refine_uvs,  # the whole pipeline gets twice the share
    case_pack_charts, case_rechart, case_refine_uvs_rechart, case_refine_uvs_folds,
    case_write_image, case_read_image, case_scene, case_bake, case_evaluate, case_trace_rays,
    case_tessellate, case_transition_strength_of, case_tessellated_refine_options, case_dilate,
)


def build(lm, seed, index):
    """The case (seed, index): builders take turns, each drawing from its own generator."""
    rng = np.random.default_rng([seed, index])
    return BUILDERS[index % len(BUILDERS)](lm, rng)
