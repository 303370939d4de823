"""The world's ground truth is itself a measurement: a motion-capture system samples the true pose at its
own rate, with orientation and position noise and time-stamp jitter. Whoever uses it must reconstruct
the rate from it, as with real data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gyrodenoise.testworld.motion import MotionSource


@dataclass(frozen=True)
class MocapConfig:
    rate_hz: float = 100.0  # Vicon in the EuRoC rooms; TUM-VI's mocap runs at 120 Hz
    orientation_noise_rad: float = float(np.deg2rad(0.2))  # per-axis std of a body-frame rotation error
    position_noise_m: float = 1e-3  # per-axis std
    jitter_s: float = 1e-4  # std of (capture time - stamp)


# "vicon": raw motion capture as in the EuRoC rooms; "euroc-gt": like the released EuRoC ground truth, a
# 200 Hz batch estimate whose scatter about a 15 Hz smooth replay is ~0.01 deg / 0.03 mm; "tumvi": the
# 120 Hz mocap of TUM-VI; "ideal": exact poses (isolates the trajectory reconstruction from noise)
MOCAP_PRESETS: dict[str, MocapConfig] = {
    "vicon": MocapConfig(),
    "euroc-gt": MocapConfig(200.0, float(np.deg2rad(0.01)), 3e-5, 0.0),
    "tumvi": MocapConfig(120.0, float(np.deg2rad(0.2)), 1e-3, 1e-4),
    "ideal": MocapConfig(100.0, 0.0, 0.0, 0.0),
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
    return MocapPoses(
        t=t,
        stamp_ns=t0_ns + stamp_rel,
        pos=kin.pos + dpos,
        rot=kin.rot * Rotation.from_rotvec(dtheta),
        info={
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
