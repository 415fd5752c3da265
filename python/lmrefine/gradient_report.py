"""Pictures and a summary of a gradient map (the first stage of the method).

Used by ``python3 -m lmrefine gradient-map`` and the stage-1 ``demo``.
"""

import json
import os
import time

import numpy as np

from . import _native

# Channel letter -> what it measures (see lmrefine.gradient_map).
CHANNELS = {
    "r": "light changing along y (down the columns), forward sense",
    "g": "light changing along x (along the rows), forward sense",
    "b": "light changing along y (down the columns), backward sense",
    "a": "light changing along x (along the rows), backward sense",
}


def robust_max(values):
    """The 99.9th percentile of the non-zero values: one hot texel does not
    turn a whole picture black."""
    nonzero = values[values > 0]
    return float(np.percentile(nonzero, 99.9)) if nonzero.size else 0.0


def channel_picture(channel, mask, scale):
    """Gray picture of one channel, 0..scale mapped to black..white; texels
    that no chart covers are dark blue so the layout stays visible."""
    value = np.clip(channel / scale, 0.0, 1.0) if scale > 0 else np.zeros_like(channel)
    picture = np.repeat(value[..., None], 3, axis=2)
    picture[~mask] = (0.02, 0.03, 0.12)
    return picture.astype(np.float32)


def direction_picture(gradient, mask, scale):
    """Vertical change (r + b) in red, horizontal change (g + a) in green."""
    vertical = gradient[..., 0] + gradient[..., 2]
    horizontal = gradient[..., 1] + gradient[..., 3]
    picture = np.zeros(gradient.shape[:2] + (3,), np.float32)
    if scale > 0:
        picture[..., 0] = np.clip(vertical / (2 * scale), 0, 1)
        picture[..., 1] = np.clip(horizontal / (2 * scale), 0, 1)
    picture[~mask] = (0.02, 0.03, 0.12)
    return picture


def summarize(gradient, mask, seconds):
    covered = int(mask.sum())
    summary = {
        "height": int(gradient.shape[0]),
        "width": int(gradient.shape[1]),
        "covered_texels": covered,
        "covered_fraction": covered / mask.size,
        "seconds_gradient_map": seconds,
        "channels": {},
    }
    for index, letter in enumerate("rgba"):
        values = gradient[..., index][mask]
        peak = float(values.max()) if values.size else 0.0
        summary["channels"][letter] = {
            "meaning": CHANNELS[letter],
            "max": peak,
            "mean": float(values.mean()) if values.size else 0.0,
            # Where light changes noticeably: the texels the automaton will enlarge.
            "active_fraction": float((values > 0.1 * peak).mean()) if peak > 0 else 0.0,
        }
    return summary


def write_markdown(path, summary, source):
    lines = [
        "# Gradient map summary",
        "",
        f"Source: `{source}`, {summary['width']}x{summary['height']} texels, "
        f"{summary['covered_fraction'] * 100:.1f}% covered by charts.",
        f"Gradient map computed in {summary['seconds_gradient_map'] * 1000:.1f} ms.",
        "",
        "| channel | measures | max | mean (covered) | active texels (>10% of max) |",
        "|---|---|---|---|---|",
    ]
    for letter, channel in summary["channels"].items():
        lines.append(
            f"| {letter} | {channel['meaning']} | {channel['max']:.4g} | {channel['mean']:.4g} | "
            f"{channel['active_fraction'] * 100:.1f}% |"
        )
    lines += [
        "",
        "Pictures: `gradient_r.png` ... `gradient_a.png` (one per channel, same scale), "
        "`gradient_direction.png` (red: change along y, green: change along x), `lightmap.png`. "
        "Dark blue: texels no chart covers (always 0 in the map).",
        "",
    ]
    with open(path, "w") as handle:
        handle.write("\n".join(lines))


def tone_map(lightmap):
    """Display picture of an HDR lightmap: exposure to its 99th percentile."""
    rgb = lightmap[..., :3] if lightmap.ndim == 3 else np.repeat(lightmap[..., None], 3, axis=2)
    if rgb.shape[2] == 1:
        rgb = np.repeat(rgb, 3, axis=2)
    scale = np.percentile(rgb, 99) or 1.0
    return np.clip(rgb / scale, 0, 1).astype(np.float32)


def write_gradient_report(lightmap, mask, out_dir, source="array", wavelet="d4", progress=None):
    """Compute the gradient map of ``lightmap`` and write its pictures,
    ``summary.json`` and ``summary.md`` into ``out_dir``. Returns the summary."""
    os.makedirs(out_dir, exist_ok=True)
    start = time.perf_counter()
    gradient = _native.gradient_map(lightmap, mask, wavelet=wavelet, progress=progress)
    seconds = time.perf_counter() - start
    scale = robust_max(gradient[mask])
    for index, letter in enumerate("rgba"):
        _native.write_image(os.path.join(out_dir, f"gradient_{letter}.png"),
                            channel_picture(gradient[..., index], mask, scale))
    _native.write_image(os.path.join(out_dir, "gradient_direction.png"), direction_picture(gradient, mask, scale))
    _native.write_image(os.path.join(out_dir, "lightmap.png"), tone_map(lightmap))
    _native.write_image(os.path.join(out_dir, "gradient_map.exr"), gradient)
    summary = summarize(gradient, mask, seconds)
    summary["source"] = source
    summary["wavelet"] = wavelet
    with open(os.path.join(out_dir, "summary.json"), "w") as handle:
        json.dump(summary, handle, indent=2)
    write_markdown(os.path.join(out_dir, "summary.md"), summary, source)
    return summary
