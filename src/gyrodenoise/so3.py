"""SO(3) maths shared by the loss, the evaluation and the simulator.

Conventions (see DESIGN.md):
- A rotation matrix R maps the IMU (body) frame to the world frame.
- Integration is right multiplication by a body-frame increment: R_n = R_{n-1} exp(w_n dt_n),
  where dt_n = t_n - t_{n-1} and w_n is the rate sample taken at t_n.
- Quaternions inside gyrodenoise are scalar-last (x, y, z, w), the order of scipy. File readers
  convert from their file's order (ASL: w, x, y, z) at the edge.

The torch functions work on any leading batch shape and are differentiable; the loss calls them in
float64. `exp` and `log` stay accurate near the identity (Taylor branches) and near pi (log goes
through a quaternion chosen by Shepperd's method, never through acos of the trace).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from gyrodenoise.arrays import as_rows

_SMALL = 1e-6  # below this angle (rad) the Taylor branches are exact to float64 precision
# log(check=True): how far from a rotation a matrix may be, per dtype (2000 float32 steps drift ~1e-4)
_ROTATION_TOL = {torch.float64: 1e-6, torch.float32: 1e-3}
MAX_STEP_S = 1.0  # integrate_gyro: a median step above this is stamps or nanoseconds, not periods (IMUs: >= 5 Hz)


def _linear_maps() -> dict[str, torch.Tensor]:
    """Constant matrices that turn index-by-index formulas into one matmul each.

    Indexing one entry at a time (R[..., i, j]) costs an operator, and its gradient a zero-filled copy of
    the whole tensor, per entry: the training loss's log and exp were ~900 operators per step, which is
    what a GPU step waits for. As matmuls with these constants they are ~450 (same values to float64
    rounding: tests/test_so3.py checks them against scipy).
    """

    def e(i: int, j: int) -> torch.Tensor:  # R[i, j] as a row-major (9,) selector
        return torch.nn.functional.one_hot(torch.tensor(3 * i + j), 9).double()

    hat = torch.zeros(3, 9, dtype=torch.float64)  # hat(phi).flatten() == phi @ hat
    for i, j, k, sign in [(0, 1, 2, -1), (0, 2, 1, 1), (1, 0, 2, 1), (1, 2, 0, -1), (2, 0, 1, -1), (2, 1, 0, 1)]:
        hat[k, 3 * i + j] = sign
    tr = e(0, 0) + e(1, 1) + e(2, 2)
    # Shepperd's branches: branch b (largest of w, x, y, z) gives 4 q_b (w, x, y, z) = R.flatten() @ A_b + c_b
    branches = [
        [tr, e(2, 1) - e(1, 2), e(0, 2) - e(2, 0), e(1, 0) - e(0, 1)],
        [e(2, 1) - e(1, 2), 2 * e(0, 0) - tr, e(0, 1) + e(1, 0), e(0, 2) + e(2, 0)],
        [e(0, 2) - e(2, 0), e(0, 1) + e(1, 0), 2 * e(1, 1) - tr, e(1, 2) + e(2, 1)],
        [e(1, 0) - e(0, 1), e(0, 2) + e(2, 0), e(1, 2) + e(2, 1), 2 * e(2, 2) - tr],
    ]
    quat = torch.stack([col for branch in branches for col in branch], dim=1)  # (9, 16)
    quat_const = torch.eye(4, dtype=torch.float64).flatten()  # the 1 of "1 + tr" and "1 + 2 R_kk - tr"
    choice = torch.stack([tr, e(0, 0), e(1, 1), e(2, 2)], dim=1)  # (9, 4): which q_b^2 is largest
    return {"hat": hat, "quat": quat, "quat_const": quat_const, "choice": choice}


_MAPS = _linear_maps()
_MAPS_ON: dict[tuple, dict[str, torch.Tensor]] = {}


def _maps(like: torch.Tensor) -> dict[str, torch.Tensor]:
    """The constants on `like`'s device and dtype, copied once (a copy per call would sync a GPU)."""
    key = (like.dtype, like.device)
    if key not in _MAPS_ON:
        _MAPS_ON[key] = {k: v.to(dtype=like.dtype, device=like.device) for k, v in _MAPS.items()}
    return _MAPS_ON[key]


def _torch_only(x: object, what: str, numpy_way: str) -> None:
    if not isinstance(x, torch.Tensor):
        raise TypeError(
            f"so3.{what} works on torch tensors (the loss's differentiable path), got {type(x).__name__}: pass "
            f"torch.as_tensor(x), or for numpy use scipy: {numpy_way}"
        )


def hat(phi: torch.Tensor) -> torch.Tensor:
    """Skew-symmetric matrix of (..., 3) vectors: hat(a) @ b == cross(a, b)."""
    return (phi @ _maps(phi)["hat"]).unflatten(-1, (3, 3))


def exp(phi: torch.Tensor) -> torch.Tensor:
    """Exponential map (..., 3) rotation vectors -> (..., 3, 3) rotation matrices (Rodrigues).

    R = I + a hat(phi) + b hat(phi)^2 with hat(phi)^2 = phi phi^T - theta^2 I, so
    R = (1 - b theta^2) I + a hat(phi) + b phi phi^T.
    """
    _torch_only(phi, "exp", "Rotation.from_rotvec(phi).as_matrix()")
    theta2 = (phi * phi).sum(-1)[..., None, None]
    small = theta2 < _SMALL**2
    theta2_safe = torch.where(small, 1.0, theta2)
    theta = theta2_safe.sqrt()
    # Taylor terms beyond theta^2 are below float64 resolution for theta < _SMALL
    a = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    # (1 - cos t) / t^2 as 0.5 (sin(t/2) / (t/2))^2: the same value without the cancellation that cost its Jacobian
    # ~1e-11 just above _SMALL
    half = theta / 2
    b = torch.where(small, 0.5 - theta2 / 24.0, 0.5 * (torch.sin(half) / half) ** 2)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device)
    return (1.0 - b * theta2) * eye + a * hat(phi) + b * (phi[..., :, None] * phi[..., None, :])


def _quat_wxyz(R: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (..., 4) in (w, x, y, z) order with w >= 0, by Shepperd's method: the
    quaternion is built from the largest of (w, x, y, z), so no branch divides by a small number and
    angles near pi stay accurate."""
    maps = _maps(R)
    flat = R.flatten(-2)
    branches = (flat @ maps["quat"] + maps["quat_const"]).unflatten(-1, (4, 4))
    choice = (flat @ maps["choice"]).argmax(-1)
    q = torch.gather(branches, -2, choice[..., None, None].expand(*choice.shape, 1, 4)).squeeze(-2)
    return q * torch.where(q[..., :1] < 0, -1.0, 1.0) / q.norm(dim=-1, keepdim=True)


def matrix_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4), (x, y, z, w), w >= 0 (Shepperd)."""
    _torch_only(R, "matrix_to_quat", "Rotation.from_matrix(R).as_quat()")
    return _quat_wxyz(R).roll(-1, dims=-1)


def log(R: torch.Tensor, check: bool = True) -> torch.Tensor:
    """Logarithm map (..., 3, 3) -> (..., 3) rotation vectors with norm in [0, pi].

    `check` refuses matrices that are not rotations (R^T R = I and det 1 within `_ROTATION_TOL` of their dtype):
    the quaternion of any other matrix is still unit, so its "angle" would look plausible. The loss passes False:
    its matrices are products of `exp`, and the check waits for the device (a host sync) at every step."""
    _torch_only(R, "log", "Rotation.from_matrix(R).as_rotvec()")
    if check:
        _check_rotations(R, "log")
    q = _quat_wxyz(R)
    w, v = q[..., 0], q[..., 1:]
    s2 = (v * v).sum(-1)
    small = s2 < _SMALL**2
    s = torch.where(small, 1.0, s2).sqrt()
    # angle / sin(angle/2) = 2 atan2(s, w) / s; Taylor for s -> 0 (w -> 1). The branch not taken still gets a
    # gradient: w = 1 there, or a rotation by exactly pi (w = 0) had NaN gradients through 2 / w
    w_taylor = torch.where(small, w, 1.0)
    factor = torch.where(small, 2.0 / w_taylor - 2.0 * s2 / (3.0 * w_taylor**3), 2.0 * torch.atan2(s, w) / s)
    return v * factor[..., None]


def _check_rotations(R: torch.Tensor, what: str) -> None:
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"{what}: expected rotation matrices of shape (..., 3, 3), got {tuple(R.shape)}")
    if R.numel() == 0:
        return
    tol = _ROTATION_TOL.get(R.dtype, _ROTATION_TOL[torch.float32])
    eye = torch.eye(3, dtype=R.dtype, device=R.device)
    ortho = (R.transpose(-1, -2) @ R - eye).abs().amax(dim=(-1, -2))
    det = torch.linalg.det(R)
    bad = ~((ortho <= tol) & ((det - 1).abs() <= tol))  # NaN is bad too
    if bool(bad.any()):
        k = tuple(int(i) for i in torch.nonzero(bad)[0]) if bad.dim() else ()
        where = f"the matrix at index {k}" if k else "the matrix"
        raise ValueError(
            f"{what}: {where} is not a rotation (max |R^T R - I| {float(ortho[k]):.3g}, det "
            f"{float(det[k]):.6g}; tolerance {tol:g} in {R.dtype}): give body-to-world rotation matrices, e.g. "
            "from so3.exp or Rotation.as_matrix(), re-orthonormalised if they were averaged or interpolated"
        )


def tree_product(R: torch.Tensor, levels: int) -> torch.Tensor:
    """Products of consecutive blocks of 2**levels matrices along dim -3, in `levels` batched steps.

    R: (..., N, 3, 3) with N divisible by 2**levels. Returns (..., N / 2**levels, 3, 3) where
    block k is R[k*m] @ R[k*m+1] @ ... @ R[k*m+m-1] (m = 2**levels), the ordered product that
    right-multiplied integration needs.
    """
    if R.shape[-3] % (1 << levels):
        raise ValueError(
            f"tree_product: {R.shape[-3]} matrices do not split into blocks of 2**{levels} = {1 << levels}; give a "
            "multiple of the block (the loss's crops are multiples of its longest increment)"
        )
    for _ in range(levels):
        # unbind, not R[..., 0::2] and R[..., 1::2]: its gradient is one stack, not two zero-filled copies
        even, odd = R.unflatten(-3, (-1, 2)).unbind(-3)
        R = even @ odd
    return R


def _check_median_step(med: float) -> None:
    """Both integrations: a median step outside [0, MAX_STEP_S] is stamps or nanoseconds, not sample periods."""
    if not 0 <= med <= MAX_STEP_S:
        raise ValueError(
            f"dt: median step {med:.4g}; expected sample periods in seconds (0.005 at 200 Hz), e.g. "
            "np.diff(t, prepend=t[0]) with t in s: were timestamps, or nanoseconds, given?"
        )


def integrate_gyro_torch(R0: torch.Tensor, gyro: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
    """`integrate_gyro` on torch tensors (float64, on their device): what validation runs on the GPU.

    gyro: (N, 3) rad/s, dt: (N,) s (dt[0] unused), R0: (3, 3). Returns (N, 3, 3).
    """
    if dt.dtype != torch.float64:  # DESIGN.md: time is float64; float32 steps drift 9e-6 rad in 1e5 steps
        raise ValueError(f"dt is {dt.dtype}; give the steps in float64 seconds (time is never float32)")
    if len(dt) > 1:
        _check_median_step(float(dt[1:].median()))
    if len(gyro) == 0:
        return torch.zeros((0, 3, 3), dtype=torch.float64, device=gyro.device)
    gyro = gyro.double()
    prefix = torch.cat([torch.eye(3, dtype=gyro.dtype, device=gyro.device)[None], exp(gyro[1:] * dt[1:, None])])
    shift = 1
    while shift < len(prefix):  # Hillis-Steele inclusive scan, out of place
        prefix = torch.cat([prefix[:shift], prefix[:-shift] @ prefix[shift:]])
        shift *= 2
    return R0.to(prefix) @ prefix


# ---------------------------------------------------------------- numpy helpers (float64)


def integrate_gyro(R0: np.ndarray, gyro: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Open-loop attitude: R_0 = R0, R_n = R_{n-1} exp(gyro_n dt_n) for n >= 1.

    gyro: (N, 3) rad/s, dt: (N,) s (dt[0] is unused; `np.diff(t, prepend=t[0])` of stamps in s) or one period for
    all samples. R0: (3, 3) body to world. Returns (N, 3, 3) float64.
    The cumulative product is a parallel prefix scan (log2 N batched matmuls) in float64.
    """
    gyro = as_rows(gyro, "gyro", 3, " rad/s")
    dt = np.asarray(dt, dtype=np.float64)
    if dt.ndim == 0:  # one sample period for all
        dt = np.full(len(gyro), float(dt))
    if dt.shape != (len(gyro),):
        raise ValueError(f"dt has shape {dt.shape}; expected ({len(gyro)},) like gyro, or one sample period (s)")
    if len(dt) > 1:
        _check_median_step(float(np.median(dt[1:])))
    if np.shape(R0) != (3, 3):
        raise ValueError(f"R0 has shape {np.shape(R0)}; expected a (3, 3) rotation matrix (body to world)")
    r0 = np.asarray(R0, dtype=np.float64)
    if not np.allclose(r0.T @ r0, np.eye(3), atol=1e-6) or not np.isclose(np.linalg.det(r0), 1.0, atol=1e-6):
        raise ValueError("R0 is not a rotation matrix (R0^T R0 = I, det 1 within 1e-6)")
    if not np.isfinite(gyro).all():
        k = int(np.argmax(~np.isfinite(gyro).all(axis=1)))
        raise ValueError(f"gyro row {k} is not finite: every orientation after it would be NaN")
    if len(dt) > 1 and not (np.isfinite(dt[1:]).all() and (dt[1:] >= 0).all()):
        k = 1 + int(np.argmax(~(np.isfinite(dt[1:]) & (dt[1:] >= 0))))
        raise ValueError(f"dt[{k}] = {dt[k]}: steps must be finite and >= 0 (stamps in order)")
    if len(gyro) == 0:
        return np.zeros((0, 3, 3))
    steps = Rotation.from_rotvec(gyro[1:] * dt[1:, None]).as_matrix()
    prefix = np.concatenate([np.eye(3)[None], steps], axis=0)
    shift = 1
    n = len(prefix)
    while shift < n:  # Hillis-Steele inclusive scan: prefix[k] = steps[1] ... steps[k]
        prefix[shift:] = prefix[:-shift] @ prefix[shift:]
        shift *= 2
    return r0 @ prefix


def relative_rotvec(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Log(R_a^T R_b) for stacks of rotation matrices, via scipy (accurate at all angles)."""
    return Rotation.from_matrix(np.swapaxes(R_a, -1, -2) @ R_b).as_rotvec()


def yaw_of(R: np.ndarray) -> np.ndarray:
    """Yaw (rad) of world-frame rotations, ZYX Euler convention: atan2(R[1,0], R[0,0])."""
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def rpy_of(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad), ZYX convention, of (..., 3, 3) rotations."""
    return Rotation.from_matrix(R).as_euler("ZYX")[..., ::-1]
