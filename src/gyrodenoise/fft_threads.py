"""Real FFTs along the first axis on the cores this process may use: scipy's pocketfft, which gives numpy's numbers
(the discrepancy fits' rows and their low-passed regressors, a few thousand transforms per selection). OMP_NUM_THREADS
caps the threads, as it does torch's and BLAS's (the test suite's parallel workers set it to 1)."""

from __future__ import annotations

import os

import numpy as np
import scipy.fft


def workers() -> int:
    """OMP_NUM_THREADS when set to a positive integer, else every core (-1)."""
    try:
        n = int(os.environ.get("OMP_NUM_THREADS", ""))
    except ValueError:
        return -1
    return n if n > 0 else -1


def rfft(x: np.ndarray) -> np.ndarray:
    return scipy.fft.rfft(x, axis=0, workers=workers())


def irfft(spectrum: np.ndarray, n: int) -> np.ndarray:
    return scipy.fft.irfft(spectrum, n=n, axis=0, workers=workers())
