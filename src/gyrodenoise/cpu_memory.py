"""Keep freed CPU memory in the training process instead of handing it back to the OS.

A CPU training step of the EuRoC network allocates and frees dozens of ~30 MB activation tensors.
By default glibc serves such blocks with mmap (or trims the heap top) and returns them to the OS
when freed, so the next step page-faults every page back in, zero-filled by the kernel: 43-60k page
faults per step, 9-23% of the step's time on the 2-core VM (benchmarks/results/cpu_step_profile.md).
`mallopt` makes malloc serve them from its heap and keep that heap: the process holds its peak
(~1.2 GB for the default EuRoC run, steady over the run) until it exits.
"""

from __future__ import annotations

import ctypes
import sys

# glibc's <malloc.h> parameter numbers
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_MAX = -1, -2, -4
TOP_PAD_BYTES = 64 << 20  # grow the heap in 64 MB steps: fewer brk calls


def retain_freed_memory() -> bool:
    """Tell glibc's malloc to keep freed memory (no mmap blocks, no heap trimming).

    True when applied; False where malloc is not glibc's (macOS, Windows, musl): nothing changes.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return all(
        mallopt(param, value) == 1
        for param, value in ((M_MMAP_MAX, 0), (M_TRIM_THRESHOLD, 2**31 - 1), (M_TOP_PAD, TOP_PAD_BYTES))
    )
