"""Increment loss of the paper, eqs. (8)-(10).

For each increment length j (16 and 32 samples by default), the estimated increments
dR_hat_{i,i+j} = prod_{k=i+1}^{i+j} exp(w_hat_k dt_k), i = 0, j, 2j, ... are built as a log2(j)-deep
tree of batched products (float64) and compared with the precomputed ground-truth increments:
r = Log(dR dR_hat^T), rho = Huber with threshold `huber_delta` (rad) on each component, averaged.
Each term is multiplied by `weight` (1e6 by default, the scale of the authors' implementation): with
Adam's coupled weight decay, the loss scale sets how strongly the decay regularises, so it is a
hyperparameter, not a cosmetic factor. Terms whose ground truth is missing (mask False) are left out.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable

import torch
from torch.nn import functional as F

from gyrodenoise import so3

_EXAMPLES = {"huber_delta": "0.005", "weight": "1e6"}


def _items(value: object) -> list:
    """The elements of a list-like setting; [] for a single value or a string (not a list of increments)."""
    return [] if isinstance(value, str | bytes) or not isinstance(value, Iterable) else list(value)


class IncrementLoss(torch.nn.Module):
    def __init__(self, increments: tuple[int, ...] = (16, 32), huber_delta: float = 0.005, weight: float = 1e6) -> None:
        super().__init__()
        items = _items(increments)
        whole = bool(items) and all(isinstance(j, numbers.Integral) and not isinstance(j, bool) for j in items)
        # >= 1 and distinct: 0 divided by zero further on, and a repeated length counted its term twice
        if not whole or min(items) < 1 or len(set(items)) != len(items):
            raise ValueError(
                f"loss.increments={increments!r}: a list of distinct increment lengths in samples, powers of two, "
                "e.g. 'loss.increments=[16,32]'"
            )
        self.increments = sorted(int(j) for j in items)
        self.base = self.increments[0]
        if any(j & (j - 1) or j % self.base for j in self.increments):
            raise ValueError(f"loss.increments must be powers of two, got {self.increments}")
        for key, value in (("huber_delta", huber_delta), ("weight", weight)):  # torch refuses delta <= 0 mid-fit
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 < value < math.inf:
                raise ValueError(f"loss.{key}={value!r}: give a positive number, e.g. loss.{key}={_EXAMPLES[key]}")
        self.delta, self.weight = huber_delta, weight

    def residuals(self, w_hat: torch.Tensor, dt: torch.Tensor, dR: torch.Tensor, mask: torch.Tensor):
        """Yield (j, r, mask_j) for each increment length.

        w_hat: (B, 1 + L, 3) corrected gyro; dt: (B, 1 + L); dR: (B, L / base, 3, 3) ground-truth
        increments over `base` samples; mask: (B, L / base).
        """
        steps = so3.exp(w_hat[:, 1:].double() * dt[:, 1:, None])  # step k -> k+1 uses sample k+1
        est = so3.tree_product(steps, int(math.log2(self.base)))
        gt, m = dR, mask
        for j in self.increments:
            while est.shape[1] > dR.shape[1] * self.base // j:  # pair up until blocks span j samples
                est = so3.tree_product(est, 1)
                gt = so3.tree_product(gt, 1)
                m = m.unflatten(1, (-1, 2)).all(-1)
            yield j, so3.log(gt @ est.transpose(-1, -2), check=False), m

    def forward(self, w_hat: torch.Tensor, dt: torch.Tensor, dR: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Sum over increment lengths of weight x the Huber mean over the components of available increments.

        Masked means, not boolean indexing or a branch on the mask: both would wait for the device
        (a host sync) at every training step. A length with no available increment adds 0.
        """
        total = w_hat.new_zeros((), dtype=torch.float64)
        for _, r, m in self.residuals(w_hat, dt, dR, mask):
            rho = F.huber_loss(r, torch.zeros_like(r), reduction="none", delta=self.delta)
            rho = torch.where(m[..., None], rho, 0.0)  # ground truth is finite where missing (SLERP)
            total = total + self.weight * rho.sum() / (3 * m.sum()).clamp(min=1)
        return total
