"""The gyro correction model of the paper: w_hat = C_hat w_imu + w_tilde (eq. 5, Fig. 2).

w_tilde comes from a causal dilated 1D CNN over the past IMU samples (gyro + accelerometer).
Normalisation statistics of the training data are buffers of the model, so that they travel with
the weights (checkpoints, shipped models, exported graphs).
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import torch
from torch import nn

from gyrodenoise.models.cpu_layers import DilatedConv1d, FastDropout

ACTIVATIONS = {
    "gelu": nn.GELU,
    "elu": nn.ELU,
    "silu": nn.SiLU,
    "relu": nn.ReLU,
    "tanh": nn.Tanh,
    "softplus": nn.Softplus,
    "mish": nn.Mish,
}


class GyroCorrection(nn.Module):
    """Common part: C_hat (3x3, initialised at identity) and input normalisation buffers.

    C_hat = I + C_delta: weight decay then pulls C_hat towards identity, not towards zero.
    """

    def __init__(self) -> None:
        super().__init__()
        self.C_delta = nn.Parameter(torch.zeros(3, 3))
        self.register_buffer("mean", torch.zeros(6))
        self.register_buffer("std", torch.ones(6))

    def set_normalization(self, mean: np.ndarray | torch.Tensor, std: np.ndarray | torch.Tensor) -> None:
        self.mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        self.std.copy_(torch.as_tensor(std, dtype=torch.float32))

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        """w_tilde: (B, N, 6) raw IMU -> (B, N, 3) rad/s."""
        raise NotImplementedError

    def forward(self, imu: torch.Tensor) -> torch.Tensor:
        """imu: (B, N, 6) raw gyro (rad/s) + accelerometer (m/s^2) -> corrected gyro (B, N, 3)."""
        return imu[..., :3] @ self.C_hat.T + self.correction(imu)

    @property
    def C_hat(self) -> torch.Tensor:
        return torch.eye(3, dtype=self.C_delta.dtype, device=self.C_delta.device) + self.C_delta


class DilatedCNNDenoiser(GyroCorrection):
    """Fig. 2: conv layers with the given channels / kernel / dilations, each followed by batch norm,
    a smooth activation and dropout, then a 1x1 conv to 3 outputs scaled by `output_scale_deg_s`.

    Causality: the input is padded on the left only (replicating the first sample) by the
    receptive field minus one, so output n depends on samples <= n.
    """

    def __init__(
        self,
        channels: tuple[int, ...] = (16, 32, 64, 128),
        kernel_size: int = 7,
        dilations: tuple[int, ...] = (1, 4, 16, 64),
        act: str = "gelu",
        dropout: float = 0.1,
        batch_norm: bool = True,
        output_scale_deg_s: float | tuple[float, float, float] = (1.0, 2.0, 5.0),
    ) -> None:
        super().__init__()
        if len(channels) != len(dilations):
            raise ValueError(f"channels {list(channels)} and dilations {list(dilations)} differ in length")
        if act not in ACTIVATIONS:
            raise ValueError(f"model.act={act!r}; choose one of {sorted(ACTIVATIONS)}")
        for key, given in (("channels", channels), ("dilations", dilations), ("kernel_size", kernel_size)):
            values = [given] if key == "kernel_size" else list(given)
            if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and v >= 1 for v in values):
                raise ValueError(f"model.{key}={given!r}: give positive integers")
        if not isinstance(batch_norm, bool):  # the string "false" from a command line would be true
            raise ValueError(f"model.batch_norm={batch_norm!r}; give true or false")
        if not 0 <= dropout < 1:
            raise ValueError(f"model.dropout={dropout!r}; give a probability in [0, 1)")
        layers: list[nn.Module] = []
        c_in = 6
        for c, d in zip(channels, dilations, strict=True):
            layers.append(DilatedConv1d(c_in, c, kernel_size, dilation=d))
            if batch_norm:
                layers.append(nn.BatchNorm1d(c))
            layers += [ACTIVATIONS[act](), FastDropout(dropout)]
            c_in = c
        head = nn.Conv1d(c_in, 3, 1)
        nn.init.zeros_(head.weight)  # untrained model == raw IMU (w_tilde = 0)
        nn.init.zeros_(head.bias)
        layers.append(head)
        self.net = nn.Sequential(*layers)
        self.receptive_field = 1 + (kernel_size - 1) * sum(dilations)
        # per-axis unit of the network output: lets a bias of a few deg/s (the ADIS16448 z axis has
        # ~4 deg/s) be reached with O(1) outputs, which weight decay would otherwise pull back
        scale = torch.as_tensor(output_scale_deg_s, dtype=torch.float32).expand(3) * (math.pi / 180)
        self.register_buffer("output_scale", scale.clone())

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        x = ((imu - self.mean) / self.std).transpose(1, 2)  # (B, 6, N)
        x = nn.functional.pad(x, (self.receptive_field - 1, 0), mode="replicate")
        return self.output_scale * self.net(x).transpose(1, 2)


class CalibratedImu(GyroCorrection):
    """The 'calibrated IMU' baseline: C_hat and a constant bias, 12 parameters.

    g_sensitivity=True adds G (3x3, rad/s per m/s^2): a gyro bias linear in the raw specific force,
    w_hat = C_hat w_imu + b + G a_imu (21 parameters; a MEMS gyro's acceleration sensitivity).
    """

    def __init__(self, g_sensitivity: bool = False) -> None:
        super().__init__()
        self.bias = nn.Parameter(torch.zeros(3))
        self.G = nn.Parameter(torch.zeros(3, 3)) if g_sensitivity else None
        self.receptive_field = 1

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        if self.G is None:
            return self.bias.expand(*imu.shape[:-1], 3)
        return self.bias + imu[..., 3:] @ self.G.T


@torch.no_grad()
def predict_gyro(model: nn.Module, imu: np.ndarray | torch.Tensor) -> torch.Tensor:
    """Corrected gyro (N, 3) float64 for one whole sequence (N, 6), in eval mode (an ensemble: the mean)."""
    was_training = model.training
    model.eval()
    x = torch.as_tensor(imu, dtype=torch.float32, device=next(model.buffers()).device)
    w = model(x[None])[0].double().cpu()
    model.train(was_training)
    return w


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
