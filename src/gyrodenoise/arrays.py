"""Arrays a user passes in, one row per sample: checked once here, so that a wrong shape is named with the shape
expected and the fix for the commonest mistake, a transposed array, instead of failing deep inside (or, square,
silently)."""

from __future__ import annotations

import numpy as np


def as_rows(a: object, name: str, width: int, columns: str = "") -> np.ndarray:
    """`a` as a float64 (N, width) array, or ValueError naming `name`, the shape expected (`columns`: what they hold,
    e.g. " rad/s") and, for a (width, N) array, its transpose."""
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        hint = f" (it looks transposed: pass {name}.T)" if arr.ndim == 2 and arr.shape[0] == width else ""
        raise ValueError(f"{name} has shape {arr.shape}; expected (N, {width}){columns}, one row per sample{hint}")
    return arr
