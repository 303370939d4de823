"""Does a sequence's IMU agree with its ground truth? Checks of training and evaluation data.

The corrector checks a recording without ground truth (`checks.py`: units, rate, gaps from the IMU alone).
With ground truth the checks can be sharper: the rate implied by the truth's orientation must match the
gyro in size (a gyro in deg/s is ~57 times larger) and in time (a truth on another clock, or shifted, peaks
the cross-correlation of the two rate magnitudes away from zero lag). On EuRoC's 11 flights and TUM-VI's
rooms 1, 3, 5 the gyro/truth rate ratio (both over 50 ms) is 0.98-1.06 and the best lag 0.
The rate vectors must also point the same way: the rotation that best maps the truth's body rate onto the
gyro is 0.05-3.1 deg on those 14 recordings, and ~117 deg for a truth whose quaternion is stored x, y, z, w
but read w, x, y, z (whose rate magnitudes, the checks above, stay plausible). A gyro axis flipped in sign
(or two swapped) is a mirror no rotation undoes: the best orthogonal map between the two is a reflection, on all
14 recordings with any one axis flipped, and on none as they are.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.signal import correlate
from scipy.spatial.transform import Rotation

from gyrodenoise.data.checks import gravity_norm
from gyrodenoise.data.imu_csv import G0
from gyrodenoise.data.readers import GAP_FACTOR, DataFormatError  # GAP_FACTOR: training's gap
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.paths import portable_path

DEG_PER_RAD = 180.0 / np.pi
RATIO_RANGE = (0.5, 2.0)  # gyro / truth rate magnitude outside it: a scale or unit problem
MAX_CROPPED_SHARE = 0.10  # IMU samples outside the truth's span, as a share of the file
AXES_MAX_DEG = 10.0  # gyro axes this far from the truth's body axes: quaternion order, frame or convention
MAX_LAG_S = 0.05  # a best lag beyond it: the truth is not on the IMU's clock
MIN_LAG_CORR = 0.5  # ... when the correlation of the rate magnitudes peaks there at least this high
SEARCH_S = 60.0  # lags searched either way
MOVING_RAD_S = 0.2  # samples whose truth rate exceeds it compare the magnitudes
RATE_WINDOW_S = 0.05  # truth and gyro rates compared over this span
SINGLE_AXIS_RATIO = 0.05  # the truth's rates span one axis when their 2nd singular value is below this x the 1st
# the handedness of the gyro-truth map is read only when the motion spans all three axes: the 3rd singular value of
# the cross-covariance at least this x the 1st (EuRoC and TUM-VI: 0.10-0.40; planar motion leaves it to noise)
MIRROR_MIN_RATIO = 0.05


class GyroUnitError(DataFormatError):
    """The gyro is ~57 times the ground truth's rate about the same axes: deg/s read as rad/s."""

    def __init__(self, message: str, ratio: float) -> None:
        super().__init__(message)
        self.ratio = ratio


class AccUnitError(DataFormatError):
    """The accelerometer's norm at rest is ~1 or ~1000, not 9.81: g or milli-g read as m/s^2, inputs 9.8 or 1000 times
    off those the models learn from."""


class DataConsistencyWarning(UserWarning):
    """The IMU and the ground truth of a sequence disagree in a way that spoils training or scores."""


@dataclass
class Consistency:
    gaps: int  # IMU steps > GAP_FACTOR x the median period
    longest_step_s: float
    rate_ratio: float  # median |gyro| / median |truth rate| over moving samples (nan: too little motion)
    best_lag_s: float  # lag of the gyro behind the truth that best aligns their rate magnitudes
    corr_at_best: float
    corr_at_zero: float
    # the rotation that best maps the truth's body rate onto the gyro (nan: too little motion)
    axes_angle_deg: float = np.nan
    # the best linear map of the truth's rate onto the gyro is a mirror, not a rotation: a flipped axis, or a
    # left-handed frame (a rotation cannot undo it, so one flipped axis with little motion about it can look
    # only a few degrees off: TUM-VI room 1 with its y axis flipped, 7.8 deg)
    mirrored: bool = False
    # that rotation (gyro ~ axes_fit . truth rate; None: too little motion, or motion about one axis only)
    axes_fit: Rotation | None = None


@contextlib.contextmanager
def noting_data_warnings() -> Iterator[list[str]]:
    """Collect the DataConsistencyWarning messages raised inside (each once) into the list it yields once the block
    ends, so that a command's outputs (evaluate's table and results.json, the discrepancy report) carry them, not
    only the console. Every one is recorded, even one already shown earlier in the process (a notebook's rerun).
    Other warnings pass as usual."""
    found: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataConsistencyWarning)
        yield found
    for w in caught:
        if issubclass(w.category, DataConsistencyWarning):
            found.append(str(w.message))
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    found[:] = dict.fromkeys(found)


def measure(seq: Sequence) -> Consistency:
    dt = np.diff(seq.t)
    period = float(np.median(dt))
    # rates over RATE_WINDOW_S, not one IMU step: a raw tracker's orientation noise, differentiated over 5 ms,
    # would dominate its rate (test-world mocap: gyro/truth ratios of 0.27-0.49 that way)
    k = max(1, int(round(RATE_WINDOW_S / period)))
    R = Rotation.from_matrix(seq.rot)
    span = seq.t[k:] - seq.t[:-k]
    truth_vec = (R[:-k].inv() * R[k:]).as_rotvec() / span[:, None]  # body-frame rate over each window
    csum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (seq.gyro[1:] + seq.gyro[:-1]) * dt[:, None], 0)])
    gyro_vec = (csum[k:] - csum[:-k]) / span[:, None]  # the gyro's mean over the same window
    truth_rate, gyro_rate = np.linalg.norm(truth_vec, axis=1), np.linalg.norm(gyro_vec, axis=1)
    bad_step = np.concatenate([[0], np.cumsum(dt > GAP_FACTOR * period)])
    ok = seq.gt_mask[k:] & seq.gt_mask[:-k] & (bad_step[k:] == bad_step[:-k])
    a = np.where(ok, gyro_rate - gyro_rate[ok].mean(), 0.0) if ok.any() else np.zeros_like(gyro_rate)
    b = np.where(ok, truth_rate - truth_rate[ok].mean(), 0.0) if ok.any() else np.zeros_like(truth_rate)
    norm = float(np.linalg.norm(a) * np.linalg.norm(b)) or 1.0
    c = correlate(a, b, mode="full", method="fft") / norm
    lags = np.arange(-len(b) + 1, len(a))
    window = np.abs(lags) * period <= SEARCH_S
    best = int(np.argmax(np.where(window, c, -np.inf)))
    corr0 = float(c[len(b) - 1])
    # both moving: a static recording's noisy truth (0.2 deg per sample) exceeds the threshold over 50 ms alone
    moving = ok & (truth_rate > MOVING_RAD_S) & (gyro_rate > MOVING_RAD_S)
    if moving.sum() <= 100 and corr0 >= MIN_LAG_CORR:
        # the gyro follows the truth but rarely exceeds the threshold: far smaller than the truth's rate (a gyro
        # in a unit 1000 times too large, or divided twice) is a scale to report, not too little motion
        moving = ok & (truth_rate > MOVING_RAD_S)
    enough = moving.sum() > 100
    ratio = float(np.median(gyro_rate[moving]) / np.median(truth_rate[moving])) if enough else np.nan
    axes_deg, mirrored, fit = compare_axes(gyro_vec[moving], truth_vec[moving]) if enough else (np.nan, False, None)
    return Consistency(
        gaps=int((dt > GAP_FACTOR * period).sum()),
        longest_step_s=float(dt.max()),
        rate_ratio=ratio,
        best_lag_s=float(lags[best] * period),
        corr_at_best=float(c[best]),
        corr_at_zero=corr0,
        axes_angle_deg=axes_deg,
        mirrored=mirrored,
        axes_fit=fit,
    )


def compare_axes(gyro_vec: np.ndarray, truth_vec: np.ndarray) -> tuple[float, bool, Rotation | None]:
    """(angle in deg of the rotation that best maps the truth's rate vectors onto the gyro's, whether the best
    orthogonal map is a mirror, that rotation or None where one axis leaves it undetermined), from one SVD of the
    gyro-truth cross-covariance, where the noise of each side averages out (the truth's own spread would count its
    noise as motion).

    Motion about one axis (a turntable, a pendulum) fixes only that axis: any turn about it fits equally, so the
    angle is then the one between the two rate axes. A mirror (determinant -1) is judged only for motion about
    all three axes (MIRROR_MIN_RATIO); otherwise it is False."""
    u, sv, vt = np.linalg.svd(gyro_vec.T @ truth_vec)
    mirrored = bool(sv[2] >= MIRROR_MIN_RATIO * sv[0] and np.linalg.det(u @ vt) < 0)
    if sv[1] > SINGLE_AXIS_RATIO * sv[0]:
        fit, _ = Rotation.align_vectors(gyro_vec, truth_vec)
        return float(np.degrees(fit.magnitude())), mirrored, fit
    return float(np.degrees(np.arccos(np.clip(u[:, 0] @ vt[0], -1.0, 1.0)))), mirrored, None


def clock_offset(m: Consistency) -> bool:
    """Whether the rates agree clearly better away from zero lag: the two are not on one clock. A clear peak:
    strong, and at most half the decorrelation of zero lag (EuRoC shifted by 100 ms: 0.97 vs 0.89; a constant-rate
    turntable's rate magnitude has no structure: peaks of 0.1-0.15)."""
    return bool(
        abs(m.best_lag_s) > MAX_LAG_S
        and m.corr_at_best >= MIN_LAG_CORR
        and 1 - m.corr_at_zero >= 2 * (1 - m.corr_at_best)
    )


class InconsistentTruthError(DataFormatError):
    """A training sequence's ground truth does not describe its gyro (scale, axes or clock): a model trained on it
    learns nothing true (`check(..., stop=True)`)."""


def check(seq: Sequence, stop: bool = False) -> Consistency:
    """Raise for a gyro in deg/s; warn (DataConsistencyWarning) for IMU gaps and an IMU outside the truth's span;
    for a gyro/truth scale far from 1, a truth about other axes or off the IMU's clock, warn, or raise
    `InconsistentTruthError` with `stop` (training sequences: their scores and their training mean nothing).
    Returns the measures."""
    files = [portable_path(f) if f else "?" for f in (seq.meta.get("imu_file"), seq.meta.get("gt_file"))]
    where = f"{seq.name} ({files[0]}, truth {files[1]})"  # portable: the message is kept in reports
    if len(seq) < 2 or len(seq) <= max(1, int(round(RATE_WINDOW_S / float(np.median(np.diff(seq.t)))))) + 1:
        cropped = int(seq.meta.get("imu_samples_cropped", 0))
        raise DataFormatError(  # shorter than the window the rates are compared over
            f"{where}: {len(seq)} samples with ground truth ({seq.t[-1] - seq.t[0]:.3f} s): too short to check against "
            "its truth, or to train or score on; give a recording of at least a few seconds"
            + (
                f" (the truth covers only these: {cropped} IMU samples lie outside it; check that the ground truth "
                "covers the recording)."
                if cropped
                else "."
            )
        )
    m = measure(seq)
    same_axes = not m.axes_angle_deg > AXES_MAX_DEG and not m.mirrored  # nan (too little motion) counts as the same
    if np.isfinite(m.rate_ratio) and 0.6 * DEG_PER_RAD <= m.rate_ratio <= 1.4 * DEG_PER_RAD and same_axes:
        raise GyroUnitError(
            f"{where}: the gyro is {m.rate_ratio:.1f} times the rate of the ground truth's orientation, about the "
            "same axes: it looks like deg/s. gyrodenoise reads rad/s (the ASL format's unit): multiply the gyro "
            "columns by pi/180 (0.0174533).",
            m.rate_ratio,
        )
    _check_acc_unit(seq, where)
    cropped = int(seq.meta.get("imu_samples_cropped", 0))
    if cropped > MAX_CROPPED_SHARE * (cropped + len(seq)):  # EuRoC/TUM-VI: 0-2.8 %, the IMU running before the mocap
        warnings.warn(
            f"{where}: {cropped} of {cropped + len(seq)} IMU samples lie outside the ground truth's time span and "
            f"are left out (the truth covers {seq.t[-1] - seq.t[0]:.1f} s): check that the truth file is whole.",
            DataConsistencyWarning,
            stacklevel=2,
        )
    if m.gaps:
        warnings.warn(
            f"{where}: {m.gaps} gap(s) in the IMU timestamps (the longest {m.longest_step_s:.3f} s). Training and "
            "the calibrated fit leave out the increments across a gap, but the open-loop attitude crosses it in one "
            "step, so its error after the gap is not the method's: split the recording at its gaps (one sequence "
            "folder each).",
            DataConsistencyWarning,
            stacklevel=2,
        )
    problems = _truth_problems(m)
    if problems and stop:
        raise InconsistentTruthError(
            f"{where}: {' Also, '.join(problems)} This is a training sequence: training on it would fit the "
            "disagreement, so the run stops here. Fix the file, or give dataset.inconsistent_truth=warn to train "
            "anyway."
        )
    for problem in problems:
        warnings.warn(f"{where}: {problem}", DataConsistencyWarning, stacklevel=2)
    return m


def _check_acc_unit(seq: Sequence, where: str) -> None:
    """Raise for an accelerometer in g or milli-g, warn for any other norm far from g (as the corrector's check)."""
    if len(seq) < 2:
        return
    norm = gravity_norm(seq.acc, seq.gyro, 1.0 / float(np.median(np.diff(seq.t))))
    if norm.ok:
        return
    found = f"{where}: the accelerometer's norm is {norm.g:.4g} m/s^2 {norm.where}, where gravity alone gives {G0}"
    guess = norm.unit_guess()
    if guess in ("g", "mg"):
        factor = G0 if guess == "g" else G0 / 1000.0
        raise AccUnitError(
            f"{found}: it looks like {guess}. gyrodenoise reads m/s^2 (the ASL format's unit): multiply the "
            f"accelerometer columns by {factor:g}."
        )
    warnings.warn(
        f"{found}: check the accelerometer's unit (m/s^2) and that its columns hold the raw specific force, gravity "
        "included.",
        DataConsistencyWarning,
        stacklevel=3,
    )


def _truth_problems(m: Consistency) -> list[str]:
    """What makes the ground truth a wrong description of the gyro: clock, scale, axes (each a sentence). A clock
    offset comes first: the scale and the axes are compared at the stamps as they are, and an offset alone spoils
    both comparisons (0.5 s on a hand-held recording: axes 126 deg away)."""
    problems = []
    if clock_offset(m):
        problems.append(
            f"the gyro's rate magnitude matches the ground truth's best {m.best_lag_s:+.3f} s away from "
            f"the stamps (correlation {m.corr_at_best:.2f} there, {m.corr_at_zero:.2f} at zero lag): the ground "
            f"truth is probably not on the IMU's clock; add {m.best_lag_s:+.3f} s to the ground truth's timestamps "
            "first (the comparisons below, if any, are at the stamps as they are, and may follow from the offset)."
        )
    if np.isfinite(m.rate_ratio) and not RATIO_RANGE[0] <= m.rate_ratio <= RATIO_RANGE[1]:
        problems.append(
            f"the gyro is {m.rate_ratio:.3g} times the rate of the ground truth's orientation (about 1 "
            "expected): check the gyro's unit and scale, and that the gyro columns are not the accelerometer's "
            "(ASL order: t, gyro x y z, acc x y z)."
        )
    if m.mirrored or m.axes_angle_deg > AXES_MAX_DEG:
        if m.mirrored:  # a reflection: no rotation undoes it, whatever angle the best rotation reaches
            what = (
                "the gyro's axes are a mirror image of the ground truth's body axes (no rotation maps one onto the "
                "other): a gyro axis is flipped in sign (or all three are), or two axes are swapped; or"
            )
        else:
            what = (
                f"the gyro turns about axes {m.axes_angle_deg:.0f} deg away from the ground truth's body axes (the "
                f"rotation that best maps the truth's body rate onto the gyro; under {AXES_MAX_DEG:g} deg expected):"
            )
        problems.append(
            f"{what} the truth's quaternion order may be wrong (the ASL files hold w, x, y, z; x, y, z, w "
            "read so gives ~100 deg or more), it may be the pose of another body than the IMU, or world-in-body "
            f"instead of body-in-world; or{'' if m.mirrored else ' a gyro axis is flipped or permuted, or'} the gyro "
            "columns are the accelerometer's. Scores against it mean nothing: fix the file or rotate the truth into "
            "the IMU frame" + _fitted_rotation(m) + "."
        )
    return problems


def _fitted_rotation(m: Consistency) -> str:
    """The body-to-IMU rotation the comparison fitted, to apply to the truth when it is the pose of another body."""
    if m.mirrored or m.axes_fit is None or clock_offset(m):  # off the clock, the fitted rotation is no frame's
        return ""
    x, y, z, w = m.axes_fit.as_quat()
    return (
        f" (the fitted rotation from the truth's body axes to the IMU's, gyro = R truth rate: quaternion w, x, y, z = "
        f"{w:.4f}, {x:.4f}, {y:.4f}, {z:.4f}; right-multiply each truth orientation by its inverse)"
    )
