"""Simulate an IMU along a smooth trajectory with an error model, and write ASL folders.

The truth is evaluated at `oversample` x the IMU rate on a grid centred on each IMU stamp; the
effects act there in continuous time (noise densities scale with the internal rate), the front end
saturates, and the output is the centred mean over each IMU period (an anti-alias filter without
delay), then quantised. Everything random comes from one seeded numpy Generator.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.effects import Effect, WhiteNoise
from gyrodenoise.sim.trajectory import SmoothTrajectory

IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
GT_HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"


@dataclass
class SimulatedImu:
    t_ns: np.ndarray  # (N,) int64
    gyro: np.ndarray  # (N, 3)
    acc: np.ndarray  # (N, 3)
    gt_pos: np.ndarray  # (N, 3) true position at the stamps
    gt_quat_xyzw: np.ndarray  # (N, 4) true orientation at the stamps
    true_gyro: np.ndarray  # (N, 3) ideal rate at the stamps
    meta: dict = field(default_factory=dict)


def apply_error_model(
    effects: list[Effect], sig: SignalContext, rng: np.random.Generator, stages: tuple[int, ...] = (0, 1, 2, 3)
) -> np.ndarray:
    """Gyro output of the listed stages. Stage 1 effects respond to the true inputs, not to each other."""
    y = sig.omega.copy()
    for stage in stages:
        for e in sorted((e for e in effects if e.stage == stage), key=lambda e: e.name):
            y = e.apply(sig, y, rng)
    return y


def simulate_imu(
    traj: SmoothTrajectory,
    effects: list[Effect],
    rate_hz: float = 200.0,
    duration_s: float | None = None,
    seed: int = 0,
    oversample: int = 10,
    t0_ns: int = 1_000_000_000_000_000_000,
    margin_s: float = 0.5,
    acc_noise_density: float = 2.0e-3,
    acc_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> SimulatedImu:
    """Gyro from `effects`; accelerometer = specific force + constant bias + white noise.

    Stamps start `margin_s` after the trajectory start (the spline's ends are less reliable) and
    are exact integer nanoseconds. The error model's time 0 is the first stamp (power-on).
    """
    rng = np.random.default_rng(seed)
    period_ns = int(round(1e9 / rate_hz))
    span = traj.t_end - traj.t_start - 2 * margin_s
    if duration_s is not None:
        span = min(span, duration_s)
    n = int(np.floor(span * 1e9 / period_ns)) + 1
    k = np.arange(n, dtype=np.int64)
    t_ns = t0_ns + k * period_ns
    t_rel = k * (period_ns * 1e-9)  # since power-on
    t_traj = traj.t_start + margin_s + t_rel
    # centred internal grid: IMU sample k averages the period [t_k - T/2, t_k + T/2)
    m = int(oversample)
    sub = ((np.arange(m) + 0.5) / m - 0.5) * (period_ns * 1e-9)
    t_hi_rel = (t_rel[:, None] + sub[None]).ravel()
    shift = traj.t_start + margin_s
    kin_hi = traj.evaluate(t_hi_rel + shift)
    sig = SignalContext(
        t=t_hi_rel,
        omega=kin_hi.omega,
        alpha=kin_hi.alpha,
        f=kin_hi.specific_force,
        rate_hz=rate_hz * m,
        kinematics_at=lambda t: traj.evaluate(t + shift),
    )
    y_hi = apply_error_model(effects, sig, rng)
    gyro = y_hi.reshape(n, m, 3).mean(1)
    out_sig = SignalContext(t=t_rel, omega=gyro, alpha=np.zeros_like(gyro), f=np.zeros_like(gyro), rate_hz=rate_hz)
    for e in effects:
        if e.stage == 4:
            gyro = e.apply(out_sig, gyro, rng)
    f = kin_hi.specific_force.reshape(n, m, 3).mean(1)
    acc = (
        f
        + np.asarray(acc_bias)
        + WhiteNoise(density=np.full(3, acc_noise_density)).apply(
            SignalContext(t_rel, f, f, f, rate_hz), np.zeros_like(f), rng
        )
    )
    kin = traj.evaluate(t_traj)
    return SimulatedImu(
        t_ns=t_ns,
        gyro=gyro,
        acc=acc,
        gt_pos=kin.pos,
        gt_quat_xyzw=kin.quat_xyzw,
        true_gyro=kin.omega,
        meta={
            "rate_hz": rate_hz,
            "oversample": m,
            "seed": seed,
            "effects": [e.to_dict() for e in effects],
            "acc_noise_density": acc_noise_density,
        },
    )


def _write_csv(path: Path, header: str, t_ns: np.ndarray, values: np.ndarray) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(header + "\n")
        for t, row in zip(t_ns.tolist(), values.tolist(), strict=True):
            fh.write(str(t) + "," + ",".join(repr(v) for v in row) + "\n")


def asl_written(folder: Path) -> bool:
    """Whether `write_asl` has put a sequence at `folder` (it renames a whole copy into place, so both files)."""
    return all((folder / "mav0" / d / "data.csv").is_file() for d in ("imu0", "state_groundtruth_estimate0"))


def write_asl(folder: str | Path, sim: SimulatedImu, gt_stride: int = 1, keep_existing: bool = False) -> Path:
    """<folder>/mav0/{imu0,state_groundtruth_estimate0}/data.csv + sim.json, written atomically.

    The folder is assembled under a temporary name beside it and renamed into place, so a reader
    never sees a half-written sequence. Quaternions are written w, x, y, z (ASL order).
    """
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.tmp"))
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(tmp, 0o777 & ~mask)  # mkdtemp makes 0700: others sharing the cache could not read the sequence
    try:
        imu_dir = tmp / "mav0" / "imu0"
        gt_dir = tmp / "mav0" / "state_groundtruth_estimate0"
        imu_dir.mkdir(parents=True)
        gt_dir.mkdir(parents=True)
        _write_csv(imu_dir / "data.csv", IMU_HEADER, sim.t_ns, np.concatenate([sim.gyro, sim.acc], 1))
        q = sim.gt_quat_xyzw[::gt_stride]
        q = q * np.where(q[:, 3:] < 0, -1.0, 1.0)
        gt_vals = np.concatenate([sim.gt_pos[::gt_stride], q[:, 3:], q[:, :3]], 1)
        _write_csv(gt_dir / "data.csv", GT_HEADER, sim.t_ns[::gt_stride], gt_vals)
        (tmp / "sim.json").write_text(json.dumps(sim.meta, indent=2))
        if keep_existing and asl_written(folder):  # another process wrote it meanwhile (same settings, same content)
            return folder
        if folder.exists():
            shutil.rmtree(folder, ignore_errors=True)
        try:
            os.replace(tmp, folder)
        except OSError:  # ENOTEMPTY/EEXIST: another process renamed its copy in first
            if not (keep_existing and asl_written(folder)):
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return folder
