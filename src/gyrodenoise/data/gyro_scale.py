"""The gyro's unit read off gravity: over half-second windows in which the accelerometer sees mostly gravity, the
tilt change the gyro predicts (its rotation applied to the gravity direction) is compared with the tilt change the
accelerometer measures, for the gyro as given and for it in deg/s or converted to deg/s twice.

A gyro in deg/s read as rad/s rotates 57 times too far: where the body tilts by a few degrees, or sits still
with a bias of a fraction of a deg/s, only the deg/s reading predicts what the accelerometer sees. Motion about
gravity alone (yaw) and windows with strong linear acceleration say nothing and are left out; a recording
without tilt changes gives no verdict. The accelerometer must be in m/s^2 (`gravity_norm` checks it first).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

G0 = 9.80665
WINDOW_S = 0.5  # the tilt change is measured over this span
END_S = 0.1  # the gravity direction is the accelerometer's mean over this long at each end of a window
QUASI_STATIC = 0.1  # |acc| within this fraction of g at both ends (little linear acceleration)
INFORMATIVE_DEG = 5.0  # a window counts when the hypotheses' predictions differ by more than this
MIN_WINDOWS = 4  # informative windows needed for a verdict
AGREE = 0.8  # the share of informative windows a hypothesis must fit best for a verdict
# deg/s also needs the rad/s reading to miss by this much (median): a deg/s gyro read as rad/s turns 57 times too
# far and misses by tens of degrees (24-104 deg on EuRoC and TUM-VI converted to deg/s), while a gyro whose samples do
# not follow the body's motion (synthetic noise) misses by a few in either unit
WRONG_MIN_DEG = 20.0
SCALES = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
ACC_STILL = 0.2  # m/s^2: the accelerometer's sample-to-sample scatter (std of its differences / sqrt 2)


@dataclass
class GyroScaleVerdict:
    unit: str | None  # the hypothesis that fits (a key of SCALES), None: no verdict
    windows: int  # informative windows
    share: float  # of them, the share the unit fits best
    median_error_deg: dict[str, float]  # per hypothesis, over the informative windows

    @property
    def wrong_unit(self) -> bool:
        return self.unit is not None and self.unit != "rad/s"


def _tilt_errors(acc: np.ndarray, gyro: np.ndarray, rate_hz: float) -> np.ndarray:
    """(windows, hypotheses) angle between the measured and the predicted gravity direction at each window's end."""
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        return np.zeros((0, len(SCALES)))
    n, e = max(int(round(WINDOW_S * rate_hz)), 4), max(int(round(END_S * rate_hz)), 1)
    starts = np.arange(0, len(acc) - n + 1, n)
    if not len(starts):
        return np.zeros((0, len(SCALES)))
    a0 = np.stack([acc[s : s + e].mean(0) for s in starts])
    a1 = np.stack([acc[s + n - e : s + n].mean(0) for s in starts])
    static = (np.abs(np.linalg.norm(a0, axis=1) / G0 - 1) < QUASI_STATIC) & (
        np.abs(np.linalg.norm(a1, axis=1) / G0 - 1) < QUASI_STATIC
    )
    # a multirotor's accelerometer sees its thrust, fixed in the body, not its tilt: windows that vibrate like one
    # in flight (sample-to-sample changes of 1-3 m/s^2 on EuRoC, against 0.04-0.1 at rest or in a hand) are left out,
    # as are those with a strong linear acceleration
    vibration = np.stack([np.diff(acc[s : s + n], axis=0).std(0).max() / np.sqrt(2) for s in starts])
    static &= vibration < ACC_STILL
    a0, a1, starts = a0[static], a1[static], starts[static]
    if not len(starts):
        return np.zeros((0, len(SCALES)))
    # rotation from the middle of the first end segment to the middle of the last: the product of the samples'
    # rotations (right products, body frame, one period each), all windows at once
    lo, hi = e // 2, n - e + e // 2
    w = gyro[starts[:, None] + np.arange(lo, hi)]  # (windows, steps, 3)
    out = np.empty((len(starts), len(SCALES)))
    for j, scale in enumerate(SCALES.values()):
        r = Rotation.from_rotvec(w[:, 0] * (scale / rate_hz))
        for k in range(1, w.shape[1]):  # scipy composes the windows' rotations elementwise
            r = r * Rotation.from_rotvec(w[:, k] * (scale / rate_hz))
        pred = r.inv().apply(a0)  # gravity in the later body frame: R^T g
        cos = np.einsum("ij,ij->i", pred, a1) / (np.linalg.norm(pred, axis=1) * np.linalg.norm(a1, axis=1))
        out[:, j] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def gyro_scale_verdict(acc: np.ndarray, gyro: np.ndarray, rate_hz: float) -> GyroScaleVerdict:
    """Which unit the gyro's rotations fit, judged against the accelerometer's gravity (module docstring)."""
    err = _tilt_errors(np.asarray(acc, np.float64), np.asarray(gyro, np.float64), float(rate_hz))
    names = list(SCALES)
    informative = err[(np.nanmax(err, axis=1) - np.nanmin(err, axis=1)) > INFORMATIVE_DEG] if len(err) else err
    medians = {k: float(np.median(informative[:, i])) if len(informative) else float("nan") for i, k in
               enumerate(names)}  # fmt: skip
    if len(informative) < MIN_WINDOWS:
        return GyroScaleVerdict(None, len(informative), 0.0, medians)
    best = np.argmin(informative, axis=1)
    counts = np.bincount(best, minlength=len(names))
    top = int(np.argmax(counts))
    share = float(counts[top] / len(informative))
    clear = share >= AGREE and (names[top] != "deg/s" or medians["rad/s"] >= WRONG_MIN_DEG)
    return GyroScaleVerdict(names[top] if clear else None, len(informative), share, medians)


def gyro_unit_message(what: str, verdict: GyroScaleVerdict) -> str:
    """The evidence for a gyro in deg/s, for a warning or an error that starts with `what`."""
    med = verdict.median_error_deg
    return (
        f"{what}: in {verdict.windows} half-second stretches where the accelerometer sees gravity without vibrating, "
        f"the gyro's rotations taken as rad/s move gravity {med['rad/s']:.0f} deg (median) from where the "
        f"accelerometer sees it, and taken as deg/s {med['deg/s']:.1f} deg ({verdict.share:.0%} of the stretches "
        "fit deg/s better)."
    )
