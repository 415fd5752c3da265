"""Hostile values for the fuzz suite: what a careless or malicious caller may
pass where an array, a number, a string, a path or a callback is expected.

Every function takes a numpy Generator and returns one value; none of them
touches lmrefine. Large allocations are views (broadcast_to), never real.
"""

import numpy as np

DTYPES = (np.float16, np.float32, np.float64, np.int8, np.int32, np.int64, np.uint8, np.uint32, np.bool_,
          np.complex64, object, "U3", ">f4", ">i4")

NUMBERS = (0, -1, 1, 2, 3, 7, 2**31, 2**31 - 1, 2**32 + 16, 2**63, -2**63, 10**6, 46341, 10**30, 1e308,
           float("nan"), float("inf"), -float("inf"), -0.0, 1e-45, 0.5, 16.5, -3.25, True, False,
           np.int64(16), np.uint8(255), np.float32("nan"), np.float64(1e300), complex(1, 1))

JUNK = (None, "16", "", "nan", b"16", (), [], {}, (16.5, 16), (0, 0), (16, 0), (1,), (16, 16, 16), [16, 16],
        (-16, 16), (2**31, 2**31), (float("nan"), 16), object(), slice(1), np.array([]), np.zeros((2, 2)))

STRINGS = ("", "nonsense", "D4", "d4\x00", "haar" * 200, "periodic\x00x", "\udcff", "é", " d4", "d4 ")


def number(rng):
    return NUMBERS[rng.integers(len(NUMBERS))]


def junk(rng):
    return JUNK[rng.integers(len(JUNK))]


def scalar(rng):
    """Any hostile scalar-ish value."""
    return number(rng) if rng.random() < 0.6 else junk(rng)


def string(rng):
    r = rng.random()
    if r < 0.7:
        return STRINGS[rng.integers(len(STRINGS))]
    return scalar(rng)


def values_like(array, rng):
    """A copy of `array` with some entries replaced by NaN, Inf, huge, tiny or negative values."""
    out = np.array(array, copy=True)
    if out.size == 0:
        return out
    flat = out.reshape(-1)
    count = int(rng.integers(1, min(flat.size, 8) + 1))
    where = rng.integers(flat.size, size=count)
    if out.dtype.kind == "f":
        choices = np.array([np.nan, np.inf, -np.inf, 1e30, -1e30, 1e-45, -0.0, 3e38, -1.0, 2.0, 1e9, 1e10],
                           dtype=np.float64)
    elif out.dtype.kind in "iu":
        info = np.iinfo(out.dtype)
        choices = np.array([info.min, info.max, -1, -2, 0, 10**6], dtype=np.int64).clip(info.min, info.max)
    else:
        return out
    flat[where] = choices[rng.integers(len(choices), size=count)].astype(out.dtype)
    return out


def reshape_like(array, rng):
    """`array` with a wrong shape: an axis added, dropped, emptied, transposed or flattened."""
    a = np.asarray(array)
    kind = rng.integers(7)
    if kind == 0:
        return a[..., None]
    if kind == 1 and a.ndim:
        return a.reshape(-1)
    if kind == 2 and a.ndim:
        return a[:0]
    if kind == 3 and a.ndim >= 2:
        return a.T
    if kind == 4 and a.ndim >= 2:
        return a[:, :0]
    if kind == 5 and a.ndim and len(a):
        return a[0]
    return np.zeros((0,) * int(rng.integers(0, 4)), a.dtype)


def layout_of(array, rng):
    """`array` with the same values but a hostile memory layout."""
    a = np.asarray(array)
    kind = rng.integers(6)
    if kind == 0:
        return np.asfortranarray(a)
    if kind == 1 and a.ndim:
        doubled = np.repeat(a, 2, axis=0)
        return doubled[::2]  # strided view
    if kind == 2:
        frozen = a.copy()
        frozen.setflags(write=False)
        return frozen
    if kind == 3 and a.dtype.kind in "fiu":
        return a.astype(a.dtype.newbyteorder()).byteswap().view(a.dtype.newbyteorder())
    if kind == 4:
        return a.tolist()
    return np.broadcast_to(a.reshape(-1)[:1] if a.size else np.zeros(1, a.dtype), a.shape)


def huge_view(array, rng):
    """A zero-stride view of an enormous shape of `array`'s dimensionality."""
    a = np.asarray(array)
    side = int((1 << 20, 1 << 16, 3000)[rng.integers(3)])  # refused by the memory check, or quick
    shape = tuple(side if i < 2 else a.shape[i] for i in range(max(a.ndim, 1)))
    return np.broadcast_to(np.zeros((), a.dtype if a.dtype != object else np.float32), shape)


def array_like(array, rng):
    """One hostile variant of a valid `array`."""
    r = rng.random()
    if r < 0.3:
        return values_like(array, rng)
    if r < 0.45:
        dtype = DTYPES[rng.integers(len(DTYPES))]
        try:
            return np.asarray(array).astype(dtype)
        except (TypeError, ValueError):
            return np.asarray(array)
    if r < 0.65:
        return reshape_like(array, rng)
    if r < 0.8:
        return layout_of(array, rng)
    if r < 0.85:
        return huge_view(array, rng)
    return scalar(rng)


class CallbackError(Exception):
    """Raised by a hostile progress callback: it must come out of the call unchanged."""


class _BadBool:
    def __bool__(self):
        raise CallbackError("__bool__ of the progress callback's answer")


def progress(rng):
    """A progress callback: well-behaved, cancelling (in several spellings), raising, or not callable."""
    calls = [0]
    stop_at = int(rng.integers(0, 6))
    kind = int(rng.integers(10))

    def callback(fraction, stage=""):
        calls[0] += 1
        if calls[0] <= stop_at and fraction < 1.0:
            return True
        if kind == 0:
            return False
        if kind == 1:
            return np.False_
        if kind == 2:
            return 0
        if kind == 3:
            raise CallbackError(f"progress raised at {fraction}")
        if kind == 4:
            return _BadBool()
        if kind == 5:
            return ""
        return None if kind == 6 else True

    if kind == 8:
        return (None, 5, "stop", lambda: True, lambda a, b, c: True)[rng.integers(5)]
    return callback
