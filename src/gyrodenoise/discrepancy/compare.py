"""Load measured sequences as the detector sees them, and the statistics that compare measured and
simulated gyros: residuals, Allan deviation, Welch spectra, cross-correlations, orientation drift."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.spatial.transform import Rotation

from gyrodenoise.data import consistency
from gyrodenoise.data.readers import (
    DataFormatError,
    GroundTruthData,
    ImuData,
    find_groundtruth_file,
    read_groundtruth,
    read_imu,
)
from gyrodenoise.data.sequence import build_sequence, sequence_folder
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.trajectory import SmoothTrajectory
from gyrodenoise.so3 import integrate_gyro

MAX_GT_GAP_S = 0.25  # a longer ground-truth gap splits a sequence: a spline cannot bridge it at hand-held rates
KNOTS_PER_TRUTH_PERIOD = 2.0  # knot spacing over the truth's sample period, at least (20 Hz truth: 0.1 s)
MIN_STRETCH_S = 10.0  # shorter gap-free stretches are left out (and listed): too short for spectra and drift


def gap_free_stretches(t_ns: np.ndarray, max_gap_s: float = MAX_GT_GAP_S) -> list[slice]:
    """Index ranges of the ground truth between its gaps longer than `max_gap_s`."""
    cut = np.flatnonzero(np.diff(t_ns) * 1e-9 > max_gap_s) + 1
    edges = np.concatenate([[0], cut, [len(t_ns)]])
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def load_fit_contexts(
    root: str | Path,
    name: str,
    gt_file: str | None = None,
    knot_spacing: float = 0.05,
    margin_s: float = 0.5,
    max_gap_s: float = MAX_GT_GAP_S,
    min_stretch_s: float = MIN_STRETCH_S,
) -> tuple[list[FitContext], list[dict]]:
    """The sequence as the detector sees it, split at ground-truth gaps longer than `max_gap_s` (TUM-VI's mocap
    occlusions: a spline through them invents the motion, and its rate there would dominate the residual).
    Returns (one context per gap-free stretch of at least `min_stretch_s` after the margins, named
    'NAME@A-Bs' when the sequence is split; the stretches left out, with why). A sequence without such gaps
    gives one context named NAME. The IMU is first checked against its truth as training data is
    (`consistency.check`: an error for a gyro in deg/s, warnings for another clock, axes or scale)."""
    mav0 = sequence_folder(root, name)
    gt_path = mav0 / gt_file if gt_file else find_groundtruth_file(mav0)
    imu = read_imu(mav0 / "imu0" / "data.csv")
    gt = read_groundtruth(gt_path)
    m = consistency.check(build_sequence(name, imu, gt))
    # a scale or a clock that disagrees is what the workflow names (scale factor, time offset); a truth about other
    # axes (x, y, z, w read as w, x, y, z; another body) is not: rates compared axis by axis would name noise
    if (m.mirrored or m.axes_angle_deg > consistency.AXES_MAX_DEG) and not consistency.clock_offset(m):
        raise DataFormatError(
            f"{gt_path}: the ground truth turns about other axes than the gyro of {imu.path} ("
            + ("a mirror image" if m.mirrored else f"{m.axes_angle_deg:.0f} deg away")
            + "): the workflow compares the rates axis by axis, so its verdict would mean nothing. Fix the truth "
            "first: the ASL files hold the quaternion as w, x, y, z, of the IMU's body in the world (not another "
            "body's, not world-in-body)."
        )
    stretches = gap_free_stretches(gt.t_ns, max_gap_s)
    if len(stretches) == 1:
        span = (min(gt.t_ns[-1], imu.t_ns[-1]) - max(gt.t_ns[0], imu.t_ns[0])) * 1e-9 - 2 * margin_s
        if span < min_stretch_s:  # its spectra and 10-s drifts would be NaN or one window's noise, without a word
            raise DataFormatError(
                f"{gt_path}: IMU and ground truth of {name} overlap for {max(span, 0):.1f} s (less {margin_s:g} s "
                f"at each end), shorter than the {min_stretch_s:g} s the comparison needs (its spectra, its 10-s "
                "drifts): the workflow needs tens of seconds of motion per sequence."
            )
        return [_context(name, name, imu, gt, gt_path, knot_spacing, margin_s)], []
    out, left = [], []
    for s in stretches:
        a, b = ((gt.t_ns[s.start], gt.t_ns[s.stop - 1]) - imu.t_ns[0]) * 1e-9
        label = f"{name}@{a:.1f}-{b:.1f}s"
        if b - a - 2 * margin_s < min_stretch_s:
            left.append({"sequence": name, "stretch": label, "seconds": float(b - a), "why": "too short"})
            continue
        part = GroundTruthData(gt.t_ns[s], gt.pos[s], gt.quat_xyzw[s], gt.path)
        out.append(_context(label, name, imu, part, gt_path, knot_spacing, margin_s))
    if not out:
        raise DataFormatError(
            f"{gt_path}: no stretch between ground-truth gaps longer than {max_gap_s} s lasts {min_stretch_s} s; "
            "the sequence cannot be compared (lower the minimum or allow longer gaps)."
        )
    return out, left


def load_fit_context(
    root: str | Path,
    name: str,
    gt_file: str | None = None,
    knot_spacing: float = 0.05,
    margin_s: float = 0.5,
) -> FitContext:
    """One context for the whole sequence (`load_fit_contexts`); refuses a ground truth with long gaps."""
    fcs, left = load_fit_contexts(root, name, gt_file, knot_spacing, margin_s)
    if len(fcs) > 1 or left:
        raise DataFormatError(
            f"{name}: the ground truth has gaps longer than {MAX_GT_GAP_S} s, which a spline cannot bridge; "
            "use load_fit_contexts, which splits the sequence at them."
        )
    return fcs[0]


def _context(
    name: str,
    sequence: str,
    imu: ImuData,
    gt: GroundTruthData,
    gt_path: Path,
    knot_spacing: float,
    margin_s: float,
) -> FitContext:
    """IMU samples inside the ground-truth span (minus `margin_s` at each end, where the spline is
    less reliable), with the true rate, angular acceleration and specific force from a smooth fit
    of the ground truth, each the mean over the IMU period centred on its stamp. Time 0 is the sequence's
    first IMU sample."""
    t_gt = (gt.t_ns - gt.t_ns[0]) * 1e-9
    period = float(np.median(np.diff(t_gt))) if len(t_gt) > 1 else math.inf
    if knot_spacing < KNOTS_PER_TRUTH_PERIOD * period:  # a knot per truth sample: no data to bind the fit
        need = math.ceil(KNOTS_PER_TRUTH_PERIOD * period * 100) / 100
        raise DataFormatError(
            f"{gt_path}: the ground truth is sampled at {1 / period:.4g} Hz, too slow for knots every "
            f"{knot_spacing:g} s (the truth spline needs at least {KNOTS_PER_TRUTH_PERIOD:g} truth samples between "
            f"knots): pass --knot-spacing {need:g} or more."
        )
    traj = SmoothTrajectory.fit(t_gt, gt.quat_xyzw, gt.pos, knot_spacing, t0_ns=int(gt.t_ns[0]), source=str(gt_path))
    t_imu = (imu.t_ns - traj.t0_ns) * 1e-9
    keep = (t_imu >= traj.t_start + margin_s) & (t_imu <= traj.t_end - margin_s)
    if keep.sum() < 100:
        overlap = min(t_imu[-1], traj.t_end) - max(t_imu[0], traj.t_start)
        short = len(t_imu) < 100 or overlap > 0  # the streams meet: the recording, not the clock, is too short
        raise DataFormatError(
            f"{gt_path}: fewer than 100 IMU samples of {imu.path} fall inside the ground-truth span"
            + (
                f" less {margin_s:g} s at each end ({int(keep.sum())} of {len(t_imu)}): the recording is too short to "
                "compare; the workflow needs tens of seconds of motion."
                if short
                else ". Both files must share one clock (ns)."
            )
        )
    t = t_imu[keep]
    rate = float(1.0 / np.median(np.diff(t)))
    # the ideal sample is the rate's mean over one period, as the simulator's: compared with the instantaneous
    # rate, its droop sinc(f / rate) would be read as a low-pass (1.6 % at 20 Hz for 200 Hz)
    kin = traj.sample_mean(t, 1.0 / rate)
    return FitContext(
        name=name,
        t=t - t_imu[0],  # since the first IMU sample (power-on for warm-up effects)
        gyro=imu.gyro[keep],
        omega=kin.omega,
        alpha=kin.alpha,
        f=kin.specific_force,
        rate_hz=rate,
        extra={
            "rot": kin.rot,
            "t_ns": imu.t_ns[keep],
            "acc": imu.acc[keep],
            "gt_file": str(gt_path),
            # truth at other times (sequence time), for the time-offset regressor
            "kinematics_at": lambda tt, off=float(t_imu[0]): traj.sampled_at(tt + off, 1.0 / rate),
            # the ground truth around its own fit, for the trusted band (`reconstruction.estimate_band`)
            **gt_fit_residual(traj, t_gt, gt.quat_xyzw, margin_s),
            "knot_spacing": knot_spacing,
            "sequence": sequence,  # the recording this stretch is part of
        },
    )


def gt_fit_residual(traj: SmoothTrajectory, t: np.ndarray, quat_xyzw: np.ndarray, margin_s: float = 0.5) -> dict:
    """Rotation vector of R_fit(t)^T R_gt(t) at the ground-truth samples inside the span (minus
    `margin_s`): the ground truth's noise plus the motion the spline does not follow."""
    keep = (t >= traj.t_start + margin_s) & (t <= traj.t_end - margin_s)
    rot_fit = Rotation.from_matrix(traj.evaluate(t[keep]).rot)
    res = (rot_fit.inv() * Rotation.from_quat(quat_xyzw[keep])).as_rotvec()
    return {"gt_t": t[keep], "gt_rotvec_residual": res}


# ----------------------------------------------------------------------------- spectra, correlation


def spectrum(x: np.ndarray, rate_hz: float, nperseg: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectral density ((rad/s)^2/Hz) per axis."""
    nper = min(nperseg, len(x))
    f, p = signal.welch(x - x.mean(0), fs=rate_hz, nperseg=nper, axis=0)
    return f, p


def cross_correlations(fcs: list[FitContext], residuals: list[np.ndarray]) -> dict[str, list[float]]:
    """Pearson correlation of each residual axis with candidate regressors (same axis / magnitude)."""
    r = np.concatenate([x - x.mean(0) for x in residuals])
    regs = {
        "angular_rate": np.concatenate([fc.omega for fc in fcs]),
        "angular_acceleration": np.concatenate([fc.alpha for fc in fcs]),
        "specific_force": np.concatenate([fc.f - fc.f.mean(0) for fc in fcs]),
        "rate_abs_rate": np.concatenate([fc.omega * np.abs(fc.omega) for fc in fcs]),
        "time": np.concatenate([np.repeat(fc.t[:, None], 3, 1) for fc in fcs]),
    }
    out = {}
    for k, v in regs.items():
        v = v - v.mean(0)
        den = np.sqrt((v * v).sum(0) * (r * r).sum(0))
        out[k] = np.where(den > 0, (v * r).sum(0) / np.maximum(den, 1e-300), 0.0).tolist()
    return out


# ----------------------------------------------------------------------------- orientation drift


def window_drift_deg(gyro_a: np.ndarray, gyro_b: np.ndarray, dt: float, window_s: float) -> np.ndarray:
    """Angle (deg) between the attitudes integrated from gyro_a and gyro_b over consecutive windows."""
    m = int(round(window_s / dt))
    n = (len(gyro_a) - 1) // m
    out = []
    for k in range(n):
        sl = slice(k * m, k * m + m + 1)
        dts = np.full(m + 1, dt)
        Ra = integrate_gyro(np.eye(3), gyro_a[sl], dts)[-1]
        Rb = integrate_gyro(np.eye(3), gyro_b[sl], dts)[-1]
        out.append(np.degrees(np.linalg.norm(Rotation.from_matrix(Ra.T @ Rb).as_rotvec())))
    return np.asarray(out)


def drift_vs_truth_deg(gyro: np.ndarray, rot: np.ndarray, dt: float, window_s: float) -> np.ndarray:
    """Angle (deg) of the open-loop attitude error after `window_s`, windows started on the truth."""
    m = int(round(window_s / dt))
    n = (len(gyro) - 1) // m
    out = []
    for k in range(n):
        a = k * m
        R = integrate_gyro(rot[a], gyro[a : a + m + 1], np.full(m + 1, dt))[-1]
        out.append(np.degrees(np.linalg.norm(Rotation.from_matrix(rot[a + m].T @ R).as_rotvec())))
    return np.asarray(out)
