"""The best-validation checkpoint, named by the epochs done (best-epoch0100.ckpt after the 100th epoch), as the
progress line, train.log and summary.json count them; Lightning's {epoch} is the 0-based index (best-epoch0099).
Runs before 2026-11-27 wrote the 0-based index."""

from __future__ import annotations

from lightning.pytorch.callbacks import ModelCheckpoint
from torch import Tensor


class BestCheckpoint(ModelCheckpoint):
    """ModelCheckpoint whose `{epoch}` in the file name is the number of epochs done (1-based)."""

    def format_checkpoint_name(
        self,
        metrics: dict[str, Tensor],
        filename: str | None = None,
        ver: int | None = None,
        prefix: str | None = None,
    ) -> str:
        if "epoch" in metrics:
            metrics = {**metrics, "epoch": metrics["epoch"] + 1}
        return super().format_checkpoint_name(metrics, filename, ver, prefix)
