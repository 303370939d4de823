"""EpochProgressBar: one bar over epochs on a terminal, plain lines every N epochs in a log."""

from __future__ import annotations

import lightning.pytorch as L
import pytest
import torch

from gyrodenoise.progress import EpochProgressBar


class Tiny(L.LightningModule):
    """One batch per epoch, logging the metrics the bar shows (as DenoiserModule does)."""

    def __init__(self) -> None:
        super().__init__()
        self.w = torch.nn.Parameter(torch.ones(1))

    def training_step(self, batch, batch_idx):
        loss = (self.w * batch[0]).pow(2).mean()
        self.log("train/loss", loss, prog_bar=True)
        return loss

    def validation_step(self, batch, batch_idx):
        self.log("val/aoe_deg", 1.5 + self.current_epoch, prog_bar=True)

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.1)

    def train_dataloader(self):
        return torch.utils.data.DataLoader(torch.utils.data.TensorDataset(torch.ones(2, 1)), batch_size=2)

    val_dataloader = train_dataloader


def fit(bar: EpochProgressBar, epochs: int) -> None:
    trainer = L.Trainer(
        max_epochs=epochs,
        check_val_every_n_epoch=3,
        num_sanity_val_steps=0,
        callbacks=[bar],
        logger=False,
        enable_checkpointing=False,
        enable_model_summary=False,
        accelerator="cpu",
    )
    trainer.fit(Tiny())


def test_plain_lines_every_n_epochs(capsys):
    fit(EpochProgressBar(print_every_n_epochs=2, plain=True), epochs=5)
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("epoch ")]
    # every 2 epochs, after the validation (epoch 3) and the last one
    assert [ln.split(" | ")[0] for ln in lines] == ["epoch 2/5", "epoch 3/5", "epoch 4/5", "epoch 5/5"]
    # the latest validation, with its epoch when it is older than the line
    assert "val/aoe_deg" not in lines[0] and lines[1].endswith("| val/aoe_deg 3.5")
    assert lines[2].endswith("| val/aoe_deg 3.5 (epoch 3)")
    assert " elapsed, " in lines[0] and " left | train/loss " in lines[0]


def test_one_bar_over_all_epochs(capsys):
    bar = EpochProgressBar(plain=False)
    fit(bar, epochs=5)
    out = capsys.readouterr().out
    assert bar.train_progress_bar.n == bar.train_progress_bar.total == 5  # counts epochs, not batches
    assert "Epoch 1" not in out  # no per-epoch bar
    final = out.split("\r")[-1]  # the last redraw of the one bar
    assert final.startswith("Training: 100%") and "5/5" in final and "epoch/s" in final
    assert "train/loss=" in final and "val/aoe_deg=3.5]" in final  # latest validation AOE (epoch 3)


def test_with_a_bar_the_run_log_still_gets_the_plain_lines(tmp_path):
    from gyrodenoise.job_log import console_to_job_log

    with console_to_job_log(tmp_path / "train.log"):
        fit(EpochProgressBar(print_every_n_epochs=2, plain=False), epochs=5)
    lines = [ln for ln in (tmp_path / "train.log").read_text().splitlines() if ln.startswith("epoch ")]
    assert [ln.split(" | ")[0] for ln in lines] == ["epoch 2/5", "epoch 3/5", "epoch 4/5", "epoch 5/5"]
    assert "\r" not in (tmp_path / "train.log").read_text()


def test_rejects_nonpositive_interval():
    with pytest.raises(ValueError, match="print_every_n_epochs"):
        EpochProgressBar(print_every_n_epochs=0)


def test_a_handler_made_in_one_job_writes_into_the_next_jobs_log(tmp_path):
    """Lightning's console handler, made at its import inside the first job of a sequential sweep, kept that job's
    tee: from the second job on every record was a '--- Logging error --- I/O operation on closed file'."""
    import logging

    from gyrodenoise.job_log import console_to_job_log

    log = logging.getLogger("gyrodenoise.test.sweep")
    log.propagate = False
    try:
        with console_to_job_log(tmp_path / "0.log"):
            handler = logging.StreamHandler()  # binds sys.stderr: job 0's tee
            log.addHandler(handler)
            log.warning("job 0")
        with console_to_job_log(tmp_path / "1.log"):
            log.warning("job 1")
    finally:
        log.removeHandler(handler)
    assert (tmp_path / "0.log").read_text() == "job 0\n"
    assert (tmp_path / "1.log").read_text() == "job 1\n"
