"""Sanity checks of an IMU recording before a model corrects it: the usual mistakes, caught early.

Each check names the file, the column or line, what looks wrong and what to do. Mistakes that
would feed the network garbage (wrong units, wrong time unit, duplicated or unsorted stamps) raise
`SanityCheckError`; `force=True` turns the unit checks into warnings for the rare recording that
really is like that. Things that degrade the result but may be intended (a rate other than the
model's, gaps) warn with `SanityWarning`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from gyrodenoise.data.gyro_scale import gyro_scale_verdict, gyro_unit_message
from gyrodenoise.data.imu_csv import G0, TIME_UNITS, ImuRecording, time_units_for_period
from gyrodenoise.data.readers import (
    IMU_RATE_RANGE_HZ,
    DataFormatError,
    back_in_time_advice,
    burst_advice,
    burst_rate_hz,
)

GYRO_P99_MAX = 15.0  # rad/s (860 deg/s); hand-held and drone motion stays well below at the 99th percentile
# beyond these no MEMS IMU measures (gyro full scales stop at ~4000 deg/s, accelerometers at a few hundred g):
# such a value is a corrupted sample, and one of them spoils a whole receptive field of outputs
GYRO_ABS_MAX = 100.0  # rad/s (5730 deg/s)
ACC_ABS_MAX = 5000.0  # m/s^2 (~510 g)
SATURATED_RUNS = 2  # an axis at its largest magnitude in this many separate runs looks clipped
# a clipped range spans thousands of the sensor's steps (2**15 on a 16-bit gyro); a quantized gyro at rest or in slow
# motion repeats its largest value, a few steps, in many runs without being clipped
SATURATED_MIN_STEPS = 256
# a step longer than this many median periods is a gap (two or more samples missing): the streaming corrector's
# STREAM_GAP_FACTOR, so that a file and a stream of it are judged alike (3.0 let two missing samples in a row pass)
FILE_GAP_FACTOR = 2.5
RATE_TOL = 0.05  # relative rate difference to the model's training rate that warns
G_TOL_REST, G_TOL_MOVING = 0.10, 0.30  # relative |acc| - g tolerance with / without a rest period


class SanityCheckError(DataFormatError):
    """The recording is not what the model expects; the message says what to do."""


class SanityWarning(UserWarning):
    """The recording is usable but may give a worse correction; the message says why."""


@dataclass
class CheckReport:
    rate_hz: float = float("nan")
    g_measured: float = float("nan")
    rest_fraction: float = 0.0
    warnings: list[str] = field(default_factory=list)
    misfits: list[str] = field(default_factory=list)  # of the warnings, those that say the model does not fit (rate)
    notes: list[str] = field(default_factory=list)  # what was taken as it is, said (single missing samples)

    def warn(self, msg: str) -> None:
        self.warnings.append(msg)
        warnings.warn(msg, SanityWarning, stacklevel=3)


def _where(rec: ImuRecording, k: int) -> str:
    line = int(rec.lines[k])
    return f"{rec.path}:{line}" if line > 0 else f"{rec.path} (sample {k})"


def check_time_order(rec: ImuRecording, drop_duplicates: bool = False, report: CheckReport | None = None):
    """Stamps strictly increasing. Duplicates: error, or keep the first when asked."""
    d = np.diff(rec.t_ns)
    back = np.flatnonzero(d < 0)
    if back.size:
        k = int(back[0]) + 1
        raise SanityCheckError(
            f"{_where(rec, k)}: timestamp ({rec.describe('t')}) goes back in time from line "
            f"{rec.lines[k - 1]} ({back.size} such place{'s' if back.size > 1 else ''}). "
            + (
                back_in_time_advice(rec.t_ns, rec.lines)
                or "Sort the file by time (e.g. `sort -t, -k1,1n`) or check that --columns maps the time column."
            )
        )
    # a line repeating the one before exactly (a logger that wrote a sample twice) is one sample: kept once, said, as
    # the ASL reader of training does (it refused the recording before, while training read the same file)
    same = (d == 0) & np.all(rec.gyro[1:] == rec.gyro[:-1], axis=1) & np.all(rec.acc[1:] == rec.acc[:-1], axis=1)
    if same.any():
        k, n = int(np.argmax(same)) + 1, int(same.sum())
        msg = (
            f"{_where(rec, k)}: {n} line{'s' if n > 1 else ''} repeat{'' if n > 1 else 's'} the line before exactly "
            f"(same timestamp, same values; the first is a copy of line {rec.lines[k - 1]}): each sample is kept once."
        )
        if report is not None:
            report.warn(msg)
        else:
            warnings.warn(msg, SanityWarning, stacklevel=2)
        rec = _subset(rec, np.concatenate([[True], ~same]))
        d = np.diff(rec.t_ns)
    dup = np.flatnonzero(d == 0) + 1
    if dup.size:
        if not drop_duplicates:
            k = int(dup[0])
            raise SanityCheckError(
                f"{_where(rec, k)}: duplicated timestamp {rec.t_ns[k]} ns with other values (same as line "
                f"{rec.lines[k - 1]}; {dup.size} duplicated samples in all). Remove the duplicated lines, or pass "
                "--drop-duplicates to keep the first sample of each stamp."
            )
        keep = np.ones(len(rec), dtype=bool)
        keep[dup] = False
        if report is not None:
            report.warn(f"{rec.path}: dropped {dup.size} samples with duplicated timestamps (first kept).")
        rec = _subset(rec, keep)
    return rec


def check_time_unit(rec: ImuRecording, report: CheckReport) -> None:
    if len(rec) < 2:
        raise SanityCheckError(f"{rec.path}: only {len(rec)} sample; an IMU recording needs many.")
    period_ns = float(np.median(np.diff(rec.t_ns)))
    rate = 1e9 / period_ns
    report.rate_hz = rate
    lo, hi = IMU_RATE_RANGE_HZ
    if lo <= rate <= hi:
        return
    given = TIME_UNITS[rec.units["time"]]
    burst = burst_rate_hz(rec.t_ns)
    if burst is not None and lo <= burst <= hi:  # not a unit: the stamps of reads, not of samples
        raise SanityCheckError(f"{rec.path}: {rec.describe('t')}: {burst_advice(period_ns, burst)}.")
    fits = time_units_for_period(period_ns / given)
    hint = f"pass --time-unit {fits[0]}" if fits else "check --time-unit and the time column (--columns)"
    raise SanityCheckError(
        f"{rec.path}: {rec.describe('t')} read as {rec.units['time']} gives a median sample period of "
        f"{period_ns / given:g} {rec.units['time']}, i.e. {rate:.4g} Hz; an IMU samples at "
        f"{lo:g} Hz - {hi / 1000:g} kHz. The time unit is probably wrong: {hint}."
    )


def check_gaps(rec: ImuRecording, report: CheckReport, factor: float = FILE_GAP_FACTOR, resample: bool = False) -> None:
    """Warn about gaps in the timestamps (not when --resample interpolates over them); note single missing samples
    (a step of about two periods), which are taken as consecutive as the streaming corrector takes them."""
    d = np.diff(rec.t_ns)
    period = float(np.median(d))
    gaps = np.flatnonzero(d > factor * period)
    singles = np.flatnonzero((d > 1.5 * period) & (d <= factor * period))
    if singles.size and not resample:
        report.notes.append(
            f"{_where(rec, int(singles[0]) + 1)}: {singles.size} single missing sample(s) (a step of about two "
            f"periods, the first after line {rec.lines[singles[0]]}), taken as consecutive; --resample interpolates "
            "them"
        )
    if not gaps.size or resample:
        return
    k = int(gaps[np.argmax(d[gaps])])
    missing = float((d[gaps] - period).sum()) * 1e-9
    report.warn(
        f"{_where(rec, k + 1)}: {gaps.size} gap(s) in the timestamps (steps > {factor:g}x the median "
        f"period of {period * 1e-6:.3g} ms); the longest is {d[k] * 1e-9:.3f} s after line {rec.lines[k]}, "
        f"{missing:.3f} s missing in all. The network treats samples as consecutive and the integration "
        "crosses a gap in one step: split the recording at the gaps, or pass --resample to interpolate "
        "onto a uniform grid (only sensible for short gaps)."
    )


def check_gyro_units(rec: ImuRecording, report: CheckReport, force: bool = False) -> None:
    norm = np.linalg.norm(rec.gyro, axis=1)
    p99 = float(np.percentile(norm, 99))
    cols = rec.describe("wx", "wy", "wz")
    if p99 > GYRO_P99_MAX:
        _fail_or_warn(
            report,
            force,
            f"{rec.path}: gyro ({cols}, read as {rec.units['gyro']}) has a 99th-percentile norm of "
            f"{p99:.3g} rad/s ({np.degrees(p99):.0f} deg/s); real motion stays below ~{GYRO_P99_MAX:g} rad/s. "
            + (
                "The file is probably in deg/s: pass --gyro-unit deg/s."
                if rec.units["gyro"] == "rad/s"
                else "Check the gyro unit and that --columns maps the gyro columns."
            ),
        )
    elif rec.units["gyro"] == "rad/s":  # within the range of motion: what its rotations do to gravity says the unit
        verdict = gyro_scale_verdict(rec.acc, rec.gyro, report.rate_hz)
        if verdict.wrong_unit:
            _fail_or_warn(report, force, gyro_unit_message(f"{rec.path}: gyro ({cols}, read as rad/s)", verdict)
                          + " The file is probably in deg/s: pass --gyro-unit deg/s.")  # fmt: skip
    acc_std = float(np.linalg.norm(rec.acc, axis=1).std())
    if p99 < 0.03 and acc_std > 1.0:  # < 1.7 deg/s while the body clearly moves
        report.warn(
            f"{rec.path}: gyro ({cols}) is almost zero (99th percentile {p99:.2g} rad/s) while the "
            f"accelerometer shows motion (|acc| std {acc_std:.2g} m/s^2). Was a rad/s file read with "
            "--gyro-unit deg/s, or are the gyro columns mapped right?"
        )


def check_physical_range(rec: ImuRecording, report: CheckReport, force: bool = False) -> None:
    """No sample beyond what any MEMS IMU measures (a corrupted register read, a unit slip of 1e3 and more)."""
    for what, values, limit, unit in (
        ("gyro", rec.gyro, GYRO_ABS_MAX, "rad/s"),
        ("acc", rec.acc, ACC_ABS_MAX, "m/s^2"),
    ):
        bad = np.flatnonzero(np.abs(values).max(axis=1) > limit)
        if bad.size:
            k = int(bad[0])
            _fail_or_warn(
                report,
                force,
                f"{_where(rec, k)}: {what} sample {values[k].tolist()} {unit} is beyond what any IMU measures "
                f"(|{what}| > {limit:g} {unit}; {bad.size} such samples). A corrupted sample: repair or remove it, "
                "or split the recording there; one such sample spoils ~2.5 s of corrected outputs.",
            )


def _steps(mag: np.ndarray, top: float) -> float:
    """How many of the axis's quantization steps (the smallest gap between its distinct magnitudes) `top` is; inf
    for values that show no step (float data)."""
    gaps = np.diff(np.unique(mag))
    gaps = gaps[gaps > top * 1e-9]  # float rounding of one step is not a step
    return top / gaps.min() if gaps.size else float("inf")


def check_saturation(rec: ImuRecording, report: CheckReport) -> None:
    """Warn when a gyro axis sits at its largest magnitude in separate runs: clipped at the sensor's range."""
    for axis, name in enumerate(("wx", "wy", "wz")):
        mag = np.abs(rec.gyro[:, axis])
        top = float(mag.max())
        at = mag >= top * (1 - 1e-9)
        starts = np.flatnonzero(at & ~np.r_[False, at[:-1]])
        plateau = top > 0 and len(starts) >= SATURATED_RUNS and at.sum() >= 2 * SATURATED_RUNS
        if plateau and _steps(mag, top) >= SATURATED_MIN_STEPS:
            report.warn(
                f"{_where(rec, int(starts[0]))}: gyro {rec.describe(name)} sits at {top:.4g} rad/s "
                f"({np.degrees(top):.0f} deg/s), its largest magnitude, in {int(at.sum())} samples ({len(starts)} "
                "separate runs): the gyro looks saturated (clipped at its range). What was cut cannot be corrected "
                "and the orientation drifts by it: record with a larger gyro range."
            )


@dataclass
class GravityNorm:
    """|acc| where the IMU rests (else its median over the recording), as the accelerometer unit check reads it."""

    g: float  # m/s^2 as read
    rest_fraction: float  # share of half-second windows at rest
    where: str  # for messages: 'at rest (N half-second windows)' or '(median over the whole recording ...)'
    tolerance: float  # relative |g / G0 - 1| accepted (tighter at rest)

    @property
    def ok(self) -> bool:
        return abs(self.g / G0 - 1.0) <= self.tolerance

    def unit_guess(self) -> str | None:
        """The unit the accelerometer is likely in when it was read as m/s^2: 'g', 'mg', 'near zero' or None."""
        r = self.g / G0
        return "near zero" if r < 0.05 else "g" if 0.07 < r < 0.15 else "mg" if 70.0 < r < 130.0 else None


def gravity_norm(acc: np.ndarray, gyro: np.ndarray, rate_hz: float) -> GravityNorm:
    """|acc| at rest: half-second windows whose |acc| varies by under 3 % and whose gyro stays under 0.2 rad/s."""
    acc_norm = np.linalg.norm(acc, axis=1)
    w_norm = np.linalg.norm(gyro, axis=1)
    n = max(5, int(round(0.5 * rate_hz))) if np.isfinite(rate_hz) else 50
    m = len(acc) // n
    rest = np.zeros(0, dtype=bool)
    if m:
        a = acc_norm[: m * n].reshape(m, n)
        w = w_norm[: m * n].reshape(m, n)
        med = np.median(a, axis=1)
        rest = (a.std(axis=1) < 0.03 * np.abs(med) + 1e-9) & (w.mean(axis=1) < 0.2)
    fraction = float(rest.mean()) if rest.size else 0.0
    if rest.any():
        return GravityNorm(
            float(np.median(a[rest])), fraction, f"at rest ({int(rest.sum())} half-second windows)", G_TOL_REST
        )
    return GravityNorm(
        float(np.median(acc_norm)), fraction, "(median over the whole recording: no rest found)", G_TOL_MOVING
    )


def check_acc_at_rest(rec: ImuRecording, report: CheckReport, force: bool = False) -> None:
    """|acc| at rest must be g (the model needs specific force, gravity included, in m/s^2)."""
    norm = gravity_norm(rec.acc, rec.gyro, report.rate_hz)
    report.rest_fraction, report.g_measured = norm.rest_fraction, norm.g
    if norm.ok:
        return
    g, where, r, guess = norm.g, norm.where, norm.g / G0, norm.unit_guess()
    if guess == "near zero":
        todo = (
            "Near zero: these columns may not be the accelerometer, or hold gravity-free linear "
            "acceleration; the model needs the raw specific force, gravity included. Check --columns."
        )
    elif guess == "g":
        todo = "That is about 1: the file is probably in g: pass --acc-unit g."
    elif 7.0 < r < 13.0:
        todo = f"The file is probably in m/s^2 but was read as {rec.units['acc']}: pass --acc-unit m/s^2."
    elif guess == "mg":
        todo = "That is about 1000: the file is probably in milli-g: pass --acc-unit mg."
    else:
        todo = "Check the accelerometer unit (--acc-unit) and that --columns maps the accelerometer axes."
    _fail_or_warn(
        report,
        force,
        f"{rec.path}: accelerometer ({rec.describe('ax', 'ay', 'az')}, read as {rec.units['acc']}) has "
        f"norm {g:.4g} m/s^2 {where}, expected g = {G0} m/s^2. {todo}",
    )


def check_rate(
    rec: ImuRecording, model_rate_hz: float | None, report: CheckReport, resample: bool, rate_matters: bool = True
) -> bool:
    """True when the recording should be resampled to the model's rate. rate_matters=False: a model without memory
    (the calibrated one) corrects each sample alone, so another rate is no reason to warn or resample."""
    if not rate_matters:
        return bool(resample and model_rate_hz)
    if not model_rate_hz:
        report.warn(f"the model does not record its training rate; cannot compare with {report.rate_hz:.4g} Hz.")
        return False
    if resample:  # also at the model's rate: a uniform grid over the recording's gaps
        return True
    if abs(report.rate_hz / model_rate_hz - 1.0) <= RATE_TOL:
        return False
    up = " (upsampling interpolates: it cannot restore the bandwidth the recording lacks, and may not help)"
    report.misfits.append(
        f"{rec.path}: sampled at {report.rate_hz:.4g} Hz but the model was trained at {model_rate_hz:.4g} Hz. "
        "Its dilated convolutions span a fixed number of samples, so at another rate it sees another "
        f"time window and noise level: pass --resample to resample to {model_rate_hz:.4g} Hz"
        + (up if report.rate_hz < model_rate_hz else "")
        + ", or train a model on data at this rate."
    )
    report.warn(report.misfits[-1])
    return False


def run_checks(
    rec: ImuRecording,
    model_rate_hz: float | None,
    resample: bool = False,
    drop_duplicates: bool = False,
    force: bool = False,
    rate_matters: bool = True,
) -> tuple[ImuRecording, CheckReport, bool]:
    """All checks in order. Returns (recording, possibly deduplicated; report; resample needed). rate_matters:
    see `check_rate`."""
    report = CheckReport()
    rec = check_time_order(rec, drop_duplicates, report)
    check_time_unit(rec, report)
    check_gaps(rec, report, resample=resample)
    # the two unit checks are independent: a file in deg/s and in g is told both at once, not one run per problem
    problems = []
    for check in (check_physical_range, check_gyro_units, check_acc_at_rest):
        try:
            check(rec, report, force)
        except SanityCheckError as e:
            problems.append(str(e))
    if len(problems) == 1:
        raise SanityCheckError(problems[0])
    if problems:
        raise SanityCheckError(f"{len(problems)} problems:\n" + "\n".join(f"- {p}" for p in problems))
    check_saturation(rec, report)
    return rec, report, check_rate(rec, model_rate_hz, report, resample, rate_matters)


def _fail_or_warn(report: CheckReport, force: bool, msg: str) -> None:
    if force:
        report.warn(msg + " (continuing: --force)")
    else:
        raise SanityCheckError(msg + " If the data really are like this, pass --force.")


def _subset(rec: ImuRecording, keep: np.ndarray) -> ImuRecording:
    return ImuRecording(
        t_ns=rec.t_ns[keep],
        gyro=rec.gyro[keep],
        acc=rec.acc[keep],
        lines=rec.lines[keep],
        path=rec.path,
        columns=rec.columns,
        units=rec.units,
    )
