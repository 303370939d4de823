"""Tiny synthetic sequences in the ASL folder layout, and a subprocess training run, for tests that train."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


def write_asl_sequence(folder: Path, seconds: float, seed: int, rate_hz: float = 200.0) -> None:
    """A few seconds of smooth rotation: ground truth and a biased, noisy IMU in the ASL layout."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz) + 1
    t = np.arange(n) / rate_hz
    f = rng.uniform(0.2, 0.8, 3)
    w = np.stack(
        [
            0.6 * np.sin(2 * np.pi * f[0] * t),
            0.4 * np.cos(2 * np.pi * f[1] * t),
            0.3 * np.sin(2 * np.pi * f[2] * t + 1.0),
        ],
        axis=1,
    )
    rots = [Rotation.identity()]
    for k in range(1, n):
        rots.append(rots[-1] * Rotation.from_rotvec(w[k] / rate_hz))
    R = Rotation.concatenate(rots)
    gravity = np.array([0.0, 0.0, 9.81])
    acc = R.inv().apply(gravity) + 0.02 * rng.standard_normal((n, 3))
    gyro = w + np.array([0.01, -0.02, 0.005]) + 1e-3 * rng.standard_normal((n, 3))
    t_ns = (1_403_636_579_758_555_392 + np.round(t * 1e9)).astype(np.int64)
    q = R.as_quat()  # x y z w
    pos = np.stack([np.sin(t), np.cos(t), 0.1 * t], axis=1)

    imu_dir, gt_dir = folder / "mav0" / "imu0", folder / "mav0" / "state_groundtruth_estimate0"
    imu_dir.mkdir(parents=True)
    gt_dir.mkdir(parents=True)
    with open(imu_dir / "data.csv", "w") as fh:
        fh.write(
            "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
            "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
        )
        for k in range(n):
            fh.write(f"{t_ns[k]}," + ",".join(f"{v:.9f}" for v in (*gyro[k], *acc[k])) + "\n")
    with open(gt_dir / "data.csv", "w") as fh:
        fh.write("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n")
        for k in range(n):
            vals = (*pos[k], q[k, 3], q[k, 0], q[k, 1], q[k, 2])
            fh.write(f"{t_ns[k]}," + ",".join(f"{v:.9f}" for v in vals) + "\n")


# a network and a schedule small enough to train on 6-s synthetic sequences in about a second
TINY_TRAINING = [
    "dataset.train_duration_s=4",
    "dataset.window=256",
    "model.channels=[4,8]",
    "model.dilations=[1,2]",
    "trainer.max_epochs=1",
    "trainer.accelerator=cpu",
    "logger=none",
]


def run_train(args: list[str], cwd: Path, timeout: int = 240) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "gyrodenoise.train", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert proc.returncode == 0, f"train failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"
    return proc
