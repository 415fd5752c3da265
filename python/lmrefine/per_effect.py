"""Separate layouts for separate effects (method.md §6, issue 14 item 3).

Direct light (hard shadow edges) and indirect light (slow bounce light) have
different signals. Each effect gets its own refined layout, refined from its
own first bake, and its own map at its own resolution; the final light at a
surface point is their sum (the combined pass is direct + indirect,
docs/baker.md; AO is not a term of it). The texels are split between the
effects so that together they hold no more than the one combined map they are
compared with (R^2), by a split rule:

- ``equal``: half each.
- ``energy``: in proportion to each effect's gradient energy G (the sum of
  squared differences between neighbouring covered texels of its first bake
  at R, without the bake's noise: see gradient_energy): the effect with more
  edges gets more texels.
- ``sqrt``: in proportion to sqrt(G). With the first-order error model
  err^2 ~ G h^2 ~ G / n (h the texel size, n the texel count), this split
  minimises the summed squared error of the effects under sum n = R^2.

Used by lmrefine.evaluation (``evaluate --per-effect``); measured in
docs/refiner.md.
"""

import math

import numpy as np

EFFECTS = ("direct", "indirect")
SPLIT_RULES = ("equal", "energy", "sqrt")
# No effect gets less than this share of the texels (nor a side under 8):
# a map of a few texels cannot be refined and a rule must not starve one.
MIN_FRACTION = 0.05


def parse_rules(value):
    """`value` as a tuple of split rules: a rule name, a comma-separated list
    or a sequence of names. ValueError naming the unknown rule."""
    if isinstance(value, str):
        names = tuple(name.strip() for name in value.split(","))
    elif isinstance(value, (tuple, list)):
        names = tuple(value)
    else:
        raise TypeError(f"per_effect must be a split rule ({', '.join(SPLIT_RULES)}) or a list of them, "
                        f"got {type(value).__name__}")
    if not names:
        raise ValueError(f"per_effect names no split rule; use some of {', '.join(SPLIT_RULES)}")
    for name in names:
        if name not in SPLIT_RULES:
            raise ValueError(f"unknown per-effect split rule {name!r}; use one of {', '.join(SPLIT_RULES)} "
                             "(comma-separated for several)")
    if len(set(names)) != len(names):
        raise ValueError(f"per_effect names a split rule twice: {','.join(names)}")
    return names


def gradient_energy(image, second=None):
    """Sum of squared RGB differences between horizontally and vertically
    neighbouring texels that are both covered (alpha > 0.5) in a baked map
    (H, W, 4): the signal an effect's layout has to resolve.

    A bake's noise adds its own energy, and an indirect bake at a few dozen
    samples is mostly noise texel to texel. With `second`, an independent
    bake of the same map (another seed), the sum is of products of the two
    bakes' differences instead: the noises are independent, so its
    expectation is the energy of the light alone."""
    image = np.asarray(image, np.float64)
    other = image if second is None else np.asarray(second, np.float64)
    if other.shape != image.shape:
        raise ValueError(f"second must be a bake of the same map, shape {image.shape}; got {other.shape}")
    covered = (image[..., 3] > 0.5) & (other[..., 3] > 0.5)
    energy = 0.0
    for axis in (0, 1):
        both = np.logical_and(np.delete(covered, 0, axis), np.delete(covered, -1, axis))
        product = np.diff(image[..., :3], axis=axis) * np.diff(other[..., :3], axis=axis)
        energy += float(product.sum(axis=-1)[both].sum())
    return energy


def split_fractions(rule, energies):
    """Each effect's share of the texels under `rule` ({effect: fraction},
    summing to 1, none under MIN_FRACTION); `energies` {effect: G}."""
    names = list(energies)
    if rule == "equal" or not any(energies[name] > 0 for name in names):
        weights = np.ones(len(names))
    elif rule == "energy":
        weights = np.array([max(energies[name], 0.0) for name in names])
    elif rule == "sqrt":
        weights = np.sqrt([max(energies[name], 0.0) for name in names])
    else:
        raise ValueError(f"unknown per-effect split rule {rule!r}; use one of {', '.join(SPLIT_RULES)}")
    fractions = weights / weights.sum()
    # Lift the starved effects to the floor, taking it from the others in proportion.
    low = fractions < MIN_FRACTION
    if low.any():
        rest = fractions[~low].sum()
        fractions = np.where(low, MIN_FRACTION, fractions * (1.0 - MIN_FRACTION * low.sum()) / rest)
    return {name: float(f) for name, f in zip(names, fractions)}


def split_resolutions(resolution, fractions):
    """Square map sides {effect: r} whose texel counts sum to at most
    resolution^2 and as close to it as square sides allow (each r at least
    8): floor(sqrt(f) R), then one more texel row and column for the effects
    furthest under their share while the total stays within R^2."""
    total = resolution * resolution
    sides = {name: max(8, int(math.floor(math.sqrt(f) * resolution))) for name, f in fractions.items()}
    if sum(r * r for r in sides.values()) > total:
        raise ValueError(f"resolution {resolution} is too small to split between {len(fractions)} effects "
                         "(each needs at least 8 x 8 texels): raise --resolution")
    for name in sorted(fractions, key=lambda n: sides[n] ** 2 / total - fractions[n]):
        grown = sum(r * r for r in sides.values()) - sides[name] ** 2 + (sides[name] + 1) ** 2
        if grown <= total:
            sides[name] += 1
    return sides
