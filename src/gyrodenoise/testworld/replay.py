"""A real EuRoC ground truth replayed as smooth continuous-time motion.

The recorded poses are resampled to a uniform grid (SLERP, linear position), low-passed with a zero-phase
Butterworth filter (quaternion components on one hemisphere, then renormalised; positions per axis) so that
the derivatives are physically smooth, and interpolated by scipy's RotationSpline (cubic in the rotation
vector, C2; its first derivative is the body-frame rate) and a C2 CubicSpline for the position. This is a
different function family from the workflow's least-squares B-spline fit, on purpose.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline, Slerp

from gyrodenoise.testworld.asl import read_asl_pose
from gyrodenoise.testworld.motion import Kinematics

EDGE_S = 1.0  # dropped at each end: the zero-phase filter's start-up transients live there
GAP_FACTOR = 5.0  # a step longer than this many median periods is a gap


def default_euroc_root() -> Path:
    env = os.environ.get("GYRODENOISE_DATA")
    return Path(env) / "euroc" if env else Path.cwd().parent / "shared" / "data" / "euroc"


class EurocReplay:
    """Smooth motion through a recorded ASL ground truth (`<root>/<name>/mav0/state_groundtruth_estimate0`)."""

    def __init__(
        self,
        name: str,
        root: str | Path | None = None,
        cutoff_hz: float = 15.0,
        grid_hz: float = 200.0,
        duration: float | None = None,
    ) -> None:
        root = Path(root) if root is not None else default_euroc_root()
        path = root / name / "mav0" / "state_groundtruth_estimate0" / "data.csv"
        if not path.is_file():
            raise FileNotFoundError(
                f"{path} not found: trajectory euroc:{name} needs the EuRoC ASL folder "
                "(pass --euroc-root, or set GYRODENOISE_DATA to the folder holding euroc/)"
            )
        if not 0 < cutoff_hz < grid_hz / 2:
            raise ValueError(f"cutoff_hz={cutoff_hz} must lie in (0, grid_hz / 2 = {grid_hz / 2})")
        self.name, self.path, self.cutoff_hz, self.grid_hz = name, path, cutoff_hz, grid_hz
        t_ns, pos, rot = read_asl_pose(path)
        t_ns, pos, rot = _longest_gap_free(t_ns, pos, rot)
        self.t0_ns = int(t_ns[0])
        t = (t_ns - t_ns[0]) * 1e-9
        grid = np.arange(0.0, t[-1], 1.0 / grid_hz)
        if duration is not None:
            grid = grid[grid <= duration + 2 * EDGE_S]
        if len(grid) < 4 * grid_hz * EDGE_S:
            raise ValueError(f"{path}: too short after removing gaps ({t[-1]:.1f} s)")
        q = Slerp(t, rot)(grid).as_quat()
        q = _one_hemisphere(q)
        p = np.stack([np.interp(grid, t, pos[:, i]) for i in range(3)], axis=1)
        sos = signal.butter(4, cutoff_hz, fs=grid_hz, output="sos")
        q = signal.sosfiltfilt(sos, q, axis=0)
        p = signal.sosfiltfilt(sos, p, axis=0)
        self.rot_spline = RotationSpline(grid, Rotation.from_quat(q / np.linalg.norm(q, axis=1, keepdims=True)))
        self.pos_spline = CubicSpline(grid, p)
        self.t_start, self.t_end = float(grid[0] + EDGE_S), float(grid[-1] - EDGE_S)

    def evaluate(self, t: np.ndarray) -> Kinematics:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if (t < self.t_start - EDGE_S).any() or (t > self.t_end + EDGE_S).any():
            raise ValueError(f"times outside the replayed span [{self.t_start:.3f}, {self.t_end:.3f}] s")
        return Kinematics(
            t=t,
            rot=self.rot_spline(t),
            omega=self.rot_spline(t, 1),  # RotationSpline: R(t) = R_i exp(theta(t)), so this is body-frame
            alpha=self.rot_spline(t, 2),
            pos=self.pos_spline(t),
            acc=self.pos_spline(t, 2),
        )

    def describe(self) -> dict:
        return {
            "kind": "euroc",
            "source": self.name,
            "source_file": str(self.path),
            "source_t0_ns": self.t0_ns,
            "smoothing": f"zero-phase 4th-order Butterworth, {self.cutoff_hz:g} Hz, on {self.grid_hz:g} Hz "
            "resampled quaternion components and positions",
            "cutoff_hz": self.cutoff_hz,
            "interpolation": "scipy RotationSpline (rotation), CubicSpline (position)",
            "duration_s": self.t_end - self.t_start,
        }


def _one_hemisphere(q: np.ndarray) -> np.ndarray:
    """Flip signs so that consecutive quaternions have a positive dot product: q(t) is then continuous."""
    flips = np.concatenate([[1.0], np.sign(np.einsum("ij,ij->i", q[1:], q[:-1]))])
    flips[flips == 0] = 1.0
    return q * np.cumprod(flips)[:, None]


def _longest_gap_free(t_ns: np.ndarray, pos: np.ndarray, rot: Rotation) -> tuple[np.ndarray, np.ndarray, Rotation]:
    d = np.diff(t_ns)
    breaks = np.flatnonzero(d > GAP_FACTOR * np.median(d))
    if len(breaks) == 0:
        return t_ns, pos, rot
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks + 1, [len(t_ns)]])
    k = int(np.argmax(ends - starts))
    s = slice(starts[k], ends[k])
    return t_ns[s], pos[s], rot[s]
