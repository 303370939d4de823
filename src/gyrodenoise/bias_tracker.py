"""A causal gyro-bias estimate from gravity, for a corrected gyro that is still integrated open loop.

Why: on EuRoC nearly all of the attitude error left after the denoiser is one constant gyro bias per flight,
mostly its horizontal part (reports/accuracy.md, "What is left of the error once a flight's gyro bias is
known"), and gravity makes that part observable over time. `GravityBiasTracker` is a Mahony-form observer of
the gravity direction in the body frame u with a bias state b:

    e = (a / |a|) x u,   w_c = w - b + k_P e,   u <- u rotated by -w_c dt,   b <- b - k_I e dt

(Mahony, Hamel, Pflimlin 2008, the "passive" complementary filter reduced to one reference direction).
Its output is w - b: at sample n it uses b after samples 0..n-1 only, so it can run on a live stream. The
attitude stays the open-loop integration of that output; the observer's own tilt u is never used for it.
Only the bias components that gravity can see over the flight are corrected: about the vertical the
accelerometer says nothing, so b stays where it was there.

Conventions (DESIGN.md): gyro rad/s and accelerometer m/s^2 in the IMU body frame, float64, dt[n] = t[n] -
t[n-1] (dt[0] unused), the gyro at sample n drives the step from n-1 to n as in `so3.integrate_gyro`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline

if TYPE_CHECKING:
    from gyrodenoise.data.sequence import Sequence

MIN_ACC_NORM = 1e-6  # m/s^2: below this the accelerometer has no direction (free fall, a zeroed sample)


@dataclass(frozen=True)
class GravityBiasTracker:
    """Gains k_p (1/s, tilt correction) and k_i (1/s^2, bias integration); both >= 0."""

    k_p: float = 0.1
    k_i: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("k_p", "k_i"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"GravityBiasTracker: {name} must be a finite number >= 0, got {value!r}")

    def bias(self, gyro: np.ndarray, acc: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """(N, 3) rad/s: the bias estimate applied at each sample (row n uses samples 0..n-1 only)."""
        return track_bias(gyro, acc, dt, np.array([self.k_p]), np.array([self.k_i]))[0]

    def correct(self, gyro: np.ndarray, acc: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """(N, 3) rad/s: gyro minus the causal bias estimate."""
        return np.asarray(gyro, dtype=np.float64) - self.bias(gyro, acc, dt)


def track_bias(gyro: np.ndarray, acc: np.ndarray, dt: np.ndarray, k_p: np.ndarray, k_i: np.ndarray) -> np.ndarray:
    """(G, N, 3): the tracker's bias estimates for G gain pairs (k_p, k_i: (G,) arrays)."""
    gyro, acc, dt = _checked(gyro, acc, dt)
    k_p, k_i = np.atleast_1d(np.asarray(k_p, dtype=np.float64)), np.atleast_1d(np.asarray(k_i, dtype=np.float64))
    if k_p.shape != k_i.shape:
        raise ValueError(f"track_bias: {len(k_p)} k_p values but {len(k_i)} k_i values")
    up = (acc / np.linalg.norm(acc, axis=1, keepdims=True)).tolist()
    gyro_rows, dt_list = gyro.tolist(), dt.tolist()
    return np.stack([_one_pass(gyro_rows, up, dt_list, float(p), float(i)) for p, i in zip(k_p, k_i, strict=True)])


def _one_pass(gyro: list, up: list, dt: list, k_p: float, k_i: float) -> np.ndarray:
    """One observer over the samples, in plain floats: a 3-vector per step is faster in Python than in numpy."""
    out = np.zeros((len(gyro), 3))
    ux, uy, uz = up[0] if up else (0.0, 0.0, 1.0)
    bx = by = bz = 0.0
    for n in range(1, len(gyro)):
        out[n] = (bx, by, bz)
        ax, ay, az = up[n - 1]
        ex, ey, ez = ay * uz - az * uy, az * ux - ax * uz, ax * uy - ay * ux  # e = (a/|a|) x u
        h = dt[n]
        wx, wy, wz = gyro[n]
        # rotate u by -w_c h (Rodrigues), w_c = w - b + k_P e
        rx, ry, rz = -(wx - bx + k_p * ex) * h, -(wy - by + k_p * ey) * h, -(wz - bz + k_p * ez) * h
        angle = math.sqrt(rx * rx + ry * ry + rz * rz)
        if angle > 0.0:
            kx, ky, kz = rx / angle, ry / angle, rz / angle
            c, s = math.cos(angle), math.sin(angle)
            kdu = (kx * ux + ky * uy + kz * uz) * (1.0 - c)
            ux, uy, uz = (
                ux * c + (ky * uz - kz * uy) * s + kx * kdu,
                uy * c + (kz * ux - kx * uz) * s + ky * kdu,
                uz * c + (kx * uy - ky * ux) * s + kz * kdu,
            )
            norm = math.sqrt(ux * ux + uy * uy + uz * uz)  # against rounding drift
            ux, uy, uz = ux / norm, uy / norm, uz / norm
        bx, by, bz = bx - k_i * ex * h, by - k_i * ey * h, bz - k_i * ez * h
    return out


def accelerometer_offset(seq: Sequence, spline_step: int = 20, edge_s: float = 1.0, g: float = 9.81) -> np.ndarray:
    """(3,) m/s^2: a flight's constant accelerometer offset in the body frame against its ground truth, the per-axis
    median over ground-truth-valid samples (the first and last `edge_s` left out) of a - R^T (p'' + g e_z).

    Why: the tracker reads the accelerometer's direction as gravity's, and a constant offset of ~0.1 m/s^2 is a tilt
    of ~0.6 deg that, as the body yaws, an observer may explain with a gyro bias that is not there. Feeding the
    tracker a - offset was measured on EuRoC (round 9, reports/accuracy.md) and not adopted. p'' comes from a cubic
    spline (scipy) through every `spline_step`-th ground-truth position, which smooths the mocap noise that a second
    derivative would amplify; rot is body-to-world, pos in the world frame. g = 9.81 is the value round 9 ran with (the
    simulator uses the standard 9.80665): the 0.003 m/s^2 between them is far below the ~0.1 m/s^2 offsets measured.
    """
    t = np.asarray(seq.t, dtype=np.float64)
    keep = np.asarray(seq.gt_mask, dtype=bool) & (t >= t[0] + edge_s) & (t <= t[-1] - edge_s)
    knots = np.flatnonzero(seq.gt_mask)[::spline_step]
    if keep.sum() == 0 or len(knots) < 4:
        raise ValueError(
            f"accelerometer_offset: {getattr(seq, 'name', 'sequence')} has too little ground truth "
            f"({int(np.sum(seq.gt_mask))} valid samples) to fit an offset; use a longer flight"
        )
    acc_world = CubicSpline(t[knots], seq.pos[knots])(t[keep], 2) + np.array([0.0, 0.0, g])
    specific_force = np.einsum("nji,nj->ni", seq.rot[keep], acc_world)  # R^T (p'' + g e_z)
    return np.median(np.asarray(seq.acc)[keep] - specific_force, axis=0)


def _checked(gyro: np.ndarray, acc: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    gyro, acc, dt = (np.asarray(x, dtype=np.float64) for x in (gyro, acc, dt))
    for name, x in (("gyro", gyro), ("acc", acc)):
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"bias tracker: {name} must be (N, 3), got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            row = int(np.argmax(~np.all(np.isfinite(x), axis=1)))
            raise ValueError(f"bias tracker: {name} has a non-finite value at sample {row}")
    if dt.shape != (len(gyro),) or len(acc) != len(gyro):
        raise ValueError(f"bias tracker: gyro {gyro.shape}, acc {acc.shape} and dt {dt.shape} must have N rows")
    if len(gyro) and not np.all(np.isfinite(dt[1:]) & (dt[1:] > 0)):
        raise ValueError("bias tracker: dt must be positive and finite after the first sample (sorted timestamps)")
    small = np.linalg.norm(acc, axis=1) < MIN_ACC_NORM
    if np.any(small):
        raise ValueError(
            f"bias tracker: the accelerometer is (near) zero at sample {int(np.argmax(small))}; gravity's direction "
            "is needed there (check the accelerometer columns and units, m/s^2)"
        )
    return gyro, acc, dt
