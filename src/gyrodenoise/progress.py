"""Progress over epochs: training here takes one optimiser step per epoch (one random crop per
sequence, the paper's schedule), so Lightning's default bar, one bar per epoch, shows a 1-step bar that
restarts every epoch and says nothing about the run.

`EpochProgressBar` shows ONE bar over all epochs (epoch i/max_epochs, elapsed < time left, the current
train loss and the latest validation AOE). Where stdout is not a terminal (a log file, a Slurm job, a
test's captured output), redrawn bars would fill the file with carriage returns, so it prints one plain
line every `print_every_n_epochs` epochs, after each validation and after the last epoch, and no bars at all (with
a bar, the same lines go to the run's log file):

    epoch 40/300 | 0:08 elapsed, 0:52 left | train/loss 0.0712 | val/aoe_deg 1.310
"""

from __future__ import annotations

import sys
import time
from typing import Any

import lightning.pytorch as L
from lightning.pytorch.callbacks import TQDMProgressBar
from lightning.pytorch.callbacks.progress.tqdm_progress import Tqdm
from tqdm import tqdm

from gyrodenoise.job_log import write_to_job_log

SHOWN = ("train/loss", "val/aoe_deg")  # what each line / the bar's postfix reports (logged with prog_bar=True)


class EpochProgressBar(TQDMProgressBar):
    """One bar over epochs on a terminal; a plain line every N epochs otherwise.

    Args:
        print_every_n_epochs: without a terminal, print a line every this many epochs (and after the last).
        plain: force plain lines (True) or bars (False); None: plain when stdout is not a terminal.
        refresh_rate, leave: as for Lightning's TQDMProgressBar (validation and test bars).
    """

    def __init__(
        self, print_every_n_epochs: int = 20, plain: bool | None = None, refresh_rate: int = 1, leave: bool = False
    ) -> None:
        super().__init__(refresh_rate=refresh_rate, leave=leave)
        if print_every_n_epochs < 1:
            raise ValueError(f"print_every_n_epochs={print_every_n_epochs}; give a positive number of epochs")
        self.print_every_n_epochs = print_every_n_epochs
        self._plain = plain
        self._start_epoch = 0
        self._start_time = 0.0

    @property
    def plain(self) -> bool:
        return not sys.stdout.isatty() if self._plain is None else self._plain

    @property
    def is_enabled(self) -> bool:
        # in plain mode no tqdm bar at all (validation and test included); the lines below replace them
        return super().is_enabled and not self.plain

    def get_metrics(self, trainer: L.Trainer, pl_module: L.LightningModule | None = None) -> dict[str, str]:
        """The bar's postfix (Lightning's hook for it) and the plain line's metrics: loss and latest val AOE."""
        m = trainer.progress_bar_metrics
        return {k: f"{float(m[k]):.4g}" for k in SHOWN if k in m}

    def init_train_tqdm(self) -> Tqdm:
        bar = super().init_train_tqdm()
        bar.set_description("Training")
        bar.unit = "epoch"
        return bar

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._start_epoch = trainer.current_epoch  # > 0 when resumed from a checkpoint
        self._val_epoch: int | None = None
        self._start_time = time.monotonic()
        self.train_progress_bar = self.init_train_tqdm()
        total = trainer.max_epochs if trainer.max_epochs is not None and trainer.max_epochs > 0 else None
        self.train_progress_bar.reset(total=total)
        self.train_progress_bar.initial = self._start_epoch  # the rate and time left count this run's epochs only
        self.train_progress_bar.n = self._start_epoch

    def on_validation_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        super().on_validation_end(trainer, pl_module)
        if not trainer.sanity_checking:
            self._val_epoch = trainer.current_epoch + 1  # the plain line says how old its val figure is

    def on_train_epoch_start(self, trainer: L.Trainer, *_: Any) -> None:
        pass  # one bar for the whole run: no per-epoch reset

    def on_train_batch_end(self, *_: Any) -> None:
        pass  # the bar counts epochs, updated at the end of each

    def on_train_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        # validation (when due) has already run in this epoch: its AOE is in the metrics
        done = trainer.current_epoch + 1
        last = trainer.max_epochs is not None and done >= trainer.max_epochs
        # a line every N epochs, after each validation (its figure is new) and at the end
        due = done % self.print_every_n_epochs == 0 or last or trainer.should_stop or self._val_epoch == done
        if self.is_enabled:
            self.train_progress_bar.n = done
            self.train_progress_bar.set_postfix(self.get_metrics(trainer), refresh=True)
            if due:  # the bar is redrawn on the terminal only: the run's log file gets the plain line
                write_to_job_log(self._line(trainer, done) + "\n")
        elif self.plain and self._enabled and due:
            print(self._line(trainer, done), flush=True)

    def _line(self, trainer: L.Trainer, done: int) -> str:
        elapsed = time.monotonic() - self._start_time
        total = trainer.max_epochs if trainer.max_epochs is not None and trainer.max_epochs > 0 else None
        parts = [f"epoch {done}/{total or '?'}"]
        if total and done > self._start_epoch:
            left = elapsed / (done - self._start_epoch) * (total - done)
            parts.append(f"{tqdm.format_interval(elapsed)} elapsed, {tqdm.format_interval(left)} left")
        else:
            parts.append(f"{tqdm.format_interval(elapsed)} elapsed")
        val_epoch = self._val_epoch
        parts += [
            f"{k} {v}" + (f" (epoch {val_epoch})" if k.startswith("val/") and val_epoch not in (None, done) else "")
            for k, v in self.get_metrics(trainer).items()
        ]
        return " | ".join(parts)
