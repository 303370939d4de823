"""Simulate an IMU along a smooth trajectory with an error model, and write ASL folders.

The truth is evaluated at `oversample` x the IMU rate on a grid centred on each IMU stamp; the
effects act there in continuous time (noise densities scale with the internal rate), the front end
saturates, and the output is the centred mean over each IMU period (an anti-alias filter without
delay), then quantised. Everything random comes from one seeded numpy Generator.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyrodenoise.data.asl_write import asl_written, pose_values, write_sequence
from gyrodenoise.sim.accel import apply_acc_error_model, check_acc_effects
from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.effects import Effect, TimeOffset, WhiteNoise
from gyrodenoise.sim.trajectory import SmoothTrajectory

__all__ = ["SimulatedImu", "apply_error_model", "asl_written", "simulate_imu", "write_asl"]


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
    acc_effects: list[Effect] | None = None,
) -> SimulatedImu:
    """Gyro from `effects`; accelerometer = specific force through `acc_effects` (`gyrodenoise.sim.accel`: scale
    factor, misalignment, bias random walk, bias instability) + constant bias + white noise.

    Stamps start `margin_s` after the trajectory start (the spline's ends are less reliable) and
    are exact integer nanoseconds. The error model's time 0 is the first stamp (power-on). A time offset in
    `effects` delays the accelerometer as it delays the gyro: it is the IMU's stamps that are late.
    `duration_s`: the stamps span at most this long (N samples over N - 1 periods).
    """
    _check_settings(rate_hz, duration_s, oversample, acc_noise_density, acc_bias)
    acc_effects = list(acc_effects or [])
    check_acc_effects(effects, acc_effects)
    rng = np.random.default_rng(seed)
    period_ns = int(round(1e9 / rate_hz))
    span = traj.t_end - traj.t_start - 2 * margin_s
    if duration_s is not None:
        span = min(span, duration_s)
    if span < 0:
        raise ValueError(
            f"the trajectory ({traj.t_end - traj.t_start:.3f} s) is shorter than its two margins of {margin_s} s: "
            "no IMU sample fits in it; give a longer trajectory"
        )
    n = int(np.floor(span * 1e9 / period_ns + 1e-9)) + 1
    k = np.arange(n, dtype=np.int64)
    t_ns = t0_ns + k * period_ns
    t_rel = k * (period_ns * 1e-9)  # since power-on
    t_traj = traj.t_start + margin_s + t_rel
    # centred internal grid: IMU sample k averages the period [t_k - T/2, t_k + T/2)
    m = int(oversample)
    sub = ((np.arange(m) + 0.5) / m - 0.5) * (period_ns * 1e-9)
    t_hi_rel = (t_rel[:, None] + sub[None]).ravel()
    shift = traj.t_start + margin_s
    _check_time_offsets(effects, traj, t_hi_rel[0] + shift, t_hi_rel[-1] + shift, margin_s)
    kin_hi = traj.evaluate(t_hi_rel + shift)
    sig = SignalContext(
        t=t_hi_rel,
        omega=kin_hi.omega,
        alpha=kin_hi.alpha,
        f=kin_hi.specific_force,
        rate_hz=rate_hz * m,
        kinematics_at=lambda t: traj.evaluate(t + shift),
        output_mean_of=m,
    )
    y_hi = apply_error_model(effects, sig, rng)
    gyro = y_hi.reshape(n, m, 3).mean(1)
    out_sig = SignalContext(t=t_rel, omega=gyro, alpha=np.zeros_like(gyro), f=np.zeros_like(gyro), rate_hz=rate_hz)
    for e in effects:
        if e.stage == 4:
            gyro = e.apply(out_sig, gyro, rng)
    f = sig.f.reshape(n, m, 3).mean(1)  # the time offset (stage 0) has moved the inputs both sensors see
    white = WhiteNoise(density=np.full(3, acc_noise_density)).apply(
        SignalContext(t_rel, f, f, f, rate_hz), np.zeros_like(f), rng
    )
    if acc_effects:  # drawn after everything else, so a model without them keeps every other draw
        f = apply_acc_error_model(acc_effects, sig, rng).reshape(n, m, 3).mean(1)
    acc = f + np.asarray(acc_bias) + white
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
            # only when given: a simulation without them writes the sim.json it wrote before they existed
            **({"acc_effects": [e.to_dict() for e in acc_effects]} if acc_effects else {}),
        },
    )


def _check_time_offsets(
    effects: list[Effect], traj: SmoothTrajectory, first: float, last: float, margin_s: float
) -> None:
    """One line for a time offset that reads the motion beyond the trajectory's ends (`first`, `last`: the internal
    grid's first and last times on the trajectory's clock): the spline's polynomial continuation there is no motion,
    and was taken silently (a delta meant in ms, 5 for 5 ms, gave rates of 14 rad/s)."""
    for e in effects:
        if not isinstance(e, TimeOffset):
            continue
        d = float(e.params["delta"])
        if d == 0.0:  # reads nothing beyond what the grid itself reads
            continue
        # only the overshoot the offset adds: with margin_s 0 the grid itself reaches T/2 past each end
        before = traj.t_start - (first - d) - max(0.0, traj.t_start - first)
        after = (last - d) - traj.t_end - max(0.0, last - traj.t_end)
        if max(before, after) > 1e-9:
            where = f"{before:.3g} s before its start" if before > after else f"{after:.3g} s after its end"
            raise ValueError(
                f"effect 'time_offset': delta {d:g} s reads the motion {where}, past the trajectory "
                f"([{traj.t_start:g}, {traj.t_end:g}] s), where the spline has no motion; delta is in s (5 ms is "
                f"0.005), and the samples keep margin_s ({margin_s:g} s) of motion on each side for it"
            )


def _check_settings(
    rate_hz: float, duration_s: float | None, oversample: int, acc_noise_density: float, acc_bias
) -> None:
    """One line per setting no IMU can have (they gave a ZeroDivisionError, empty arrays or NaN gyros)."""
    if isinstance(rate_hz, bool) or not (isinstance(rate_hz, int | float | np.number) and 0 < rate_hz <= 1e6):
        raise ValueError(f"rate_hz={rate_hz!r}: the IMU rate in Hz, a number above 0 and at most 1e6 (e.g. 200)")
    if duration_s is not None and not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s={duration_s!r}: seconds of IMU data, above 0 (or None: the whole trajectory)")
    if isinstance(oversample, bool) or not isinstance(oversample, int | np.integer) or oversample < 1:
        raise ValueError(f"oversample={oversample!r}: internal samples per IMU period, an integer >= 1 (e.g. 10)")
    if not (np.isfinite(acc_noise_density) and acc_noise_density >= 0):
        raise ValueError(f"acc_noise_density={acc_noise_density!r}: m/s^2/sqrt(Hz), a number >= 0")
    bias = np.asarray(acc_bias, dtype=np.float64)
    if bias.shape != (3,) or not np.isfinite(bias).all():
        raise ValueError(f"acc_bias={acc_bias!r}: three finite numbers in m/s^2")


def write_asl(folder: str | Path, sim: SimulatedImu, gt_stride: int = 1, keep_existing: bool = False) -> Path:
    """<folder>/mav0/{imu0,state_groundtruth_estimate0}/data.csv + sim.json, written atomically
    (`gyrodenoise.data.asl_write.write_sequence`)."""
    return write_sequence(
        folder,
        sim.t_ns,
        np.concatenate([sim.gyro, sim.acc], 1),
        sim.t_ns[::gt_stride],
        pose_values(sim.gt_pos[::gt_stride], sim.gt_quat_xyzw[::gt_stride]),
        extra_files={"sim.json": json.dumps(sim.meta, indent=2)},
        keep_existing=keep_existing,
    )
