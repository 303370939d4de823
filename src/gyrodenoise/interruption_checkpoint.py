"""checkpoints/interrupted.ckpt when a run is stopped (SIGTERM, a SLURM time limit, Ctrl-C), removed when it ends.

It does what Lightning's OnExceptionCheckpoint does, and is not one on purpose: with an OnExceptionCheckpoint among
the callbacks, Lightning turns `fit(ckpt_path=None)` into `ckpt_path="last"` and silently restores the newest
last.ckpt / interrupted.ckpt it finds in the run folder (measured with Lightning 2.6: `auto_resume=false` in the
folder of an unfinished run went on from its epoch-6 last.ckpt instead of starting afresh, and every fresh run
printed two warnings about it). Resuming is the train command's decision (`auto_resume`, `ckpt_path`), not a side
effect of a callback.

Nothing is written when the fit stops before its first optimiser step (a data file refused while the fit sets up):
such a checkpoint holds the untrained weights with the default normalisation (mean 0, std 1, the data's statistics
are set later in the set-up), so the rerun in that folder, once the file was fixed, resumed from it and trained
without the data's normalisation; and a resumed run that failed there overwrote the checkpoint it resumed from.
"""

from __future__ import annotations

import os
from typing import Any

import lightning.pytorch as L
from lightning.pytorch.callbacks import Checkpoint


class InterruptionCheckpoint(Checkpoint):
    def __init__(self, dirpath: str, filename: str = "interrupted") -> None:
        super().__init__()
        if not filename:
            raise ValueError("InterruptionCheckpoint: the filename cannot be empty")
        self.dirpath, self.filename = dirpath, filename

    @property
    def ckpt_path(self) -> str:
        return os.path.join(self.dirpath, self.filename + ".ckpt")

    def on_exception(self, trainer: L.Trainer, *_: Any, **__: Any) -> None:
        if trainer.global_step == 0:  # not one step trained (or, resuming, not restored yet): nothing to resume
            return
        trainer.save_checkpoint(self.ckpt_path, weights_only=False)  # said, or Lightning logs its default

    def teardown(self, trainer: L.Trainer, *_: Any, **__: Any) -> None:  # a run that ended normally keeps none
        trainer.strategy.remove_checkpoint(self.ckpt_path)
