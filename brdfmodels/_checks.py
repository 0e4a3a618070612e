"""Input checks shared by the BRDF library: one clear ValueError per bad argument.

Every message names the argument, the offending value and what was expected, because a
safety officer reading a traceback-free one-line error must be able to fix the input.
"""

from __future__ import annotations

import math
from numbers import Real

import numpy as np

# Length tolerance for "unit" direction vectors. Directions are normalised on entry, so
# this only rejects vectors that are clearly not directions (zero, nan, inf).
_MIN_NORM = 1e-12


def _short(value) -> str:
    """Return a compact repr of ``value`` for an error message."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def finite_scalar(name: str, value, *, minimum=None, maximum=None, strict_min=False) -> float:
    """Return ``value`` as a float after checking it is a finite real in range.

    Raises
    ------
    ValueError
        Naming ``name``, the value and the expected range.
    """
    if isinstance(value, bool) or not isinstance(value, (Real, np.floating, np.integer)):
        raise ValueError(f"{name}={_short(value)}: expected a real number")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name}={v!r}: expected a finite number")
    if minimum is not None:
        if strict_min and not v > minimum:
            raise ValueError(f"{name}={v!r}: expected a number > {minimum}")
        if not strict_min and not v >= minimum:
            raise ValueError(f"{name}={v!r}: expected a number >= {minimum}")
    if maximum is not None and not v <= maximum:
        raise ValueError(f"{name}={v!r}: expected a number <= {maximum}")
    return v


def finite_array(name: str, value, *, ndim=None, minimum=None, dtype=float) -> np.ndarray:
    """Return ``value`` as a float array after checking it is finite (and >= minimum)."""
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={_short(value)}: expected an array of real numbers") from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name}: expected a {ndim}-d array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].ravel()[0]
        raise ValueError(f"{name} contains {float(bad)!r}: expected finite numbers")
    if minimum is not None and arr.size and arr.min() < minimum:
        raise ValueError(f"{name} contains {float(arr.min())!r}: expected numbers >= {minimum}")
    return arr


def directions(name: str, value) -> np.ndarray:
    """Return ``value`` as a float64 array of unit vectors, shape (..., 3).

    Vectors are normalised; a zero-length, nan or infinite vector, or a last axis that is
    not 3 long, raises ValueError naming ``name``.
    """
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={_short(value)}: expected an array of 3-vectors, shape (..., 3)") from None
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3) (unit direction vectors), got shape {v.shape}")
    norm = np.sqrt(np.einsum("...i,...i->...", v, v))
    bad = ~np.isfinite(norm) | (norm < _MIN_NORM)
    if np.any(bad):
        idx = np.argwhere(np.atleast_1d(bad))[0]
        example = v.reshape(-1, 3)[int(np.ravel_multi_index(tuple(idx), np.atleast_1d(bad).shape))] if v.ndim > 1 else v
        raise ValueError(
            f"{name} has a zero-length or non-finite vector {example.tolist()!r}: expected unit direction vectors"
        )
    return v / norm[..., None]
