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

_SMALL = 1e-6  # below this angle (rad) the Taylor branches are exact to float64 precision


def hat(phi: torch.Tensor) -> torch.Tensor:
    """Skew-symmetric matrix of (..., 3) vectors: hat(a) @ b == cross(a, b)."""
    x, y, z = phi.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], dim=-1).reshape(*phi.shape[:-1], 3, 3)


def exp(phi: torch.Tensor) -> torch.Tensor:
    """Exponential map (..., 3) rotation vectors -> (..., 3, 3) rotation matrices (Rodrigues)."""
    theta2 = (phi * phi).sum(-1)
    small = theta2 < _SMALL**2
    theta2_safe = torch.where(small, torch.ones_like(theta2), theta2)
    theta = theta2_safe.sqrt()
    a = torch.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, (1.0 - torch.cos(theta)) / theta2_safe)
    K = hat(phi)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device).expand(K.shape)
    K2 = phi[..., :, None] * phi[..., None, :] - theta2[..., None, None] * eye  # hat(phi)^2, no matmul
    return eye + a[..., None, None] * K + b[..., None, None] * K2


def matrix_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4), (x, y, z, w), w >= 0.

    Shepperd's method: build the quaternion from the largest of (w, x, y, z) so that no branch
    divides by a small number, which keeps angles near pi accurate.
    """
    m = R
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack([tr, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], dim=-1)
    choice = cands.argmax(-1)
    # 4*q_k^2 for the chosen component; clamp keeps sqrt away from 0 where the branch is unused
    qw = torch.stack(
        [
            1 + tr,
            m[..., 2, 1] - m[..., 1, 2],
            m[..., 0, 2] - m[..., 2, 0],
            m[..., 1, 0] - m[..., 0, 1],
        ],
        -1,
    )
    qx = torch.stack(
        [
            m[..., 2, 1] - m[..., 1, 2],
            1 + 2 * m[..., 0, 0] - tr,
            m[..., 0, 1] + m[..., 1, 0],
            m[..., 0, 2] + m[..., 2, 0],
        ],
        -1,
    )
    qy = torch.stack(
        [
            m[..., 0, 2] - m[..., 2, 0],
            m[..., 0, 1] + m[..., 1, 0],
            1 + 2 * m[..., 1, 1] - tr,
            m[..., 1, 2] + m[..., 2, 1],
        ],
        -1,
    )
    qz = torch.stack(
        [
            m[..., 1, 0] - m[..., 0, 1],
            m[..., 0, 2] + m[..., 2, 0],
            m[..., 1, 2] + m[..., 2, 1],
            1 + 2 * m[..., 2, 2] - tr,
        ],
        -1,
    )
    # rows: candidate branch (w, x, y, z); each row is 4*q_k*(w, x, y, z)
    rows = torch.stack([qw, qx, qy, qz], dim=-2)  # (..., branch, component) in (w,x,y,z) order
    idx = choice[..., None, None].expand(*choice.shape, 1, 4)
    q_wxyz = torch.gather(rows, -2, idx).squeeze(-2)
    q_wxyz = q_wxyz / q_wxyz.norm(dim=-1, keepdim=True)
    q_wxyz = torch.where(q_wxyz[..., :1] < 0, -q_wxyz, q_wxyz)
    return torch.cat([q_wxyz[..., 1:], q_wxyz[..., :1]], dim=-1)


def log(R: torch.Tensor) -> torch.Tensor:
    """Logarithm map (..., 3, 3) -> (..., 3) rotation vectors with norm in [0, pi]."""
    q = matrix_to_quat(R)
    v, w = q[..., :3], q[..., 3]
    s2 = (v * v).sum(-1)
    small = s2 < _SMALL**2
    s = torch.where(small, torch.ones_like(s2), s2).sqrt()
    # angle / sin(angle/2) = 2 atan2(s, w) / s; Taylor for s -> 0 (w -> 1)
    factor = torch.where(small, 2.0 / w - 2.0 * s2 / (3.0 * w**3), 2.0 * torch.atan2(s, w) / s)
    return v * factor[..., None]


def tree_product(R: torch.Tensor, levels: int) -> torch.Tensor:
    """Products of consecutive blocks of 2**levels matrices along dim -3, in `levels` batched steps.

    R: (..., N, 3, 3) with N divisible by 2**levels. Returns (..., N / 2**levels, 3, 3) where
    block k is R[k*m] @ R[k*m+1] @ ... @ R[k*m+m-1] (m = 2**levels), the ordered product that
    right-multiplied integration needs.
    """
    for _ in range(levels):
        R = R[..., 0::2, :, :] @ R[..., 1::2, :, :]
    return R


def integrate_gyro_torch(R0: torch.Tensor, gyro: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
    """`integrate_gyro` on torch tensors (float64, on their device): what validation runs on the GPU.

    gyro: (N, 3) rad/s, dt: (N,) s (dt[0] unused), R0: (3, 3). Returns (N, 3, 3).
    """
    gyro, dt = gyro.double(), dt.double()
    prefix = torch.cat([torch.eye(3, dtype=gyro.dtype, device=gyro.device)[None], exp(gyro[1:] * dt[1:, None])])
    shift = 1
    while shift < len(prefix):  # Hillis-Steele inclusive scan, out of place
        prefix = torch.cat([prefix[:shift], prefix[:-shift] @ prefix[shift:]])
        shift *= 2
    return R0.to(prefix) @ prefix


# ---------------------------------------------------------------- numpy helpers (float64)


def integrate_gyro(R0: np.ndarray, gyro: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Open-loop attitude: R_0 = R0, R_n = R_{n-1} exp(gyro_n dt_n) for n >= 1.

    gyro: (N, 3) rad/s, dt: (N,) s (dt[0] is unused). Returns (N, 3, 3) float64.
    The cumulative product is a parallel prefix scan (log2 N batched matmuls) in float64.
    """
    gyro = np.asarray(gyro, dtype=np.float64)
    dt = np.asarray(dt, dtype=np.float64)
    steps = Rotation.from_rotvec(gyro[1:] * dt[1:, None]).as_matrix()
    prefix = np.concatenate([np.eye(3)[None], steps], axis=0)
    shift = 1
    n = len(prefix)
    while shift < n:  # Hillis-Steele inclusive scan: prefix[k] = steps[1] ... steps[k]
        prefix[shift:] = prefix[:-shift] @ prefix[shift:]
        shift *= 2
    return np.asarray(R0, dtype=np.float64) @ prefix


def relative_rotvec(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Log(R_a^T R_b) for stacks of rotation matrices, via scipy (accurate at all angles)."""
    return Rotation.from_matrix(np.swapaxes(R_a, -1, -2) @ R_b).as_rotvec()


def yaw_of(R: np.ndarray) -> np.ndarray:
    """Yaw (rad) of world-frame rotations, ZYX Euler convention: atan2(R[1,0], R[0,0])."""
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def rpy_of(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad), ZYX convention, of (..., 3, 3) rotations."""
    return Rotation.from_matrix(R).as_euler("ZYX")[..., ::-1]
