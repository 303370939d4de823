"""An ensemble of gyro correction models: K trained networks, one corrected gyro and its spread.

Each member keeps its own normalisation buffers and C_hat; the ensemble's output is the mean of the
members' corrected gyros, w_hat = (1/K) sum_k (C_k w_imu + w_tilde_k), and the per-sample, per-axis
standard deviation across members is the uncertainty output (`forward_with_spread`). Members that
agree where they were trained and disagree elsewhere make that spread a warning sign of inputs
unlike the training data; how well it predicts the actual error is measured by
`gyrodenoise.uncertainty`.

The spread can carry a calibration factor, `spread_scale` (default 1): the std output is the
members' sample std times it, fitted on flights the members did not see (`python -m
gyrodenoise.ensemble scale`; how the shipped `euroc` got its factor: benchmarks/uncertainty_scale_cv.py).

Stored like any model (`gyrodenoise.pretrained`): config {"name": "ensemble", "members": [cfg, ...],
"spread_scale": s (absent: 1)}, state dict keys `members.<k>.<member key>`.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import torch
from torch import nn

from gyrodenoise.arrays import as_rows
from gyrodenoise.models.denoiser import GyroCorrection


class EnsembleCorrection(nn.Module):
    """Mean and spread of K `GyroCorrection` members (any mix of denoisers and calibrated models)."""

    def __init__(self, members: Iterable[GyroCorrection], spread_scale: float = 1.0) -> None:
        super().__init__()
        spread_scale = float(spread_scale)
        if not (np.isfinite(spread_scale) and spread_scale > 0):
            raise ValueError(f"spread_scale={spread_scale}: must be a positive number (1 = the members' raw std)")
        self.spread_scale = spread_scale
        members = list(members)
        if not members:
            raise ValueError("an ensemble needs at least one member model")
        for k, m in enumerate(members):
            if isinstance(m, EnsembleCorrection):
                raise TypeError(f"member {k} is itself an ensemble: pass its members instead (ensemble.members)")
            if not isinstance(m, GyroCorrection):
                raise TypeError(f"member {k} is a {type(m).__name__}, not a GyroCorrection (raw IMU (B, N, 6) -> gyro)")
        self.members = nn.ModuleList(members)
        # the ensemble output at n depends on what the longest-memory member sees
        self.receptive_field = max(int(getattr(m, "receptive_field", 1)) for m in members)

    def __len__(self) -> int:
        return len(self.members)

    def member_outputs(self, imu: torch.Tensor) -> torch.Tensor:
        """(B, N, 6) raw IMU -> (K, B, N, 3) corrected gyro of each member."""
        return torch.stack([m(imu) for m in self.members])

    def forward(self, imu: torch.Tensor) -> torch.Tensor:
        """(B, N, 6) raw gyro (rad/s) + acc (m/s^2) -> mean corrected gyro (B, N, 3) rad/s."""
        return self.member_outputs(imu).mean(0)

    def forward_with_spread(self, imu: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, std) over the members, each (B, N, 3) rad/s.

        std is the sample standard deviation (K - 1 in the denominator: the unbiased variance of
        the members' spread) times `spread_scale`. A single member measures no spread: NaN, not a zero that reads
        as certainty (the numpy, streaming and ONNX paths give no std at all for it: `has_spread`).
        """
        out = self.member_outputs(imu)
        mean = out.mean(0)
        if len(self.members) == 1:
            return mean, torch.full_like(mean, float("nan"))
        return mean, out.std(0, correction=1) * self.spread_scale

    @property
    def C_hat(self) -> torch.Tensor:
        """Mean of the members' C_hat: the mean output is C_mean w_imu + mean(w_tilde_k), so
        `w_hat - w_imu @ C_hat.T` is the mean of the members' corrections w_tilde."""
        return torch.stack([m.C_hat for m in self.members]).mean(0)


CorrectionModel = GyroCorrection | EnsembleCorrection


def has_spread(model: object) -> bool:
    """An ensemble of two or more members: the only model whose members' spread means something."""
    return isinstance(model, EnsembleCorrection) and len(model.members) > 1


def model_device(model: nn.Module) -> torch.device:
    return next(iter(model.buffers()), torch.zeros(())).device


@torch.no_grad()
def predict_with_spread(model: CorrectionModel, imu: np.ndarray | torch.Tensor) -> tuple[np.ndarray, np.ndarray | None]:
    """Corrected gyro (N, 3) float64 of one whole sequence (N, 6) in eval mode, and the ensemble's
    per-sample std (N, 3) float64 (None for a single model or a one-member ensemble: neither has a spread)."""
    columns = " of gyro x, y, z [rad/s] then accelerometer x, y, z [m/s^2] (np.hstack([gyro, acc]))"
    arr = as_rows(imu.detach().cpu().numpy() if isinstance(imu, torch.Tensor) else imu, "imu", 6, columns)
    if len(arr) == 0 or not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr)).any(1).sum()) if len(arr) else 0
        raise ValueError(
            f"imu: {'no samples' if not len(arr) else f'{bad} rows hold NaN/inf'}; the network's outputs depend on the"
            " last ~2.5 s of samples, so one bad sample spoils hundreds of outputs: repair or drop them first"
        )
    was_training = model.training
    model.eval()
    x = torch.as_tensor(arr, dtype=torch.float32, device=model_device(model))[None]
    try:
        if has_spread(model):
            mean, std = model.forward_with_spread(x)
            return mean[0].double().cpu().numpy(), std[0].double().cpu().numpy()
        return model(x)[0].double().cpu().numpy(), None
    finally:
        model.train(was_training)
