"""Timestamp checks for a stream of IMU samples fed to the streaming corrector, one call at a time.

The network's dilated convolutions count samples, not seconds: samples out of order, a gap (the samples
either side taken as consecutive) or a stream at another rate than the model's training rate all give a
wrong correction without any error. `correct` checks a whole file for these (`gyrodenoise.data.checks`);
`StreamClock` checks the same things incrementally, before the corrector's state changes.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from gyrodenoise.data.checks import RATE_TOL, SanityWarning
from gyrodenoise.data.readers import IMU_RATE_RANGE_HZ

RATE_WINDOW = 400  # steps (2 s at 200 Hz) averaged before the rate is compared with the model's
# a step longer than this many periods is a gap: halfway between two and three periods, so that two missing samples
# are refused whatever the IMU's rate (at 3.0 they fell either side with a rate 0.3% off); one missing sample passes
STREAM_GAP_FACTOR = 2.5
# a step shorter than this many periods is refused: a stream at twice the model's rate steps exactly half a period
# (0.5 let it through on the boundary), while a jittery driver's early sample (up to 40 % early) still passes
STREAM_FAST_FACTOR = 0.6
UNITS_HINT = "t_ns must be integer nanoseconds (seconds: int(round(t_s * 1e9)))"


class StreamTimeError(ValueError):
    """A timestamp the stream cannot take (out of order, or after a gap); the corrector's state is unchanged."""


class StreamClock:
    """The last timestamp of a stream and its period; `check` refuses what would corrupt the correction.

    rate_hz: the model's training rate (None: the period is learnt from the stream's own steps, so gaps are still
    found but a wrong rate or time unit is not). gaps=False: a model without memory (a calibrated one), for which
    a gap changes nothing.
    """

    def __init__(self, rate_hz: float | None = None, gap_factor: float = STREAM_GAP_FACTOR, gaps: bool = True) -> None:
        if rate_hz is not None and not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz={rate_hz}: give the model's training rate in Hz, or None")
        self.rate_hz = rate_hz
        self.gap_factor = gap_factor if gaps else np.inf
        self.reset()

    def reset(self) -> None:
        self.last_ns: int | None = None
        self._steps_sum, self._steps_n = 0, 0
        self._rate_checked = False

    @property
    def period_ns(self) -> float | None:
        if self.rate_hz:
            return 1e9 / self.rate_hz
        return self._steps_sum / self._steps_n if self._steps_n else None

    def check(self, t_ns: int | np.ndarray | Sequence[int], n: int) -> np.ndarray | int:
        """The n stamps of the next call as int64 ns, or StreamTimeError naming the first bad one."""
        period = self.period_ns
        if n == 1 and isinstance(t_ns, int | np.integer) and self.last_ns is not None:
            step = int(t_ns) - self.last_ns  # one sample: plain ints (~1 us, not ~100 with numpy arrays)
            lo, hi = (1, np.inf) if period is None else (STREAM_FAST_FACTOR * period, self.gap_factor * period)
            if lo <= step <= hi:
                return int(t_ns)
        t = np.atleast_1d(np.asarray(t_ns))
        if t.shape != (n,) or not np.issubdtype(t.dtype, np.integer):
            raise StreamTimeError(
                f"t_ns: expected {n} integer timestamp(s), one per sample, got {t.dtype} of shape {t.shape}; "
                + UNITS_HINT
            )
        t = t.astype(np.int64)
        full = t if self.last_ns is None else np.concatenate([[self.last_ns], t])
        steps = np.diff(full)
        offset = 0 if self.last_ns is None else 1  # steps[k] ends at sample k + 1 - offset of this call

        def where(k: int) -> str:
            return "this sample" if n == 1 else f"sample {k + 1 - offset} of this call"

        if (steps <= 0).any():
            k = int(np.argmax(steps <= 0))
            raise StreamTimeError(
                f"{where(k)}: timestamp {int(full[k + 1])} is not after the previous one ({int(full[k])}); drop "
                f"repeated or late samples before pushing (the state is unchanged); {UNITS_HINT}"
            )
        at = f" at {self.rate_hz:.6g} Hz" if self.rate_hz else ""
        if self.rate_hz and (steps < STREAM_FAST_FACTOR * period).any():
            k = int(np.argmax(steps < STREAM_FAST_FACTOR * period))
            plausible = steps[k] >= 1e9 / IMU_RATE_RANGE_HZ[1]  # a rate an IMU samples at, not a unit
            looks = f"; these steps look like a {1e9 / steps[k]:.4g} Hz stream" if plausible else ""
            raise StreamTimeError(
                f"{where(k)} comes {steps[k] * 1e-6:.4g} ms after the previous one, under {STREAM_FAST_FACTOR:g} of "
                f"the model's period ({period * 1e-6:.3f} ms{at}){looks}: the stream is faster than the model's rate "
                f"(resample it), or its stamps are not ns ({UNITS_HINT}; micro- or milliseconds look like this). The "
                "state is unchanged"
            )
        period = period or (float(np.median(steps)) if steps.size else None)
        if period is not None and (steps > self.gap_factor * period).any():
            k = int(np.argmax(steps > self.gap_factor * period))
            raise StreamTimeError(
                f"{where(k)} comes {steps[k] * 1e-6:.3f} ms after the previous one, more than {self.gap_factor:g} "
                f"periods ({period * 1e-6:.3f} ms{at}): the model would take the samples either side as consecutive. "
                "After a gap, call reset() and push it as the first sample of a new stream (the start-up of one "
                "receptive field follows), or fill the gap first; a stream slower than the model's rate looks the "
                "same: resample it (the state is unchanged)"
            )
        return t

    def commit(self, t: np.ndarray | int) -> None:
        """Record the stamps of a call that went through; compare the rate once enough steps were seen."""
        if isinstance(t, int):  # check's one-sample path
            self._steps_sum += t - self.last_ns
            self._steps_n += 1
            self.last_ns = t
        elif t.size:
            steps = np.diff(t if self.last_ns is None else np.concatenate([[self.last_ns], t]))
            self._steps_sum += int(steps.sum())
            self._steps_n += steps.size
            self.last_ns = int(t[-1])
        if self.rate_hz and not self._rate_checked and self._steps_n >= RATE_WINDOW:
            self._rate_checked = True
            measured = 1e9 * self._steps_n / self._steps_sum
            if abs(measured / self.rate_hz - 1.0) > RATE_TOL:
                warnings.warn(
                    f"the stream runs at {measured:.4g} Hz but the model was trained at {self.rate_hz:.4g} Hz: its "
                    "convolutions span a fixed number of samples, so it sees another time window; resample the "
                    "stream to the model's rate, or train a model at this rate",
                    SanityWarning,
                    stacklevel=4,
                )
