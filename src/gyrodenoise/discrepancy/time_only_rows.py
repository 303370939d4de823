"""Fit rows of the columns that depend on the sample times alone (the bias, the random walk's hats), kept across
designs. A corner search builds one design per corner over the same samples (`rank`, `spectral.search_log_corner`);
turning these columns into Fourier rows again for each one was most of its time (`design.fit_rows`), while only the
columns that follow the motion change with the corner."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gyrodenoise.sim.array_memo import ArrayMemo
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import Effect

MAX_ENTRIES = 32  # a selection over a few sequences needs a handful; each entry is one effect's rows of one sequence

_rows = ArrayMemo(max_entries=MAX_ENTRIES, read_only=True)  # keyed by the identity of the arrays the rows are of


def rows_key(effect: Effect, fc: FitContext, sigma: np.ndarray, width: int) -> tuple[tuple, tuple] | None:
    """The key of `effect`'s fit rows on sequence `fc` (None: its columns follow the motion), and the arrays whose
    identity the key holds: the sample times, the row mask and the row weights (`design.fit_rows` reads them)."""
    own = effect.time_only_key()
    if own is None:
        return None
    mask, weights = fc.extra.get("row_mask"), fc.extra.get("row_weights")
    key = (type(effect).__name__, own, width, id(fc.t), len(fc.t), fc.rate_hz, id(mask), fc.extra.get("band_hz"),
           id(weights), sigma.tobytes())  # fmt: skip
    return key, (fc.t, mask, weights)


def cached_rows(key: tuple, keep: tuple, compute: Callable[[], np.ndarray]) -> np.ndarray:
    """`compute()`, or what it gave for the same key (read-only). The entry keeps the arrays of `keep` alive, so no
    other array can take their ids while it is there."""
    return _rows.get(key, compute, keep)
