"""Helpers for tests: small models with non-trivial weights, and IMU-like random data."""

from __future__ import annotations

import numpy as np
import torch

from gyrodenoise.models.build import build_model
from gyrodenoise.models.denoiser import GyroCorrection


def random_model(seed: int = 0, **kwargs) -> GyroCorrection:
    """A denoiser with non-trivial weights everywhere (BN statistics, head, C_hat), in eval mode."""
    torch.manual_seed(seed)
    m = build_model("denoiser", **kwargs)
    for mod in m.modules():
        if isinstance(mod, torch.nn.BatchNorm1d):
            mod.running_mean.normal_()
            mod.running_var.uniform_(0.5, 2.0)
            mod.weight.data.normal_(1.0, 0.2)
            mod.bias.data.normal_(0.0, 0.2)
    torch.nn.init.normal_(m.net[-1].weight, std=0.3)
    m.C_delta.data.normal_(std=0.01)
    m.set_normalization([0, 0, 0, 0, 0, 9.8], [0.3, 0.3, 0.3, 1.0, 1.0, 1.0])
    return m.eval()


def random_imu(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.normal(0, 0.5, (n, 3)), rng.normal(0, 1, (n, 3)) + [0, 0, 9.8]], axis=1)
