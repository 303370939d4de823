"""Timestamp checks for a stream of IMU samples fed to the streaming corrector, one call at a time.

The network's dilated convolutions count samples, not seconds: samples out of order, a gap (the samples
either side taken as consecutive) or a stream at another rate than the model's training rate all give a
wrong correction without any error. `correct` checks a whole file for these (`gyrodenoise.data.checks`);
`StreamClock` checks the same things incrementally, before the corrector's state changes.

With the model's rate known, a sample is judged against the time it is expected at, not against the previous
stamp alone: the stream's time base advances one period per sample taken and follows the stamps with a gain of
1/TIME_BASE_GAIN (integer ns, as the C export's `gd_step_t` computes it). A driver's jitter (a late stamp, then an
on-time one that came "early" after it) then passes, while a stream at twice the model's rate is still refused
every other sample and two missing samples are still a gap. The base's step is the stream's own mean interval once
RATE_TRACK_MIN intervals were taken (within RATE_TOL of the model's period): with the period as its step, a stream a
fraction f fast lagged the base by TIME_BASE_GAIN f periods, and its jitter then reached the early limit (4-5 % of the
samples of a stream 3-4 % fast with +-1.5 ms jitter were refused). A sample about one period late is one missing
sample: the base steps over it, so a second one a few samples later is not taken for a gap. Refusals say which kind
they are (`StreamTimeError.kind`).
"""

from __future__ import annotations

import math
import warnings
from collections import deque
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
# stamps are int64 ns, as the C export's: a larger integer was wrapped by numpy into another stamp
STAMP_MIN_NS, STAMP_MAX_NS = -(2**63), 2**63 - 1
# this many single samples in a row stamped before the last one taken: the clock went back (a restarted sensor) or the
# last stamp taken was wrong, far in the future (taken after a "gap"): without a way out the stream would refuse
# every sample from then on. A reordered or repeated sample or two, or a short burst re-sent by a driver, stay refusals
CLOCK_JUMP_SAMPLES = 20
# the time base moves by 1/8 of each sample's deviation from its expected time (a power of two: the C export's integer
# division is exact, and Python's truncation toward zero below matches C99's)
TIME_BASE_GAIN = 8
# the base's step is the mean interval of the samples taken (their steps' sum over their count, a sample about a
# period late counting two: the one missing and itself) once this many intervals were taken; a mean, not a loop on the
# deviations: samples refused as early would leave out the deviations of one sign and drive a loop off
RATE_TRACK_MIN = 32
# a step-over (one missing sample) needs the step since the last sample taken to span about two periods too (a late
# sample after a lag that built up is a slower stream, not a missing sample), and at most one in MISSED_SHARE samples
# taken stepped over besides the stream's first: more are a stream at half the rate or a lossy link, refused as a gap
MISSED_SHARE = 10


RESTARTS_IN_A_ROW = 5  # this many restarts (gaps, clock jumps) within RATE_WINDOW samples taken: a warning, once


def rate_sum_bounds(rate_hz: float) -> tuple[int, int]:
    """The sums of RATE_WINDOW steps (ns) whose mean rate is within RATE_TOL of `rate_hz`: [lo, hi]. A stream's n
    intervals summing to S pass when lo n <= S RATE_WINDOW <= hi n (integers: the C export makes the same test)."""

    def warns_fast(s: int) -> bool:
        return 1e9 * RATE_WINDOW / s / rate_hz - 1.0 > RATE_TOL

    def warns_slow(s: int) -> bool:
        return 1e9 * RATE_WINDOW / s / rate_hz - 1.0 < -RATE_TOL

    return _first(lambda s: not warns_fast(s)), _first(warns_slow) - 1


def _first(pred, lo: int = 1, hi: int = 2**63 - 1) -> int:
    """The smallest integer in [lo, hi] where the monotone `pred` holds (bisection)."""
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if pred(mid) else (mid + 1, hi)
    return lo


def _exact_diff(stamps: np.ndarray) -> np.ndarray:
    """np.diff of int64 stamps, as Python ints where a step could leave int64 (stamps beyond +-2**62: INT64_MIN after
    INT64_MAX wrapped to a step of 1 and was taken)."""
    if stamps.size and ((stamps > 2**62) | (stamps < -(2**62))).any():
        return np.diff(stamps.astype(object))
    return np.diff(stamps)


class StreamTimeError(ValueError):
    """A timestamp the stream cannot take; the corrector's state is unchanged. `kind`: "order" (not after the last
    sample taken: drop it), "early" (before its expected time by more than the tolerance: drop it, or the stream is
    faster than the model's rate), "gap" (samples are missing: reset() and push it as the first of a new stream, or
    fill the gap first), "clock" (CLOCK_JUMP_SAMPLES samples in a row before the last one taken: the clock went back;
    reset() and push it as the first of a new stream), "stamps" (not integer ns, or not one per sample). `index`: the
    sample of the call, counting from 0."""

    def __init__(self, message: str, kind: str = "stamps", index: int = 0) -> None:
        super().__init__(message)
        self.kind, self.index = kind, index


def _toward_zero(dev: int, div: int) -> int:
    """dev / div truncated toward zero, as C99's integer division (Python's // floors)."""
    q = abs(dev) // div
    return q if dev >= 0 else -q


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
        self._taken_total = 0  # samples taken over the clock's life, across resets
        self._restarts: deque[int] = deque(maxlen=RESTARTS_IN_A_ROW)  # _taken_total at the last restarts
        self._restarts_warned = False
        # the time base (rate known, gaps checked): integer period and the deviations a sample may have from its
        # expected time, the same thresholds as a step from a sample taken on time (`c_clock.step_limits`)
        self._base: tuple[int, int, int] | None = None
        if rate_hz is not None and gaps:
            period = 1e9 / rate_hz
            whole = round(period)
            self._base = (
                whole,
                math.ceil(STREAM_FAST_FACTOR * period) - whole,
                math.floor(gap_factor * period) - whole,
            )
            self._rate_bounds = rate_sum_bounds(rate_hz)
            self._step_max_off = math.floor(RATE_TOL * whole)  # the base's step within RATE_TOL of the period
        self.reset()

    def reset(self) -> None:
        self.late_in_a_row = 0  # single samples refused in a row as not after the last one taken
        self.last_ns: int | None = None
        self.base_ns: int | None = None  # where the time base puts the last sample taken
        self.track: tuple[int, int] = (0, 0)  # the taken samples' steps: sum (ns) and intervals (`base_step`)
        self._steps_sum, self._steps_n = 0, 0  # the steps taken
        self._early_n = 0  # samples refused as early: they came, between two taken ones (the rate's average)
        self._early_since = False  # one was refused since the last sample taken (its step is left out of the track)
        self.missed = 0  # samples stepped over as missing in this stream
        self._rate_checked = False

    def base_step(self, track: tuple[int, int]) -> int:
        """The time base's step (ns): the period, or the taken samples' mean interval once RATE_TRACK_MIN were taken,
        within RATE_TOL of the period (integer floor division, as the C export's unsigned one)."""
        whole, (total, n) = self._base[0], track
        if n < RATE_TRACK_MIN:
            return whole
        return whole + max(-self._step_max_off, min(self._step_max_off, total // n - whole))

    def _step_over(self, step: int, dev: int, raw: int, n_steps: int, n_missed: int) -> bool | None:
        """Whether a sample `dev` ns after its expected time (taken: within the tolerance), `raw` ns after the last one
        taken, follows one missing sample (True: the base steps over it), is late (False), or follows one missing
        sample too many (None: a gap). `n_steps`, `n_missed`: the stream's steps taken and step-overs before it."""
        lo = self._base[1]
        if dev < step + lo or raw < 2 * step + lo:
            return False
        return True if MISSED_SHARE * n_missed < n_steps + MISSED_SHARE else None

    @staticmethod
    def _advance(
        base: int, step: int, track: tuple[int, int], last: int, t: int, after_early: bool, over: bool
    ) -> tuple[int, tuple[int, int]]:
        """(time base, track) after taking a sample stamped `t` (checked: within the tolerance, and `over` from
        `_step_over`) after the one stamped `last`, the base's step being `step` (`base_step(track)`): the base steps
        over one missing sample where `over`. A step with a sample refused as early inside is left out of the track:
        whether that sample was the stream's (jitter) or one too many (a faster stream) is not known, and either guess
        would drive the track off."""
        expected = base + step + (step if over else 0)
        if not after_early:
            track = (track[0] + t - last, track[1] + 1 + over)
        return expected + _toward_zero(t - expected, TIME_BASE_GAIN), track

    @property
    def period_ns(self) -> float | None:
        if self.rate_hz:
            return 1e9 / self.rate_hz
        return self._steps_sum / self._steps_n if self._steps_n else None

    def check(self, t_ns: int | np.ndarray | Sequence[int], n: int) -> np.ndarray | int:
        """The n stamps of the next call as int64 ns, or StreamTimeError naming the first bad one."""
        period = self.period_ns
        one = n == 1 and isinstance(t_ns, int | np.integer) and STAMP_MIN_NS <= t_ns <= STAMP_MAX_NS
        if one and self.last_ns is not None:
            t1 = int(t_ns)  # one sample: plain ints (~1 us, not ~100 with numpy arrays)
            if self._base is not None:
                _, lo, hi = self._base
                step = self.base_step(self.track)
                dev, raw = t1 - self.base_ns - step, t1 - self.last_ns
                if (
                    raw > 0
                    and lo <= dev <= hi
                    and self._step_over(step, dev, raw, self._steps_n, self.missed) is not None
                ):
                    return t1
            else:
                step = t1 - self.last_ns
                lo, hi = (1, np.inf) if period is None else (STREAM_FAST_FACTOR * period, self.gap_factor * period)
                if lo <= step <= hi:
                    return t1
        t = np.atleast_1d(np.asarray(t_ns))
        if t.shape != (n,) or not np.issubdtype(t.dtype, np.integer):
            raise StreamTimeError(
                f"t_ns: expected {n} integer timestamp(s), one per sample, got {t.dtype} of shape {t.shape}; "
                + UNITS_HINT
            )
        if t.dtype == np.uint64 and (beyond := t > STAMP_MAX_NS).any():
            k = int(np.argmax(beyond))
            raise StreamTimeError(
                f"{'this sample' if n == 1 else f'sample {k + 1} of this call'}: timestamp {int(t[k])} ns is beyond "
                f"int64 nanoseconds (the year 2262); {UNITS_HINT}",
                "stamps",
                k,
            )
        t = t.astype(np.int64)
        full = t if self.last_ns is None else np.concatenate([[self.last_ns], t]).astype(np.int64)
        steps = _exact_diff(full)
        offset = 0 if self.last_ns is None else 1  # steps[k] ends at sample k + 1 - offset of this call

        def where(k: int) -> str:
            return "this sample" if n == 1 else f"sample {k + 2 - offset} of this call (counting from 1)"

        at = f" at {self.rate_hz:.6g} Hz" if self.rate_hz else ""
        if self._base is not None:  # sample by sample: the first refused one is named, whatever its kind
            self._check_against_time_base(t, full, steps, n, where, at)
            return t
        bad = {"order": steps <= 0}
        if self.rate_hz:
            bad["early"] = steps < STREAM_FAST_FACTOR * period
        period = period or (float(np.median(steps)) if steps.size else None)
        if period is not None:
            bad["gap"] = steps > self.gap_factor * period
        firsts = {kind: int(np.argmax(b)) for kind, b in bad.items() if b.any()}
        if firsts:
            kind = min(firsts, key=firsts.get)
            k = firsts[kind]
            self._refuse(kind, k, full, steps, n, where, at, period)
        return t

    def _refuse(
        self, kind: str, k: int, full: np.ndarray, steps: np.ndarray, n: int, where, at, period, dev=None, missed=None
    ):
        """Raise the StreamTimeError of the step k (ending at sample k + 1 of `full`, the last stamp taken and this
        call's), counting what the stream's later decisions need: refusals as late in a row (the clock's jump),
        early ones (the rate's average), gaps (restarts in a row)."""
        index = k + 1 - (len(full) - n)
        if kind == "order":
            self.late_in_a_row += 1 if n == 1 else 0
            if n == 1 and self.late_in_a_row >= CLOCK_JUMP_SAMPLES:
                self._restarted()
                raise StreamTimeError(
                    f"{self.late_in_a_row} samples in a row are stamped before the last one taken ({int(full[0])}): "
                    "the stream's clock went back (a restarted sensor or driver), or that stamp was wrong (far in the "
                    "future). Call reset() and push this sample as the first of a new stream (the state is unchanged)",
                    "clock",
                )
            raise StreamTimeError(
                f"{where(k)}: timestamp {int(full[k + 1])} is not after the previous one ({int(full[k])}); drop "
                f"repeated or late samples before pushing (the state is unchanged); {UNITS_HINT}",
                "order",
                index,
            )
        if kind == "early":
            self._early_n += 1  # a sample that came: the rate's average counts it
            self._early_since = True
            plausible = steps[k] >= 1e9 / IMU_RATE_RANGE_HZ[1]  # a rate an IMU samples at, not a unit
            looks = f"; these steps look like a {1e9 / steps[k]:.4g} Hz stream" if plausible else ""
            raise StreamTimeError(_early_message(where(k), steps[k], period, at, looks, dev), "early", index)
        self._restarted()
        if missed is not None:  # about a period late once too often
            raise StreamTimeError(_missed_message(where(k), *missed, period, at), "gap", index)
        raise StreamTimeError(_gap_message(where(k), steps[k], self.gap_factor, period, at), "gap", index)

    def _restarted(self) -> None:
        """A refusal that makes the caller restart the stream: warn once when they come every few samples (a stream
        much slower than the model's, or stamps that are not the samples' times): its outputs stay at start-up quality
        and its rate is never compared, since no stream lasts RATE_WINDOW steps."""
        self._restarts.append(self._taken_total)
        if len(self._restarts) == RESTARTS_IN_A_ROW and not self._restarts_warned:
            if self._taken_total - self._restarts[0] < RATE_WINDOW:
                self._restarts_warned = True
                warnings.warn(
                    f"the stream restarted {RESTARTS_IN_A_ROW} times within {self._taken_total - self._restarts[0] + 1}"
                    " samples: its stamps leave gaps every few samples, so the model keeps starting up (its outputs "
                    "stay less accurate). A stream much slower than the model's rate, or stamps taken when a buffer "
                    "was read rather than when each sample was measured, look like this: resample, or stamp each "
                    "sample",
                    SanityWarning,
                    stacklevel=5,
                )

    def _check_against_time_base(self, t: np.ndarray, full: np.ndarray, steps: np.ndarray, n: int, where, at) -> None:
        """Each sample against its expected time on the stream's time base, in order (the base moves with each)."""
        _, lo, hi = self._base
        base, track, last = self.base_ns, self.track, self.last_ns
        n_steps, n_missed = self._steps_n, self.missed
        for i, ti in enumerate(t.tolist()):
            k = i - 1 + (len(full) - n)  # the step that ends at this sample
            if last is not None and ti <= last:
                self._refuse("order", k, full, steps, n, where, at, self.period_ns)
            if base is None:  # the stream's first sample
                base = last = ti
                continue
            step = self.base_step(track)
            dev = ti - base - step
            if dev < lo:
                self._refuse("early", k, full, steps, n, where, at, self.period_ns, dev)
            if dev > hi:
                self._refuse("gap", k, full, steps, n, where, at, self.period_ns)
            over = self._step_over(step, dev, ti - last, n_steps, n_missed)
            if over is None:
                self._refuse("gap", k, full, steps, n, where, at, self.period_ns, missed=(n_missed + 1, n_steps + 1))
            (base, track), last = self._advance(base, step, track, last, ti, self._early_since and i == 0, over), ti
            n_steps, n_missed = n_steps + 1, n_missed + over

    def commit(self, t: np.ndarray | int) -> None:
        """Record the stamps of a call that went through; compare the rate once enough steps were seen."""
        self.late_in_a_row = 0
        stamps = [t] if isinstance(t, int) else t.tolist()
        if self._base is not None:
            last, after_early, n_steps = self.last_ns, self._early_since, self._steps_n
            for ti in stamps:
                if self.base_ns is None:  # the stream's first sample
                    self.base_ns = ti
                else:
                    step = self.base_step(self.track)
                    over = bool(self._step_over(step, ti - self.base_ns - step, ti - last, n_steps, self.missed))
                    moved = self._advance(self.base_ns, step, self.track, last, ti, after_early, over)
                    self.base_ns, self.track = moved
                    self.missed, n_steps = self.missed + over, n_steps + 1
                last, after_early = ti, False
        if stamps:  # an empty call takes nothing: a sample refused as early before it still is
            self._early_since = False
        if isinstance(t, int):  # check's one-sample path: plain ints
            self._steps_sum += t - self.last_ns
            self._steps_n += 1
            self._taken_total += 1
            self.last_ns = t
        elif t.size:
            steps = _exact_diff(t if self.last_ns is None else np.concatenate([[self.last_ns], t]).astype(np.int64))
            self._steps_sum += int(steps.sum())
            self._steps_n += int(steps.size)
            self._taken_total += int(t.size)
            self.last_ns = int(t[-1])
        self._compare_rate()

    def _compare_rate(self) -> None:
        """Once per stream, when its steps taken and its samples refused as early (they came, between two taken
        ones) reach RATE_WINDOW: the mean interval against the model's period, as integers (`rate_sum_bounds`: the
        C export's test, boundaries included)."""
        if self._base is None or self._rate_checked or self._steps_n + self._early_n < RATE_WINDOW:
            return
        self._rate_checked = True
        intervals = self._steps_n + self._early_n
        lo, hi = self._rate_bounds
        if lo * intervals <= self._steps_sum * RATE_WINDOW <= hi * intervals:
            return
        measured = 1e9 * intervals / self._steps_sum
        warnings.warn(
            f"the stream runs at {measured:.4g} Hz but the model was trained at {self.rate_hz:.4g} Hz: its "
            "convolutions span a fixed number of samples, so it sees another time window; resample the "
            "stream to the model's rate, or train a model at this rate",
            SanityWarning,
            stacklevel=4,
        )


def _early_message(where: str, step: int, period: float, at: str, looks: str, dev: int | None = None) -> str:
    expected = "" if dev is None else f", {-dev * 1e-6:.4g} ms before its expected time"
    return (
        f"{where} comes {step * 1e-6:.4g} ms after the previous one{expected}, under {STREAM_FAST_FACTOR:g} of the "
        f"model's period ({period * 1e-6:.3f} ms{at}){looks}: the stream is faster than the model's rate (resample "
        f"it), or its stamps are not ns ({UNITS_HINT}; micro- or milliseconds look like this). The state is unchanged"
    )


def _missed_message(where: str, missed: int, taken: int, period: float, at: str) -> str:
    return (
        f"{where} comes about one period ({period * 1e-6:.3f} ms{at}) after its expected time: a missing sample, "
        f"{missed} in {taken} samples of this stream, more than one in {MISSED_SHARE}: a stream slower than the "
        "model's rate (resample it), or a link that loses samples (fill them first). Call reset() and push it as the "
        "first sample of a new stream (the state is unchanged)"
    )


def _gap_message(where: str, step: int, gap_factor: float, period: float, at: str) -> str:
    return (
        f"{where} comes {step * 1e-6:.3f} ms after the previous one, more than {gap_factor:g} periods "
        f"({period * 1e-6:.3f} ms{at}): samples are missing, and the model would take the samples either side as "
        "consecutive. After a gap, call reset() and push it as the first sample of a new "
        "stream (the start-up of one receptive field follows), or fill the gap first; a stream slower than the "
        "model's rate looks the same: resample it (the state is unchanged)"
    )
