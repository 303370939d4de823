"""The world's ground truth is itself a measurement: a motion-capture system samples the true pose at its
own rate, with orientation and position noise and time-stamp jitter. Whoever uses it must reconstruct
the rate from it, as with real data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gyrodenoise.testworld.motion import MotionSource


@dataclass(frozen=True)
class MocapConfig:
    rate_hz: float = 100.0  # Vicon in the EuRoC rooms; TUM-VI's mocap runs at 120 Hz
    orientation_noise_rad: float = float(np.deg2rad(0.2))  # per-axis std of a body-frame rotation error
    position_noise_m: float = 1e-3  # per-axis std
    jitter_s: float = 1e-4  # std of (capture time - stamp)
    # > 0: the written orientation is a fused estimate, not the tracker's: the gyro integrated and pulled toward
    # the tracker with this time constant (a complementary filter), so it follows the gyro, noise and errors
    # included, above ~1 / (2 pi tau) Hz, as a batch estimate that fuses the IMU does (EuRoC's Machine Hall)
    fuse_tau_s: float = 0.0
    # > 0: occlusions (the tracker loses the body) start at this rate per minute, each lasting a time drawn
    # uniformly from occlusion_s; no pose is written inside one (TUM-VI's mocap has 0.04-2 s gaps)
    occlusions_per_min: float = 0.0
    occlusion_s: tuple[float, float] = (0.3, 2.0)


# "vicon": raw motion capture as in the EuRoC rooms; "euroc-gt": like the released EuRoC ground truth, a
# 200 Hz batch estimate whose scatter about a 15 Hz smooth replay is ~0.01 deg / 0.03 mm; "tumvi": the
# 120 Hz mocap of TUM-VI; "ideal": exact poses (isolates the trajectory reconstruction from noise); "euroc-fused":
# a Vicon-like tracker fused with the gyro (5-s complementary filter) and written at 200 Hz; "tumvi-occluded":
# "tumvi" with occlusions (4 per minute, 0.3-2 s each)
MOCAP_PRESETS: dict[str, MocapConfig] = {
    "vicon": MocapConfig(),
    "euroc-gt": MocapConfig(200.0, float(np.deg2rad(0.01)), 3e-5, 0.0),
    "tumvi": MocapConfig(120.0, float(np.deg2rad(0.2)), 1e-3, 1e-4),
    "ideal": MocapConfig(100.0, 0.0, 0.0, 0.0),
    "euroc-fused": MocapConfig(200.0, float(np.deg2rad(0.2)), 1e-3, 1e-4, fuse_tau_s=5.0),
    "tumvi-occluded": MocapConfig(120.0, float(np.deg2rad(0.2)), 1e-3, 1e-4, occlusions_per_min=4.0),
}


@dataclass
class MocapPoses:
    t: np.ndarray  # (M,) true capture times, s (motion time)
    stamp_ns: np.ndarray  # (M,) written stamps, int64
    pos: np.ndarray  # (M, 3) measured
    rot: Rotation  # (M,) measured body -> world
    info: dict


def measure_poses(
    motion: MotionSource,
    cfg: MocapConfig,
    t_first: float,
    t_last: float,
    t0_ns: int,
    rng: np.random.Generator,
) -> MocapPoses:
    """Poses stamped on a regular grid from `t_first` to `t_last`; each is captured at stamp + jitter."""
    if cfg.rate_hz <= 0 or cfg.orientation_noise_rad < 0 or cfg.position_noise_m < 0 or cfg.jitter_s < 0:
        raise ValueError(f"bad mocap configuration {cfg}: rate must be positive, noise levels non-negative")
    period_ns = int(round(1e9 / cfg.rate_hz))
    first_ns = int(round(t_first * 1e9))
    n = int((t_last - t_first) * 1e9 // period_ns) + 1
    stamp_rel = first_ns + np.arange(n, dtype=np.int64) * period_ns
    jitter = np.clip(rng.normal(0.0, cfg.jitter_s, n), -0.4 * period_ns * 1e-9, 0.4 * period_ns * 1e-9)
    t = np.clip(stamp_rel * 1e-9 + jitter, motion.t_start, motion.t_end)
    kin = motion.evaluate(t)
    dtheta = cfg.orientation_noise_rad * rng.normal(size=(n, 3))
    dpos = cfg.position_noise_m * rng.normal(size=(n, 3))
    seen, occlusions = np.ones(n, dtype=bool), []
    if cfg.occlusions_per_min > 0:  # drawn after the noise: the other presets' draws are unchanged
        occlusions = occlusion_spans(t_first, t_last, cfg.occlusions_per_min, cfg.occlusion_s, rng)
        for a, b in occlusions:
            seen &= ~((stamp_rel * 1e-9 > a) & (stamp_rel * 1e-9 < b))
    return MocapPoses(
        t=t[seen],
        stamp_ns=t0_ns + stamp_rel[seen],
        pos=(kin.pos + dpos)[seen],
        rot=(kin.rot * Rotation.from_rotvec(dtheta))[seen],
        info={
            "occlusions_s": occlusions,
            "rate_hz": cfg.rate_hz,
            "orientation_noise_deg": float(np.rad2deg(cfg.orientation_noise_rad)),
            "position_noise_m": cfg.position_noise_m,
            "stamp_jitter_s": cfg.jitter_s,
            "orientation_noise_model": "R_meas = R_true exp(n), n ~ N(0, sigma^2 I) in the body frame",
            # what was actually drawn, so that a test can compare the file with the configuration
            "realised_orientation_noise_deg": np.rad2deg(dtheta.std(0)).tolist(),
            "realised_position_noise_m": dpos.std(0).tolist(),
            "realised_jitter_s": float(jitter.std()),
        },
    )


def occlusion_spans(
    t_first: float, t_last: float, per_min: float, length_s: tuple[float, float], rng: np.random.Generator
) -> list[list[float]]:
    """[start, end] s of occlusions: starts a Poisson process of `per_min` per minute, lengths uniform in
    `length_s`; none within 1 s of either end (a recording starts and ends with the body in view)."""
    spans, t = [], t_first + 1.0
    while True:
        t += rng.exponential(60.0 / per_min)
        end = t + rng.uniform(*length_s)
        if end > t_last - 1.0:
            return spans
        spans.append([float(t), float(end)])
        t = end


def fuse_with_gyro(
    poses: MocapPoses, t: np.ndarray, gyro: np.ndarray, tau_s: float, t_stamps: np.ndarray
) -> MocapPoses:
    """The poses with their orientation replaced by a fused estimate: a complementary filter with gyro-bias
    estimation (proportional gain 1 / tau, integral gain 1 / (4 tau^2): critically damped) of the gyro (N, 3)
    rad/s sampled at motion times t (N,) and the tracker's orientation, e = Log(R^T R_tracker):
    b <- b - k_i e dt, R_k = R_k-1 exp(((w_k-1 + w_k) / 2 - b) dt) exp(k_p dt e).
    Run twice, the second pass starting from the first's bias (a batch estimate knows the bias from the
    start). Read at the poses' stamps `t_stamps` (motion time: an estimator's output is stamped by its own
    clock, so the tracker's capture jitter reaches it only through the slow correction). Position is left as
    measured. The tracker's noise enters the rate with a PSD ~1 / tau^2 times its own angle PSD."""
    if tau_s <= 0:
        raise ValueError(f"fuse_tau_s={tau_s}: must be positive")
    inside = (t >= poses.t[0]) & (t <= poses.t[-1])
    ti, wi = t[inside], gyro[inside]
    tracker = Slerp(poses.t, poses.rot)(ti)
    k_p, k_i = 1.0 / tau_s, 1.0 / (4.0 * tau_s**2)
    # one step per IMU sample in plain floats (scalar-last quaternions): a Rotation object per step took ~40x longer
    target, dts = [tuple(q) for q in tracker.as_quat().tolist()], np.diff(ti).tolist()
    rates = [tuple(w) for w in (0.5 * (wi[1:] + wi[:-1])).tolist()]  # trapezoid: the samples taken as point values
    bias = (0.0, 0.0, 0.0)
    for _ in range(2):
        r = target[0]
        fused = [r]
        for dt, w, q in zip(dts, rates, target[1:], strict=True):  # a causal filter
            e = _log(_mul(_conj(r), q))
            bias = tuple(b - k_i * dt * x for b, x in zip(bias, e, strict=True))
            step = tuple((wx - b) * dt for wx, b in zip(w, bias, strict=True))
            r = _unit(_mul(_mul(r, _exp(step)), _exp(tuple(k_p * dt * x for x in e))))
            fused.append(r)
    rot = Slerp(ti, Rotation.from_quat(fused))(np.clip(t_stamps, ti[0], ti[-1]))
    info = {**poses.info, "fused_with_gyro_tau_s": tau_s, "fused_final_bias_rad_s": list(bias)}
    return MocapPoses(poses.t, poses.stamp_ns, poses.pos, rot, info)


# scalar-last unit quaternions as 4-tuples of floats, for the fusion's per-sample loop


def _mul(a: tuple, b: tuple) -> tuple:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _unit(q: tuple) -> tuple:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _conj(q: tuple) -> tuple:
    return (-q[0], -q[1], -q[2], q[3])


def _exp(v: tuple) -> tuple:
    """The rotation of rotation vector v (rad)."""
    angle = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    # sin(angle / 2) / angle, by its series near 0 (as scipy's from_rotvec)
    s = 0.5 - angle * angle / 48.0 if angle < 1e-3 else math.sin(0.5 * angle) / angle
    return (v[0] * s, v[1] * s, v[2] * s, math.cos(0.5 * angle))


def _log(q: tuple) -> tuple:
    """The rotation vector (rad, angle in [0, pi]) of unit quaternion q."""
    x, y, z, w = q if q[3] >= 0 else (-q[0], -q[1], -q[2], -q[3])
    n = math.sqrt(x * x + y * y + z * z)
    angle = 2.0 * math.atan2(n, w)
    a2 = angle * angle
    s = 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0 if angle < 1e-3 else angle / n  # angle / sin(angle / 2)
    return (x * s, y * s, z * s)
