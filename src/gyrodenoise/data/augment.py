"""Training-time augmentations of IMU windows (Section III-E of the paper).

Only Gaussian noise is on by default, as in the paper. The others are switches:
- static_bias: a constant gyro/accelerometer bias per window;
- uncalibrate: multiply the gyro by I + E, E a small random matrix (scale factor + misalignment);
- rotate_acc: rotate the accelerometer axes by a small random rotation (IMU-frame shift).
All draws use torch's global RNG, which `seed_everything` seeds.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from gyrodenoise import so3


@dataclass
class AugmentConfig:
    gyro_noise_std: float = 0.0  # rad/s per sample
    acc_noise_std: float = 0.0  # m/s^2 per sample
    static_bias: bool = False
    gyro_bias_std: float = 1e-3  # rad/s
    acc_bias_std: float = 2e-2  # m/s^2
    uncalibrate: bool = False
    uncalibrate_std: float = 2e-3  # scale/misalignment (dimensionless)
    rotate_acc: bool = False
    rotate_acc_std: float = 0.01  # rad


def augment_window(imu: torch.Tensor, cfg: AugmentConfig) -> torch.Tensor:
    """imu: (N, 6) float32 window -> augmented copy."""
    out = imu.clone()
    gyro, acc = out[:, :3], out[:, 3:]
    if cfg.uncalibrate:
        E = cfg.uncalibrate_std * torch.randn(3, 3, dtype=imu.dtype)
        gyro = gyro @ (torch.eye(3, dtype=imu.dtype) + E).T
    if cfg.rotate_acc:
        dR = so3.exp(cfg.rotate_acc_std * torch.randn(3, dtype=torch.float64)).to(imu.dtype)
        acc = acc @ dR.T
    if cfg.static_bias:
        gyro = gyro + cfg.gyro_bias_std * torch.randn(3, dtype=imu.dtype)
        acc = acc + cfg.acc_bias_std * torch.randn(3, dtype=imu.dtype)
    if cfg.gyro_noise_std > 0:
        gyro = gyro + cfg.gyro_noise_std * torch.randn_like(gyro)
    if cfg.acc_noise_std > 0:
        acc = acc + cfg.acc_noise_std * torch.randn_like(acc)
    return torch.cat([gyro, acc], dim=1)
