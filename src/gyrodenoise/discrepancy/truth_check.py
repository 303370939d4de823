"""Is the ground truth independent of the gyro it judges?

The workflow compares the gyro with the rate of the ground truth. That shows the gyro's errors only
where the truth does not contain the gyro: a motion tracker's orientation does not; a batch estimate
that fuses the same IMU does, wherever the IMU dominates it (EuRoC's Machine Hall flights, whose
tracker measures position only). There, the residual gyro - truth lacks part of the gyro's own noise,
and every noise level fitted on it is too low.

Per sequence and frequency band this module measures, on the ground truth's own samples (the gyro
averaged over each ground-truth interval against the finite rotation between consecutive poses, after
shifting the IMU stamps by the lag that minimises their difference: a time offset would otherwise leave
motion x delay in the residual and hide a truth that follows the gyro):
- the coherence of the two rates (information: 1 also where an exact truth sees real motion);
- the share of the gyro's power the truth reproduces, 1 - PSD(gyro - truth) / PSD(gyro);
- with the sensor's datasheet noise density sigma (rad/s/sqrt(Hz)), the median of the residual's PSD
  over that of white noise of density sigma put through the same averaging (`white_reference`; flat
  at 2 sigma^2 one-sided before it): an independent truth leaves at least the gyro's noise in the
  residual (ratio >= ~1), so a ratio below FOLLOWS_RATIO says the truth follows the gyro in that band.
  Where the gyro itself is quieter than that white noise (its `own_floor`: per frequency the median power
  over its stretches, motion only adding to it, so not below its noise), the gyro cannot hold the
  datasheet's noise there (a sensor low-pass above its corner, a datasheet figure set high): the
  reference is that floor.
  Without sigma the check cannot tell a truth that follows the gyro from an exact one, and flags nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import optimize, signal
from scipy.spatial.transform import Rotation

from gyrodenoise.data.readers import ImuData, find_groundtruth_file, read_groundtruth, read_imu

BANDS_HZ = ((2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 80.0))
NPERSEG_S = 2.5  # Welch segment
NYQUIST_SHARE = 0.9  # bands end below this share of the truth's Nyquist frequency
MAX_LAG_S, LAG_GRID_S = 0.05, 0.002  # the time offsets the check aligns before it compares
FOLLOWS_RATIO = 0.5  # residual PSD below half the datasheet noise: the gyro's noise is partly in the truth
FLOOR_MIN_STRETCHES = 8  # stretches of NPERSEG_S the gyro's own floor needs (`own_floor`)
# effects named from the gyro's own values (its lattice, its plateaus), not from its residual against the truth
TRUTH_FREE = ("quantization", "saturation")


def interval_means(x: np.ndarray, t_ns: np.ndarray, at_ns: np.ndarray) -> np.ndarray:
    """(M - 1, 3) mean of the linearly interpolated samples x (N, 3) at t_ns over each interval of at_ns (M,);
    NaN for an empty interval (stamps clipped to the IMU record: callers keep only intervals inside it)."""
    step = np.diff(t_ns)[:, None] * 1e-9
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (x[1:] + x[:-1]) * step, 0)])  # exact integral
    c = np.stack([np.interp(at_ns, t_ns, cum[:, k]) for k in range(3)], 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.diff(c, axis=0) / (np.diff(at_ns)[:, None] * 1e-9)


def truth_rates(t_ns: np.ndarray, quat_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(truth's rate over each interval between consecutive poses (M - 1, 3) rad/s, whether the interval is
    regular (M - 1,): within 10% of the median, not a gap)."""
    dt = np.diff(t_ns) * 1e-9
    med = float(np.median(dt))
    rot = Rotation.from_quat(quat_xyzw)
    return (rot[:-1].inv() * rot[1:]).as_rotvec() / dt[:, None], np.abs(dt - med) < 0.1 * med


def gyro_truth_pairs(
    t_ns: np.ndarray,
    quat_xyzw: np.ndarray,
    imu: ImuData,
    rates: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(gyro averaged over each ground-truth interval, truth's rate over it), both (M, 3) rad/s, and the indices
    of those intervals, on the longest run of regular intervals inside the IMU record (a gap ends a run).
    `rates`: `truth_rates(t_ns, quat_xyzw)` when the caller already has them."""
    w_gt, regular = rates if rates is not None else truth_rates(t_ns, quat_xyzw)
    ok = regular & (t_ns[:-1] >= imu.t_ns[0]) & (t_ns[1:] <= imu.t_ns[-1])
    idx = np.flatnonzero(ok)
    if len(idx) == 0:
        raise ValueError("no ground-truth interval inside the IMU record: do the two files cover the same time?")
    run = max(np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1), key=len)
    inside = np.clip(t_ns, imu.t_ns[0], imu.t_ns[-1])
    return interval_means(imu.gyro, imu.t_ns, inside)[run], w_gt[run], run


def white_reference(
    noise_density: float, imu_t_ns: np.ndarray, gt_t_ns: np.ndarray, run: np.ndarray, seed: int = 0
) -> np.ndarray:
    """(M, 3) white gyro noise of `noise_density` (rad/s/sqrt(Hz)) at the IMU stamps, averaged over the same
    ground-truth intervals as the gyro: what an exact, independent truth leaves in the residual. The averaging
    low-passes it (at a truth rate equal to the IMU's, by cos^2(pi f / fs)), so the reference is simulated
    rather than taken flat at 2 sigma^2."""
    rate = 1e9 / float(np.median(np.diff(imu_t_ns)))
    noise = np.random.default_rng(seed).standard_normal((len(imu_t_ns), 3)) * noise_density * np.sqrt(rate)
    inside = np.clip(gt_t_ns, imu_t_ns[0], imu_t_ns[-1])
    return interval_means(noise, imu_t_ns, inside)[run]


def own_floor(gyro: np.ndarray, fs: float, nper: int) -> np.ndarray | None:
    """(F, 3) PSD on the frequencies of a Welch estimate with `nper`-sample segments: the gyro's power density over
    its quieter stretches. Per frequency, the median
    over non-overlapping stretches of `nper` samples of their Hann periodograms, over ln 2 (a periodogram bin of
    noise is exponential: its median is ln 2 times its mean), so noise alone gives its PSD, unbiased, and motion in
    some stretches barely moves it; motion everywhere only raises it. None with fewer than FLOOR_MIN_STRETCHES."""
    n_seg = len(gyro) // nper
    if n_seg < FLOOR_MIN_STRETCHES:
        return None
    segs = gyro[: n_seg * nper].reshape(n_seg, nper, 3)
    _, p = signal.periodogram(segs, fs, window="hann", detrend="constant", axis=1)
    return np.median(p, axis=0) / np.log(2.0)


def check_truth(
    gyro: np.ndarray, truth: np.ndarray, fs: float, white: np.ndarray | None = None, noise_density: float | None = None
) -> dict:
    """Per band (BANDS_HZ below NYQUIST_SHARE of fs/2): coherence per axis, reproduced share per axis and, with
    the simulated white-noise residual `white` (`white_reference`), the residual's PSD over the reference per axis
    (that white noise's PSD, or the gyro's own floor where that is lower: `own_floor`) and whether the truth follows
    the gyro."""
    nper = min(int(NPERSEG_S * fs), len(gyro))
    with np.errstate(invalid="ignore", divide="ignore"):  # 0/0 at the 0-Hz bin after detrending: no band reads it
        f, coh = signal.coherence(gyro, truth, fs, nperseg=nper, axis=0)
    _, p_gyro = signal.welch(gyro - gyro.mean(0), fs, nperseg=nper, axis=0)
    res = gyro - truth
    _, p_res = signal.welch(res - res.mean(0), fs, nperseg=nper, axis=0)
    p_white = signal.welch(white, fs, nperseg=nper, axis=0)[1] if white is not None else None
    floor = own_floor(gyro, fs, nper) if white is not None else None
    bands = []
    for lo, hi in BANDS_HZ:
        hi = float(min(hi, NYQUIST_SHARE * fs / 2))
        m = (f >= lo) & (f < hi)
        if m.sum() < 2:
            continue
        w = p_gyro[m] / p_gyro[m].sum(0)  # power-weighted: where the gyro has content
        band = {
            "band_hz": [lo, hi],
            "coherence": (w * coh[m]).sum(0).tolist(),
            "reproduced_share": (1 - p_res[m].sum(0) / p_gyro[m].sum(0)).tolist(),
            "residual_over_noise": None,
            "own_floor_over_noise": None,
            "follows_gyro": None,
        }
        if p_white is not None:
            noise = np.median(p_white[m], axis=0)
            own = None if floor is None else np.median(floor[m], axis=0)
            reference = noise if own is None else np.minimum(noise, own)
            ratio = np.median(p_res[m], axis=0) / reference
            band["residual_over_noise"] = ratio.tolist()
            band["own_floor_over_noise"] = None if own is None else (own / noise).tolist()
            band["follows_gyro"] = bool(np.any(ratio < FOLLOWS_RATIO))
        bands.append(band)
    return {"truth_rate_hz": fs, "seconds": len(gyro) / fs, "noise_density": noise_density, "bands": bands}


def check_sequence(mav0: str | Path, gt_file: str | Path | None = None, noise_density: float | None = None) -> dict:
    """`check_truth` of one ASL sequence folder (`.../mav0`); `gt_file` relative to it (default: the usual files)."""
    mav0 = Path(mav0)
    imu = read_imu(mav0 / "imu0" / "data.csv")
    gt_path = mav0 / gt_file if gt_file else find_groundtruth_file(mav0)
    gt = read_groundtruth(gt_path)
    lag_ns = best_lag_ns(gt.t_ns, gt.quat_xyzw, imu)
    imu = ImuData(imu.t_ns - lag_ns, imu.gyro, imu.acc, imu.path)
    gyro, truth, run = gyro_truth_pairs(gt.t_ns, gt.quat_xyzw, imu)
    fs = 1e9 / float(np.median(np.diff(gt.t_ns)))
    white = white_reference(noise_density, imu.t_ns, gt.t_ns, run) if noise_density else None
    return {"ground_truth": str(gt_path), "lag_s": lag_ns * 1e-9, **check_truth(gyro, truth, fs, white, noise_density)}


def best_lag_ns(t_ns: np.ndarray, quat_xyzw: np.ndarray, imu: ImuData, max_lag_s: float = MAX_LAG_S) -> int:
    """The shift of the IMU stamps (ns, subtracted) that minimises the residual gyro - truth: a time offset
    leaves motion x delay in the residual, which would hide a truth that follows the gyro from the check."""

    rates = truth_rates(t_ns, quat_xyzw)  # the truth does not move with the lag: computed once

    def power(lag_s: float) -> float:
        shifted = ImuData(imu.t_ns - int(round(lag_s * 1e9)), imu.gyro, imu.acc, imu.path)
        gyro, truth, _ = gyro_truth_pairs(t_ns, quat_xyzw, shifted, rates)
        r = gyro - truth
        return float(np.mean((r - r.mean(0)) ** 2))

    step = LAG_GRID_S
    grid = np.arange(-max_lag_s, max_lag_s + step / 2, step)
    powers = [power(x) for x in grid]
    k = int(np.argmin(powers))
    res = optimize.minimize_scalar(power, bounds=(grid[k] - step, grid[k] + step), method="bounded")
    return int(round(float(res.x if res.fun < powers[k] else grid[k]) * 1e9))


def followed_bands(check: dict) -> list[list[float]]:
    """The bands [lo, hi] Hz where the check found the truth following the gyro."""
    return [b["band_hz"] for b in check["bands"] if b.get("follows_gyro")]


def followed_in_band(checks: dict[str, dict], f_max_hz: dict[str, float]) -> dict[str, list[list[float]]]:
    """Per sequence of `checks`, the bands where its truth follows the gyro that start inside its compared band
    [0, f_max_hz[name]] (the band the workflow's regressions see); sequences without such a band are left out."""
    out = {}
    for name, check in checks.items():
        bands = [b for b in followed_bands(check) if b[0] < f_max_hz.get(name, float("inf"))]
        if bands:
            out[name] = bands
    return out
