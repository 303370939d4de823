"""Orientation metrics of Section IV-D, in float64 numpy.

AOE: sqrt(mean ||Log(R_n^T R_hat_n)||^2) over the samples with ground truth, the estimate aligned on
ground truth at the first instant. Yaw AOE: RMS of the yaw of the world-frame error R_hat R^T.
ROE: ||Log(dR^T dR_hat)|| over sub-trajectories of a given travelled distance (7, 21, 35 m), with
median and quartiles; yaw ROE likewise with the yaw of the world-frame relative error.
"""

from __future__ import annotations

import numpy as np
import torch

from gyrodenoise import so3
from gyrodenoise.so3 import relative_rotvec, yaw_of

AOE_DEFINITION = (
    "AOE 3D/yaw in degrees: the RMS, over the samples with ground truth, of the angle of R_gt^T R_est (yaw: of the "
    "world-frame error R_est R_gt^T); every estimate is aligned on ground truth at its first sample."
)

ROE_STRIDE = 10  # a pair starts every 10th sample: 0.05 s at 200 Hz, pairs overlap heavily anyway


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _check_rotations(R_gt: np.ndarray, R_est: np.ndarray) -> None:
    for name, R in (("R_gt", R_gt), ("R_est", R_est)):
        shape = np.shape(R)
        if len(shape) < 2 or shape[-2:] != (3, 3):
            raise ValueError(
                f"{name} has shape {shape}; expected (N, 3, 3) rotation matrices (body to world). From quaternions: "
                "scipy.spatial.transform.Rotation.from_quat(q).as_matrix() for x, y, z, w order; for w, x, y, z (ASL "
                "files) pass scalar_first=True (scipy >= 1.14) or np.roll(q, -1, axis=-1) first"
            )
    if np.shape(R_gt) != np.shape(R_est):
        raise ValueError(f"R_gt {np.shape(R_gt)} and R_est {np.shape(R_est)}: one estimate per ground-truth sample")


def orientation_errors(R_gt: np.ndarray, R_est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample 3D error angle (rad) and yaw error (rad, of R_est R_gt^T); R_gt, R_est: (N, 3, 3) matrices."""
    _check_rotations(R_gt, R_est)
    e3d = np.linalg.norm(relative_rotvec(R_gt, R_est), axis=-1)
    eyaw = _wrap(yaw_of(R_est @ np.swapaxes(R_gt, -1, -2)))
    return e3d, eyaw


def aoe(R_gt: np.ndarray, R_est: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float]:
    """(AOE 3D, AOE yaw) in radians over the samples where `mask` is True."""
    e3d, eyaw = orientation_errors(R_gt, R_est)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != bool or mask.shape != e3d.shape:  # integers would index samples, not select them
            raise ValueError(f"mask: a boolean array of shape {e3d.shape}, got {mask.dtype} {mask.shape}")
        e3d, eyaw = e3d[mask], eyaw[mask]
    return float(np.sqrt(np.mean(e3d**2))), float(np.sqrt(np.mean(eyaw**2)))


def aoe_torch(R_gt: torch.Tensor, R_est: torch.Tensor, mask: torch.Tensor | None = None) -> tuple[float, float]:
    """`aoe` on torch tensors (float64, on their device), for validation during training."""
    E_body = R_gt.transpose(-1, -2) @ R_est
    e3d = so3.log(E_body, check=False).norm(dim=-1)  # NaN weights give NaN here: TrainingDiverged says so, later
    E_world = R_est @ R_gt.transpose(-1, -2)
    eyaw = torch.atan2(E_world[..., 1, 0], E_world[..., 0, 0])  # already wrapped to [-pi, pi]
    if mask is not None:
        e3d, eyaw = e3d[mask], eyaw[mask]
    return float(e3d.square().mean().sqrt()), float(eyaw.square().mean().sqrt())


def travelled_distance(pos: np.ndarray) -> np.ndarray:
    """Cumulative path length (m) along ground-truth positions."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])


def roe(
    R_gt: np.ndarray,
    R_est: np.ndarray,
    pos: np.ndarray,
    distance: float,
    mask: np.ndarray | None = None,
    stride: int = ROE_STRIDE,
) -> tuple[np.ndarray, np.ndarray]:
    """Relative orientation errors (rad), 3D and yaw, over sub-trajectories of `distance` metres.

    For each start n (every `stride` samples), g(n) is the first sample whose travelled distance
    from n reaches `distance`. Pairs whose ends lack ground truth are left out. Returns two arrays
    (possibly empty when the sequence is shorter than `distance`).
    """
    dist = travelled_distance(pos)
    starts = np.arange(0, len(dist), stride)
    ends = np.searchsorted(dist, dist[starts] + distance)
    ok = ends < len(dist)
    starts, ends = starts[ok], ends[ok]
    if mask is not None:
        keep = mask[starts] & mask[ends]
        starts, ends = starts[keep], ends[keep]
    if len(starts) == 0:
        return np.empty(0), np.empty(0)
    T = np.swapaxes
    dR_gt = T(R_gt[starts], -1, -2) @ R_gt[ends]
    dR_est = T(R_est[starts], -1, -2) @ R_est[ends]
    e3d = np.linalg.norm(relative_rotvec(dR_gt, dR_est), axis=-1)
    # yaw: the estimate aligned on ground truth at the start of the pair, error in the world frame
    E = R_gt[starts] @ dR_est @ T(dR_gt, -1, -2) @ T(R_gt[starts], -1, -2)
    eyaw = np.abs(_wrap(yaw_of(E)))
    return e3d, eyaw


def summarize(errors: np.ndarray) -> dict[str, float]:
    """Median and quartiles (NaN when there are no pairs)."""
    if len(errors) == 0:
        return {"q1": float("nan"), "median": float("nan"), "q3": float("nan"), "n": 0}
    q1, med, q3 = np.percentile(errors, [25, 50, 75])
    return {"q1": float(q1), "median": float(med), "q3": float(q3), "n": len(errors)}
