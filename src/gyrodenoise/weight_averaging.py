"""EMA of the weights whose batch-norm statistics belong to the averaged weights.

Lightning's EMAWeightAveraging averages the batch-norm running statistics along with the weights.
Statistics averaged over the last ~100 epochs do not describe the activations of the averaged weights:
measured on EuRoC (reports/accuracy.md, 4 seeds), the averaged model validated 0.9 deg worse than the
final weights, and recomputing its statistics on the training crops removed the whole difference.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import lightning as L
import torch
from lightning.pytorch.callbacks import EMAWeightAveraging
from torch import nn
from torch.optim.swa_utils import update_bn


def recompute_batch_norm(model: nn.Module, inputs: Iterable[torch.Tensor], device: torch.device | None = None) -> None:
    """Replace the running statistics of every batch norm of `model` by their average over `inputs`
    (IMU tensors (B, N, 6)), forwarded in training mode as during training (torch's update_bn)."""
    update_bn(inputs, model, device=device)


def training_inputs(datamodule: L.LightningDataModule, batches: int) -> Iterator[torch.Tensor]:
    """`batches` training batches of `datamodule` (their IMU tensor), drawn as the training loop draws them."""
    n = 0
    while n < batches:
        for batch in datamodule.train_dataloader():
            yield batch["imu"]
            n += 1
            if n == batches:
                return


class EMAWithBatchNorm(EMAWeightAveraging):
    """EMAWeightAveraging whose averaged weights get their own batch-norm statistics at the end of fit,
    from `bn_batches` training batches. Validation during fit still uses the averaged statistics
    (recomputing them at every validation would cost more than the validation)."""

    def __init__(self, bn_batches: int = 20, **kwargs) -> None:
        super().__init__(**kwargs)
        if bn_batches < 1:
            raise ValueError(f"bn_batches={bn_batches}: at least one training batch is needed")
        self.bn_batches = bn_batches

    def on_train_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        super().on_train_end(trainer, pl_module)  # the averaged weights are now the module's
        dm = trainer.datamodule
        if dm is None:
            raise RuntimeError("EMAWithBatchNorm needs the trainer's datamodule to recompute batch-norm statistics")
        recompute_batch_norm(pl_module, training_inputs(dm, self.bn_batches), device=pl_module.device)
        # validation swaps the averaged copy in: make it hold the same statistics
        assert self._average_model is not None
        self._average_model.module.load_state_dict(pl_module.state_dict())
