"""checkpoints/interrupted.ckpt when a run is stopped (SIGTERM, a SLURM time limit, Ctrl-C), removed when it ends.

A stop is taken at the end of the epoch it arrives in: the signal is noted, the epoch finishes (its step, and its
validation when one is due), the checkpoint is written where last.ckpt is (`on_train_epoch_end`) and the fit stops.
A checkpoint written in the middle of a step, as Lightning writes one on an exception, is not resumable exactly: its
batch-norm statistics had seen the step's batch while the optimiser had not stepped, its random stream had drawn the
next crop, and Lightning re-enters the unfinished epoch on resuming (an audit measured 14.48 deg instead of the
uninterrupted run's 10.28 after a Ctrl-C and a resume). A second Ctrl-C stops at once and writes nothing: the run then
goes on from its last.ckpt. A stop asked in the last epoch writes nothing either: the training is complete, and the run
finishes (its test and model file) with exit code 0. One epoch is one optimiser step, well under a second on a CPU, so
the wait is short; SLURM's grace period after SIGTERM (30 s by default) covers it.

It does what Lightning's OnExceptionCheckpoint does, and is not one on purpose: with an OnExceptionCheckpoint among
the callbacks, Lightning turns `fit(ckpt_path=None)` into `ckpt_path="last"` and silently restores the newest
last.ckpt / interrupted.ckpt it finds in the run folder (measured with Lightning 2.6: `auto_resume=false` in the
folder of an unfinished run went on from its epoch-6 last.ckpt instead of starting afresh, and every fresh run
printed two warnings about it). Resuming is the train command's decision (`auto_resume`, `ckpt_path`), not a side
effect of a callback.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Any

import lightning.pytorch as L
from lightning.pytorch.callbacks import Checkpoint
from lightning.pytorch.trainer.states import TrainerStatus

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class InterruptionCheckpoint(Checkpoint):
    def __init__(self, dirpath: str, filename: str = "interrupted") -> None:
        super().__init__()
        if not filename:
            raise ValueError("InterruptionCheckpoint: the filename cannot be empty")
        self.dirpath, self.filename = dirpath, filename
        self.stop_signal: int | None = None  # the signal that asked the run to stop, once one has
        self.saved = False  # interrupted.ckpt written at an epoch's end
        self._previous: dict[int, Any] = {}

    @property
    def ckpt_path(self) -> str:
        return os.path.join(self.dirpath, self.filename + ".ckpt")

    def on_train_start(self, trainer: L.Trainer, *_: Any) -> None:
        # here, not at on_fit_start: Lightning installs its own SIGTERM handler after that hook, and its handler
        # stops the fit in the middle of an epoch
        if threading.current_thread() is not threading.main_thread():  # signals reach the main thread only
            return
        for sig in STOP_SIGNALS:
            self._previous[sig] = signal.getsignal(sig)
            signal.signal(sig, self._request_stop)

    def _request_stop(self, signum: int, _frame: Any) -> None:
        if self.stop_signal is not None:
            if signum == signal.SIGINT:  # asked twice: stop now, without a checkpoint
                self._restore()
                raise KeyboardInterrupt
            return
        self.stop_signal = signum
        print(
            f"\n{signal.Signals(signum).name}: stopping at the end of this epoch and writing {self.ckpt_path} to "
            "resume from" + (" (Ctrl-C again stops at once, without it)" if signum == signal.SIGINT else ""),
            file=sys.stderr,
            flush=True,
        )

    def on_train_epoch_end(self, trainer: L.Trainer, *_: Any) -> None:
        if self.stop_signal is not None and not self.saved and not _last_epoch(trainer):
            trainer.save_checkpoint(self.ckpt_path, weights_only=False)  # said, or Lightning logs its default
            self.saved = True
            trainer.should_stop = True

    def on_train_end(self, *_: Any) -> None:
        self._restore()
        if self.stop_signal is not None and not self.saved:  # it came in the last epoch: nothing is left to resume
            print(
                f"{signal.Signals(self.stop_signal).name} came in the training's last epoch: the training is complete, "
                "so the run finishes (its test and model file) instead of writing a checkpoint to resume from",
                file=sys.stderr,
                flush=True,
            )

    def on_exception(self, *_: Any, **__: Any) -> None:
        self._restore()

    def teardown(self, trainer: L.Trainer, *_: Any, **__: Any) -> None:
        self._restore()
        # a run that ended normally keeps none; one stopped at once, or failing, keeps the one it resumed from (an
        # epoch's end too; auto_resume takes the newer of it and last.ckpt)
        if trainer.state.status != TrainerStatus.INTERRUPTED and not self.saved:  # RUNNING still at a normal end
            trainer.strategy.remove_checkpoint(self.ckpt_path)

    def _restore(self) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous = {}


def _last_epoch(trainer: L.Trainer) -> bool:
    """This epoch ends the fit anyway (max_epochs or max_steps reached): a checkpoint would resume to nothing."""
    epochs, steps = trainer.max_epochs, trainer.max_steps
    return (epochs is not None and epochs >= 0 and trainer.current_epoch + 1 >= epochs) or (
        steps is not None and steps >= 0 and trainer.global_step >= steps
    )


def stopped_by(trainer: L.Trainer) -> int | None:
    """The signal that stopped this fit at an epoch's end (its interrupted.ckpt written), or None."""
    found = [c for c in trainer.callbacks if isinstance(c, InterruptionCheckpoint) and c.saved]
    return found[0].stop_signal if found else None
