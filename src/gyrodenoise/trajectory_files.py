"""Trajectories as TUM text files (`t tx ty tz qx qy qz qw`), the format evo and rpg_trajectory_evaluation read.

Stamps are printed exactly from the integer nanoseconds of the IMU clock (float64 absolute seconds lose ~100 ns).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def tum_text(t_ns: np.ndarray, R: np.ndarray, comment: str, pos: np.ndarray | None = None) -> str:
    """One line per sample after a `# comment` line; translation `pos` (m), or zero for an orientation-only
    estimate."""
    q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    trans = ["0 0 0"] * len(q) if pos is None else [f"{a:.6f} {b:.6f} {c:.6f}" for a, b, c in np.asarray(pos).tolist()]
    lines = [f"# t[s] tx ty tz qx qy qz qw ({comment})"]
    for t, xyz, (x, y, z, w) in zip(np.asarray(t_ns).tolist(), trans, q.tolist(), strict=True):
        lines.append(f"{t // 1_000_000_000}.{t % 1_000_000_000:09d} {xyz} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
    return "\n".join(lines) + "\n"
