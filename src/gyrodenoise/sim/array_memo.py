"""Results of pure functions of arrays, kept for when the same inputs come again (a bounded LRU memo).

The discrepancy workflow asks for the same low-passed rate, and the same true rate at shifted times, many times over
(the same sequence and corner from several candidates and steps: ~4 and ~3 times on average in the quick-start
notebook). Two ways to key a result:
- by content (`digest` of the inputs' bytes): safe whatever the caller does to its arrays, hashing costs a few per cent
  of recomputing; the results are handed out as copies, so a caller may change its own;
- by identity (`id()` of the inputs, which the entry keeps alive through `keep`, so that no other array takes those
  ids while it is there): free, for inputs that are never changed in place (`discrepancy.time_only_rows`); the results
  are handed out read-only, not copied.
The memo forgets the least recently used results first, beyond `max_bytes` or `max_entries`.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable, Hashable

import numpy as np


def digest(*parts: object) -> bytes:
    """A key for `parts`: arrays by dtype, shape and bytes, anything else by its repr."""
    h = hashlib.blake2b(digest_size=20)
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.data)
        else:
            h.update(repr(p).encode())
        h.update(b"|")
    return h.digest()


class ArrayMemo:
    """An LRU memo of arrays: at most `max_bytes` in all and `max_entries` results (None: no such bound);
    `read_only`: results handed out as the kept arrays themselves, made read-only, instead of copies."""

    def __init__(self, max_bytes: int | None = None, max_entries: int | None = None, read_only: bool = False) -> None:
        self.max_bytes, self.max_entries, self.read_only = max_bytes, max_entries, read_only
        self._kept: OrderedDict[Hashable, tuple[object, np.ndarray]] = OrderedDict()
        self._bytes = 0
        self.hits = self.misses = 0

    def get(self, key: Hashable, compute: Callable[[], np.ndarray], keep: object = None) -> np.ndarray:
        """The array kept for `key`, else `compute()`, kept for next time together with `keep`."""
        entry = self._kept.get(key)
        if entry is not None:
            self.hits += 1
            self._kept.move_to_end(key)
            return entry[1] if self.read_only else entry[1].copy()
        self.misses += 1
        value = compute()
        if self.read_only:
            value.flags.writeable = False
        kept = value if self.read_only else np.array(value)  # a copy of its own: the caller may change `value`
        if self.max_bytes is None or kept.nbytes <= self.max_bytes:
            self._kept[key] = (keep, kept)
            self._bytes += kept.nbytes
            while (self.max_bytes is not None and self._bytes > self.max_bytes) or (
                self.max_entries is not None and len(self._kept) > self.max_entries
            ):
                self._bytes -= self._kept.popitem(last=False)[1][1].nbytes
        return value

    def __len__(self) -> int:
        return len(self._kept)

    def clear(self) -> None:
        self._kept.clear()
        self._bytes = 0
