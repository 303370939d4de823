"""The correction as a stateful step, for exported graphs that stream: (imu chunk, state) -> (gyro, new state).

An exported graph keeps nothing between calls, so the plain export pads the start of every call (`export.py`).
This module makes the streaming corrector's state explicit instead: for each dilated convolution, the last
dilation*(k-1) inputs it saw, all flattened into one float32 vector per stream. A caller keeps that vector,
feeds it back with the next chunk (any length >= 1, one sample included) and gets the outputs the batch model
computes on the whole stream, at O(1) cost per sample.

`reset` (per stream) starts a stream: the state passed in is ignored and the history is what the batch model
sees on its left padding, copies of the chunk's first sample (every layer fed a constant outputs a constant).

    step = StatefulCorrection(model).eval()
    state = step.initial_state(batch=1)
    y, state = step(chunk, state, reset=torch.tensor([True]))     # first chunk
    y, state = step(next_chunk, state, reset=torch.tensor([False]))

An ensemble steps its members side by side (their states concatenated) and returns their mean and std, as
`EnsembleCorrection.forward_with_spread`.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from gyrodenoise.models.build import check_stream_form
from gyrodenoise.models.denoiser import CalibratedImu, DilatedCNNDenoiser
from gyrodenoise.models.ensemble import CorrectionModel, EnsembleCorrection, has_spread


def _blocks(net: nn.Sequential) -> tuple[list[nn.Sequential], nn.Conv1d]:
    """model.net as its conv blocks (Conv1d [BatchNorm1d] act Dropout) and the 1x1 head."""
    mods = list(net)
    head = mods.pop()
    blocks: list[list[nn.Module]] = []
    for m in mods:
        if isinstance(m, nn.Conv1d):
            if m.padding != (0,) or m.stride != (1,):
                raise TypeError("a stateful step needs the denoiser's unpadded, stride-1 convolutions")
            blocks.append([])
        elif not blocks:
            raise TypeError(f"model.net starts with {type(m).__name__}, expected Conv1d")
        blocks[-1].append(m)
    return [nn.Sequential(*b) for b in blocks], head


class _MemberStep(nn.Module):
    """One denoiser or calibrated model as a step; `state` is this member's slice, (B, state_size)."""

    def __init__(self, model: DilatedCNNDenoiser | CalibratedImu) -> None:
        super().__init__()
        self.model = model
        self.blocks, self.head = _blocks(model.net) if isinstance(model, DilatedCNNDenoiser) else ([], None)
        # (channels, length) of each block's input history
        self.shapes = [(b[0].in_channels, b[0].dilation[0] * (b[0].kernel_size[0] - 1)) for b in self.blocks]
        self.state_size = sum(c * n for c, n in self.shapes)

    def _initial(self, h0: torch.Tensor) -> list[torch.Tensor]:
        """Histories after copies of the normalised first sample h0 (B, 6): a constant per layer."""
        states, v = [], h0[:, :, None]
        for block, (c, n) in zip(self.blocks, self.shapes, strict=True):
            states.append(v.expand(-1, c, n))
            v = block(v.expand(-1, c, n + 1))  # one valid output of a constant input
        return states

    def forward(self, imu: torch.Tensor, state: torch.Tensor, reset: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if not self.blocks:  # a calibrated model: no memory
            return self.model(imu), state
        h = ((imu - self.model.mean) / self.model.std).transpose(1, 2)  # (B, 6, N)
        init = self._initial(h[:, :, 0])
        new_states, i = [], 0
        for block, (c, n), s0 in zip(self.blocks, self.shapes, init, strict=True):
            past = state[:, i : i + c * n].reshape(-1, c, n)
            past = torch.where(reset[:, None, None], s0, past)
            xc = torch.cat([past, h], dim=2)
            new_states.append(xc[:, :, -n:].reshape(-1, c * n))
            h = block(xc)
            i += c * n
        w_tilde = self.model.output_scale * self.head(h).transpose(1, 2)
        return imu[..., :3] @ self.model.C_hat.T + w_tilde, torch.cat(new_states, dim=1)


class StatefulCorrection(nn.Module):
    """(imu (B, N, 6), state (B, state_size), reset (B,) bool) -> (gyro (B, N, 3), [gyro_std,] state (B, state_size)).

    In eval mode (batch norm's running statistics, no dropout), float32, on the CPU; the caller's model is copied.
    """

    def __init__(self, model: CorrectionModel) -> None:
        super().__init__()
        check_stream_form(model)
        model = copy.deepcopy(model).cpu().float().eval()
        self.is_ensemble = has_spread(model)  # a one-member ensemble steps its member and outputs no std
        members = list(model.members) if isinstance(model, EnsembleCorrection) else [model]
        self.steps = nn.ModuleList(_MemberStep(m) for m in members)
        self.spread_scale = float(getattr(model, "spread_scale", 1.0))
        self.state_size = sum(s.state_size for s in self.steps)
        self.receptive_field = int(getattr(model, "receptive_field", 1))
        self.eval()

    def initial_state(self, batch: int = 1) -> torch.Tensor:
        """A state to pass with reset=True (its values are not read then)."""
        return torch.zeros(batch, self.state_size)

    def forward(self, imu: torch.Tensor, state: torch.Tensor, reset: torch.Tensor):
        outs, states, i = [], [], 0
        for step in self.steps:
            y, s = step(imu, state[:, i : i + step.state_size], reset)
            outs.append(y)
            states.append(s)
            i += step.state_size
        new_state = torch.cat(states, dim=1)
        if not self.is_ensemble:
            return outs[0], new_state
        stack = torch.stack(outs)
        return stack.mean(0), stack.std(0, correction=1) * self.spread_scale, new_state
