"""Is an ensemble's spread a useful uncertainty? Predicted vs actual orientation-increment error.

Per window of `window_s` seconds (1 s by default) with ground truth throughout:
- predicted error, from the per-sample std sigma_n (rad/s, per axis) of the corrected gyro:
  "correlated" (default): || sum_n sigma_n dt_n ||, the error of an increment when the gyro error is
  constant over the window (the members' disagreement varies at the scale of the network's 2.5 s
  receptive field, not sample to sample); "independent": sqrt(sum_n ||sigma_n||^2 dt_n^2), the error
  of white per-sample errors. Both are sqrt(E||e||^2) for Gaussian errors of that kind, so a
  calibrated spread gives RMS(actual) / RMS(predicted) = 1.
- actual error: || Log(dR_gt^T dR_est) ||, the increments of ground truth and of the open-loop
  integration of the corrected gyro over the window (`so3.integrate_gyro`, float64).

`calibration` returns the Spearman rank correlation of the two (does a larger spread mean a
larger error?) and a reliability table (windows binned by predicted error: is the error as large
as predicted?); `gyrodenoise.plots.calibration_figure` draws both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from gyrodenoise.so3 import integrate_gyro, relative_rotvec

MODES = ("correlated", "independent")


@dataclass
class CalibrationResult:
    predicted: np.ndarray  # (W,) rad, predicted increment error per window
    actual: np.ndarray  # (W,) rad
    starts: np.ndarray  # (W,) first sample index of each window
    ends: np.ndarray  # (W,) last sample index of each window
    spearman: float
    p_value: float
    table: list[dict]  # reliability bins, see reliability_table
    window_s: float
    mode: str

    def summary(self) -> dict:
        """JSON-ready numbers (degrees), without the per-window arrays."""
        rms = lambda a: float(np.degrees(np.sqrt(np.mean(a**2)))) if len(a) else float("nan")  # noqa: E731
        rms_p, rms_a = rms(self.predicted), rms(self.actual)
        return {
            "windows": len(self.predicted),
            "window_s": self.window_s,
            "mode": self.mode,
            "spearman": self.spearman,
            "p_value": self.p_value,
            "rms_predicted_deg": rms_p,
            "rms_actual_deg": rms_a,
            # 1 when calibrated; NaN without windows (a recording whose ground truth breaks off more than once a second)
            "rms_ratio": rms_a / rms_p if rms_p > 0 else float("inf") if rms_p == 0 else float("nan"),
            "table": self.table,
        }


def window_bounds(dt: np.ndarray, window_s: float, gt_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Consecutive whole windows [start, end] of `window_s` seconds (sample indices), keeping only
    windows with ground truth at every sample. dt follows Sequence.dt (dt[0] unused)."""
    if window_s <= 0:
        raise ValueError(f"window_s={window_s}: must be positive")
    t = np.concatenate([[0.0], np.cumsum(np.asarray(dt, dtype=np.float64)[1:])])
    # window edges on the sample nearest to each multiple of window_s (half a sample of slack: the
    # sum of dt lands a rounding error on either side of the exact multiple)
    half = 0.5 * float(np.median(dt[1:])) if len(t) > 1 else 0.0
    edges = np.searchsorted(t, np.arange(0.0, t[-1] + half, window_s) - half)
    starts, ends = edges[:-1], edges[1:]
    keep = ends > starts
    if gt_mask is not None:
        bad = np.concatenate([[0], np.cumsum(~np.asarray(gt_mask, dtype=bool))])  # bad[k] = #missing in [0, k)
        keep &= bad[ends + 1] - bad[starts] == 0
    return starts[keep], ends[keep]


def predicted_increment_error(
    std: np.ndarray, dt: np.ndarray, starts: np.ndarray, ends: np.ndarray, mode: str = "correlated"
) -> np.ndarray:
    """Predicted error (rad) of the increment from sample `start` to `end` (steps start+1 .. end)."""
    if mode not in MODES:
        raise ValueError(f"mode={mode!r}; choose one of {MODES}")
    std = np.asarray(std, dtype=np.float64)
    dt = np.asarray(dt, dtype=np.float64)
    if mode == "correlated":
        c = np.concatenate([np.zeros((1, 3)), np.cumsum(std * dt[:, None], axis=0)])
        return np.linalg.norm(c[ends + 1] - c[starts + 1], axis=1)
    c = np.concatenate([[0.0], np.cumsum((std**2).sum(1) * dt**2)])
    return np.sqrt(c[ends + 1] - c[starts + 1])


def actual_increment_error(
    gyro: np.ndarray, dt: np.ndarray, rot_gt: np.ndarray, starts: np.ndarray, ends: np.ndarray
) -> np.ndarray:
    """||Log(dR_gt^T dR_est)|| (rad) over each window, dR_est from the integrated corrected gyro."""
    R = integrate_gyro(rot_gt[0], gyro, dt)
    dR_est = np.swapaxes(R[starts], -1, -2) @ R[ends]
    dR_gt = np.swapaxes(rot_gt[starts], -1, -2) @ rot_gt[ends]
    return np.linalg.norm(relative_rotvec(dR_gt, dR_est), axis=-1)


def reliability_table(predicted: np.ndarray, actual: np.ndarray, n_bins: int = 10) -> list[dict]:
    """Windows sorted by predicted error in `n_bins` equal-count bins; per bin the predicted range,
    RMS predicted and RMS actual error (deg) and their ratio (1 when the spread is calibrated,
    > 1 overconfident, < 1 underconfident)."""
    order = np.argsort(predicted, kind="stable")
    rows = []
    if not len(order):  # no window with ground truth throughout: no bins (array_split refuses 0 sections)
        return rows
    for idx in np.array_split(order, min(n_bins, len(order))):
        p, a = predicted[idx], actual[idx]
        rms_p, rms_a = np.degrees(np.sqrt(np.mean(p**2))), np.degrees(np.sqrt(np.mean(a**2)))
        rows.append(
            {
                "n": len(idx),
                "predicted_lo_deg": float(np.degrees(p.min())),
                "predicted_hi_deg": float(np.degrees(p.max())),
                "rms_predicted_deg": float(rms_p),
                "rms_actual_deg": float(rms_a),
                "ratio": float(rms_a / rms_p) if rms_p > 0 else float("inf"),
            }
        )
    return rows


def calibration(
    gyro: np.ndarray,
    std: np.ndarray,
    dt: np.ndarray,
    rot_gt: np.ndarray,
    gt_mask: np.ndarray | None = None,
    window_s: float = 1.0,
    n_bins: int = 10,
    mode: str = "correlated",
) -> CalibrationResult:
    """Predicted (from `std`) vs actual (from `gyro` and ground truth) increment error per window.

    gyro, std: (N, 3) rad/s, the corrected gyro and its per-sample std; dt: (N,) s (Sequence.dt);
    rot_gt: (N, 3, 3) ground truth; gt_mask: (N,) ground truth available.
    """
    gyro, std = np.asarray(gyro, dtype=np.float64), np.asarray(std, dtype=np.float64)
    if gyro.shape != std.shape or gyro.ndim != 2 or gyro.shape[1] != 3:
        raise ValueError(f"gyro {gyro.shape} and std {std.shape} must both be (N, 3)")
    if len(dt) != len(gyro) or len(rot_gt) != len(gyro):
        raise ValueError(f"gyro has {len(gyro)} samples, dt {len(dt)}, ground truth {len(rot_gt)}")
    starts, ends = window_bounds(dt, window_s, gt_mask)
    pred = predicted_increment_error(std, dt, starts, ends, mode)
    act = actual_increment_error(gyro, dt, rot_gt, starts, ends)
    rho, p = _spearman(pred, act)
    return CalibrationResult(pred, act, starts, ends, rho, p, reliability_table(pred, act, n_bins), window_s, mode)


def _spearman(pred: np.ndarray, act: np.ndarray) -> tuple[float, float]:
    """(rho, p-value); NaN when either side does not vary beyond rounding (ranks of noise mean nothing)."""
    varies = lambda a: np.ptp(a) > 1e-9 * np.abs(a).max()  # noqa: E731
    if len(pred) < 3 or not varies(pred) or not varies(act):
        return float("nan"), float("nan")
    res = stats.spearmanr(pred, act)
    return float(res.statistic), float(res.pvalue)


def pooled(results: list[CalibrationResult], n_bins: int = 10) -> CalibrationResult:
    """The windows of several sequences together (one Spearman, one table)."""
    if not results:
        raise ValueError("no calibration results to pool")
    pred = np.concatenate([r.predicted for r in results])
    act = np.concatenate([r.actual for r in results])
    rho, p = _spearman(pred, act)
    idx = np.concatenate([r.starts for r in results]), np.concatenate([r.ends for r in results])
    return CalibrationResult(
        pred, act, *idx, rho, p, reliability_table(pred, act, n_bins), results[0].window_s, results[0].mode
    )


if __name__ == "__main__":  # a library module: say where its command-line use is
    print(
        "gyrodenoise.uncertainty is a library (calibration, pooled, plots.calibration_figure). To check an "
        "ensemble's spread against the actual 1-s increment error, run `python -m gyrodenoise.evaluate "
        "dataset=... weights.proposed=ENS.pt split=val`; to rescale the spread, `python -m gyrodenoise.ensemble "
        "scale --help`."
    )
