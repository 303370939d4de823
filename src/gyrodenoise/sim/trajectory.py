"""Smooth trajectories and their exact derivatives: the 'truth' an IMU would have measured.

Orientation and position are least-squares B-splines (scipy `make_lsq_spline`), never raw finite
differences (those add half-sample delays and amplify noise). Orientation is a spline through
sign-continuous quaternions, normalised when evaluated; its body-frame rate follows from
w = 2 Im(q* dq/dt) / |q|^2, which holds for a non-unit q as well, so no re-projection is needed.

Conventions: R maps body to world; world z is up, gravity g = (0, 0, -9.81) m/s^2; specific force
f = R^T (a - g); quaternions scalar-last (x, y, z, w).
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline, make_lsq_spline
from scipy.spatial.transform import Rotation

from gyrodenoise.data.readers import DataFormatError, read_groundtruth
from gyrodenoise.sim.array_memo import ArrayMemo, digest

GRAVITY = np.array([0.0, 0.0, -9.80665])
# the time offset's regressor reads the rate at the same shifted times several times over (`array_memo`)
_RATES = ArrayMemo(96 << 20)


@dataclass
class Kinematics:
    """Truth at times t (s): rotation, position, and the IMU's ideal inputs in the body frame."""

    t: np.ndarray  # (N,)
    rot: np.ndarray  # (N, 3, 3) body -> world
    pos: np.ndarray  # (N, 3) m
    omega: np.ndarray  # (N, 3) rad/s, body frame
    alpha: np.ndarray  # (N, 3) rad/s^2, body frame (d omega / dt)
    acc_world: np.ndarray  # (N, 3) m/s^2
    specific_force: np.ndarray  # (N, 3) m/s^2, body frame, what an ideal accelerometer reads

    @property
    def quat_xyzw(self) -> np.ndarray:
        return Rotation.from_matrix(self.rot).as_quat()


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) scalar-last quaternions."""
    av, aw = a[..., :3], a[..., 3:]
    bv, bw = b[..., :3], b[..., 3:]
    v = aw * bv + bw * av + np.cross(av, bv)
    w = aw * bw - (av * bv).sum(-1, keepdims=True)
    return np.concatenate([v, w], axis=-1)


def _conj(q: np.ndarray) -> np.ndarray:
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """Flip signs so that consecutive quaternions are in the same hemisphere (q and -q are the same)."""
    q = np.array(q, dtype=np.float64)
    flips = np.sum(q[1:] * q[:-1], axis=1) < 0
    sign = np.concatenate([[1.0], np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)])
    return q * sign[:, None]


def _knots(t0: float, t1: float, spacing: float, k: int) -> np.ndarray:
    n = max(int(np.floor((t1 - t0) / spacing)), 1)
    inner = np.linspace(t0, t1, n + 1)[1:-1]
    return np.concatenate([[t0] * (k + 1), inner, [t1] * (k + 1)])


class SmoothTrajectory:
    """Orientation + position as B-splines of time (s); `evaluate(t)` gives exact derivatives."""

    def __init__(self, quat: BSpline, pos: BSpline, t_start: float, t_end: float, t0_ns: int = 0) -> None:
        self.quat, self.pos = quat, pos
        self.t_start, self.t_end, self.t0_ns = float(t_start), float(t_end), int(t0_ns)
        self._dq, self._ddq = quat.derivative(1), quat.derivative(2)
        self._dp, self._ddp = pos.derivative(1), pos.derivative(2)
        # names this trajectory in `_RATES`: unique across processes (an id() is reused once freed; a copy or an
        # unpickled trajectory keeps the token, and its splines with it)
        self._token = uuid.uuid4().hex

    @classmethod
    def fit(
        cls,
        t: np.ndarray,
        quat_xyzw: np.ndarray,
        pos: np.ndarray,
        knot_spacing: float = 0.05,
        degree: int = 5,
        t0_ns: int = 0,
        source: str = "trajectory",
    ) -> SmoothTrajectory:
        """Least-squares B-spline of degree `degree` with knots every `knot_spacing` s.

        The knot spacing sets the bandwidth: motion faster than ~1/(2 knot_spacing) Hz is smoothed
        away together with the ground truth's noise.
        """
        t = np.asarray(t, dtype=np.float64)
        if len(t) < 2 * (degree + 1):
            raise DataFormatError(f"{source}: {len(t)} samples are too few for a degree-{degree} spline fit.")
        knots = _knots(t[0], t[-1], knot_spacing, degree)
        # drop interior knots inside gaps (no sample between two knots breaks the LSQ conditions)
        inner = knots[degree + 1 : -degree - 1]
        if len(inner):
            idx = np.searchsorted(t, inner)
            counts = np.diff(np.concatenate([[0], idx, [len(t)]]))
            keep = np.ones(len(inner), dtype=bool)
            keep[counts[1:] == 0] = False
            knots = np.concatenate([knots[: degree + 1], inner[keep], knots[-degree - 1 :]])
        q = continuous_quaternions(quat_xyzw)
        try:
            qs = make_lsq_spline(t, q, knots, k=degree)
            ps = make_lsq_spline(t, np.asarray(pos, dtype=np.float64), knots, k=degree)
        except (ValueError, np.linalg.LinAlgError) as e:
            raise DataFormatError(
                f"{source}: smooth spline fit failed ({e}). The ground truth may have long gaps; "
                "increase the knot spacing or crop the sequence."
            ) from None
        return cls(qs, ps, t[0], t[-1], t0_ns)

    @classmethod
    def from_asl(cls, gt_path: str | Path, knot_spacing: float = 0.05, degree: int = 5) -> SmoothTrajectory:
        """Fit an ASL ground-truth file (t ns, p, q_wxyz, ...). Time 0 is the file's first stamp."""
        gt = read_groundtruth(gt_path)
        t0 = int(gt.t_ns[0])
        t = (gt.t_ns - t0) * 1e-9
        return cls.fit(t, gt.quat_xyzw, gt.pos, knot_spacing, degree, t0_ns=t0, source=str(gt_path))

    def evaluate(self, t: np.ndarray) -> Kinematics:
        t = np.asarray(t, dtype=np.float64)
        q, dq, ddq = self.quat(t), self._dq(t), self._ddq(t)
        n2, qc, omega = self._rate(q, dq)
        # d/dt [2 Im(q* dq) / |q|^2] = 2 Im(q* ddq)/|q|^2 - 2 Im(q* dq) d|q|^2/dt / |q|^4
        dn2 = 2.0 * (q * dq).sum(-1, keepdims=True)
        alpha = 2.0 * _qmul(qc, ddq)[:, :3] / n2 - omega * dn2 / n2
        rot = Rotation.from_quat(q / np.sqrt(n2)).as_matrix()
        acc = self._ddp(t)
        f = np.einsum("nji,nj->ni", rot, acc - GRAVITY)
        return Kinematics(t, rot, self.pos(t), omega, alpha, acc, f)

    @staticmethod
    def _rate(q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """|q|^2, q* and the body rate 2 Im(q* dq) / |q|^2."""
        n2 = (q * q).sum(-1, keepdims=True)
        qc = _conj(q)
        return n2, qc, 2.0 * _qmul(qc, dq)[:, :3] / n2

    def rate_mean(self, t: np.ndarray, period_s: float, nodes: int = 4) -> np.ndarray:
        """`sample_mean(t, period_s, nodes).omega` alone (the same numbers), without the orientation, position,
        acceleration and specific force: the time offset's regressor reads the rate at shifted times only."""
        t = np.asarray(t, dtype=np.float64)
        key = digest(self._token, t, float(period_s), int(nodes))
        return _RATES.get(key, lambda: self._rate_mean(t, period_s, nodes))

    def _rate_mean(self, t: np.ndarray, period_s: float, nodes: int) -> np.ndarray:
        x, w = np.polynomial.legendre.leggauss(nodes)
        rates = [self._rate(self.quat(ti), self._dq(ti))[2] for ti in (t + 0.5 * period_s * xi for xi in x)]
        return sum(wi * r for wi, r in zip(w, rates, strict=True)) / 2.0

    def sampled_at(self, t: np.ndarray, period_s: float) -> SampledKinematics:
        """`sample_mean(t, period_s)`, each field computed when it is first read (`SampledKinematics`)."""
        return SampledKinematics(self, np.asarray(t, dtype=np.float64), period_s)

    def sample_mean(self, t: np.ndarray, period_s: float, nodes: int = 4) -> Kinematics:
        """What an ideal integrating IMU samples at t: rate, angular acceleration and specific force are
        their means over [t - period/2, t + period/2] (Gauss-Legendre, `nodes` points; the simulator's and
        the test world's centred anti-alias mean), orientation and position are taken at t itself."""
        t = np.asarray(t, dtype=np.float64)
        x, w = np.polynomial.legendre.leggauss(nodes)
        parts = [self.evaluate(t + 0.5 * period_s * xi) for xi in x]

        def mean(field: str) -> np.ndarray:
            return sum(wi * getattr(k, field) for wi, k in zip(w, parts, strict=True)) / 2.0

        mid = self.evaluate(t)
        return Kinematics(t, mid.rot, mid.pos, mean("omega"), mean("alpha"), mean("acc_world"), mean("specific_force"))


class SampledKinematics:
    """The sampled truth at times t (`SmoothTrajectory.sample_mean`), computed lazily: `omega` alone costs a
    fifth of the whole (`rate_mean`); any other field computes them all once, and `omega` read after it is
    taken from them (the same numbers) rather than computed again."""

    def __init__(self, traj: SmoothTrajectory, t: np.ndarray, period_s: float) -> None:
        self.t, self._traj, self._period = t, traj, period_s

    @cached_property
    def omega(self) -> np.ndarray:
        if "_all" in self.__dict__:
            return self._all.omega
        return self._traj.rate_mean(self.t, self._period)

    @cached_property
    def _all(self) -> Kinematics:
        return self._traj.sample_mean(self.t, self._period)

    def __getattr__(self, name: str):  # rot, pos, alpha, acc_world, specific_force
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._all, name)


# ------------------------------------------------------------------ procedural trajectories


def _random_smooth(rng: np.random.Generator, t: np.ndarray, n_terms: int, f_lo: float, f_hi: float) -> np.ndarray:
    """Sum of sinusoids with random frequencies and phases, unit RMS-ish amplitude, shape (N,)."""
    f = rng.uniform(f_lo, f_hi, n_terms)
    ph = rng.uniform(0, 2 * np.pi, n_terms)
    a = rng.uniform(0.5, 1.0, n_terms) / np.sqrt(n_terms / 2)
    return (a[None] * np.sin(2 * np.pi * f[None] * t[:, None] + ph[None])).sum(1)


def drone_trajectory(duration_s: float, seed: int, aggressiveness: float = 1.0) -> SmoothTrajectory:
    """EuRoC-like flight in a room: position wanders in ~4 x 4 x 1.5 m, the thrust axis (body z)
    follows the commanded acceleration (so attitude changes with it), yaw wanders."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s + 1e-9, 0.01)
    pos = np.stack(
        [
            1.6 * _random_smooth(rng, t, 6, 0.02, 0.25 * aggressiveness),
            1.6 * _random_smooth(rng, t, 6, 0.02, 0.25 * aggressiveness),
            1.2 + 0.5 * _random_smooth(rng, t, 4, 0.02, 0.2 * aggressiveness),
        ],
        axis=1,
    )
    pos_spline = SmoothTrajectory.fit(t, np.tile([0, 0, 0, 1.0], (len(t), 1)), pos, 0.1).pos
    acc = pos_spline.derivative(2)(t)
    thrust = acc - GRAVITY
    z_b = thrust / np.linalg.norm(thrust, axis=1, keepdims=True)
    yaw = 1.5 * aggressiveness * _random_smooth(rng, t, 5, 0.01, 0.15 * aggressiveness)
    heading = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1)
    y_b = np.cross(z_b, heading)
    y_b /= np.linalg.norm(y_b, axis=1, keepdims=True)
    x_b = np.cross(y_b, z_b)
    rot = np.stack([x_b, y_b, z_b], axis=2)
    quat = Rotation.from_matrix(rot).as_quat()
    return SmoothTrajectory.fit(t, quat, pos, knot_spacing=0.1)


def handheld_trajectory(duration_s: float, seed: int, rate_scale: float = 1.0) -> SmoothTrajectory:
    """Hand-held motion: slow walk, large rotations about every axis (rich excitation: attitude
    changes, angular accelerations, rates up to a few rad/s)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s + 1e-9, 0.01)
    pos = np.stack(
        [
            1.0 * _random_smooth(rng, t, 5, 0.02, 0.3),
            1.0 * _random_smooth(rng, t, 5, 0.02, 0.3),
            1.3 + 0.3 * _random_smooth(rng, t, 5, 0.05, 0.8),
        ],
        axis=1,
    )
    roll = 0.7 * _random_smooth(rng, t, 6, 0.03, 0.5 * rate_scale)
    pitch = 0.5 * _random_smooth(rng, t, 6, 0.03, 0.5 * rate_scale)
    yaw = 1.5 * _random_smooth(rng, t, 6, 0.01, 0.3 * rate_scale)
    quat = Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], axis=1)).as_quat()
    return SmoothTrajectory.fit(t, quat, pos, knot_spacing=0.05)


def yaw_only_trajectory(duration_s: float, seed: int) -> SmoothTrajectory:
    """Level turntable: rotation about the vertical only, no translation. The specific force in the
    body frame stays constant, so g-sensitivity cannot be told apart from a constant bias."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s + 1e-9, 0.01)
    yaw = 3.0 * _random_smooth(rng, t, 6, 0.02, 0.5)
    quat = Rotation.from_euler("z", yaw[:, None]).as_quat()
    return SmoothTrajectory.fit(t, quat, np.zeros((len(t), 3)), knot_spacing=0.05)


def constant_rate_trajectory(
    duration_s: float, rate_rad_s: tuple[float, float, float] = (0.3, -0.2, 0.5)
) -> SmoothTrajectory:
    """Constant body rate, no translation: no angular acceleration, so a time offset is invisible."""
    t = np.arange(0.0, duration_s + 1e-9, 0.01)
    quat = Rotation.from_rotvec(np.outer(t, rate_rad_s)).as_quat()
    return SmoothTrajectory.fit(t, quat, np.zeros((len(t), 3)), knot_spacing=0.05)


TRAJECTORIES = {
    "drone": drone_trajectory,
    "handheld": handheld_trajectory,
    "yaw_only": yaw_only_trajectory,
}
