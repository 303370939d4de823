"""The paper's network with another accelerometer input, for the screen of benchmarks/queues/euroc_acc_input_cv.txt.

The paper feeds the raw accelerometer because its changes carry angular-velocity information (eq. 7:
a_{n+1} - a_n ~ -(exp(-w dt) - I) R^T g). The raw signal also carries the direction of gravity in the body frame,
on which the networks fail when a flight holds the body at a tilt no training flight had (reports/accuracy.md,
"Where the EuRoC error comes from"). Two variants, used through `model=custom` (PYTHONPATH=benchmarks):

- acc_input="diff": the causal first difference of the accelerometer (zero at the first sample), divided by the
  raw signal's training std like the raw input is (on EuRoC's training flights both stds are ~0.4-2 m/s^2:
  rotor vibration dominates). The information of eq. 7 stays, the absolute gravity direction goes.
- acc_input="none": the accelerometer channels held at zero after normalisation (gyro only).

Same layers, parameters and initialisation as `DilatedCNNDenoiser`; only the input of the first layer differs.
"""

from __future__ import annotations

import torch
from torch import nn

from gyrodenoise.models.denoiser import DilatedCNNDenoiser

ACC_INPUTS = ("diff", "none")


class AccInputDenoiser(DilatedCNNDenoiser):
    """`DilatedCNNDenoiser` whose accelerometer input is its first difference ("diff") or nothing ("none")."""

    def __init__(self, acc_input: str = "diff", **network: object) -> None:
        if acc_input not in ACC_INPUTS:
            raise ValueError(f"model.acc_input={acc_input!r}; choose one of {ACC_INPUTS}")
        super().__init__(**network)
        self.acc_input = acc_input

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        gyro = (imu[..., :3] - self.mean[:3]) / self.std[:3]
        acc = imu[..., 3:]
        if self.acc_input == "diff":
            acc = torch.cat([torch.zeros_like(acc[:, :1]), acc[:, 1:] - acc[:, :-1]], dim=1) / self.std[3:]
        else:
            acc = torch.zeros_like(acc)
        x = torch.cat([gyro, acc], dim=-1).transpose(1, 2)  # (B, 6, N)
        x = nn.functional.pad(x, (self.receptive_field - 1, 0), mode="replicate")
        return self.output_scale * self.net(x).transpose(1, 2)
