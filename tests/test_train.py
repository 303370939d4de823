"""Training entry point on tiny synthetic data: seeded runs are reproducible, ckpt_path resumes."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from _asl import write_asl_sequence
from hydra import compose, initialize_config_dir

import gyrodenoise
from gyrodenoise.train import format_test_table, train


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("asl_train")
    for i, name in enumerate(["a", "b", "c"]):
        write_asl_sequence(root / name, seconds=6.0, seed=10 + i)
    return root


def config(root: Path, out: Path, *extra: str):
    overrides = [
        "dataset=euroc",
        f"dataset.root={root}",
        "dataset.train_seqs=[a,b]",
        "dataset.test_seqs=[c]",
        "dataset.train_duration_s=4",
        "dataset.window=256",
        "dataset.gt_files={}",
        "dataset.eval_gt_variants={}",
        "model.channels=[4,8]",
        "model.dilations=[1,2]",
        "trainer.max_epochs=3",
        "trainer.check_val_every_n_epoch=1",
        "trainer.accelerator=cpu",
        "optim.scheduler.T_0=2",
        "logger=none",
        f"paths.output_dir={out}",
        *extra,
    ]
    with initialize_config_dir(str(Path(gyrodenoise.__file__).parent / "conf"), version_base="1.3"):
        return compose("train", overrides=overrides)


def test_seeded_runs_are_reproducible(root, tmp_path):
    a = train(config(root, tmp_path / "a", "seed=3"))
    b = train(config(root, tmp_path / "b", "seed=3"))
    sa = torch.load(tmp_path / "a" / "model.pt", weights_only=True)["state_dict"]
    sb = torch.load(tmp_path / "b" / "model.pt", weights_only=True)["state_dict"]
    for k in sa:
        torch.testing.assert_close(sa[k], sb[k], rtol=0, atol=0)
    assert a["val"]["val/aoe_deg"] == b["val"]["val/aoe_deg"]
    assert "test/aoe_deg" in a["test"] and (tmp_path / "a" / "summary.json").is_file()
    # the raw IMU as a reference: no correction model of any kind, so both runs agree and it is finite
    assert a["test"]["test/raw_imu_aoe_deg/c"] == b["test"]["test/raw_imu_aoe_deg/c"] > 0
    # the safety net: the calibrated baseline fitted on the same data, compared on the same validation
    safety = a["calibrated_baseline"]
    assert safety["beats_calibrated"] in (True, False) and safety["calibrated_test_aoe_deg"] > 0
    meta = torch.load(tmp_path / "a" / "model.pt", weights_only=True)["meta"]
    assert meta["beats_calibrated"] == safety["beats_calibrated"] and (tmp_path / "a" / "calibrated.pt").is_file()
    table = format_test_table(a["test"])
    assert "| c |" in table and "| **average** |" in table and "nan" not in table


def test_ckpt_path_resumes(root, tmp_path):
    # validation only after epoch 1: the best checkpoint stays at epoch 1, last.ckpt must still follow
    # every epoch (Lightning >= 2.6 would otherwise leave it at the last best one)
    first = config(root, tmp_path / "first", "trainer.max_epochs=3", "trainer.check_val_every_n_epoch=2")
    first.callbacks.last_checkpoint.every_n_epochs = 1  # the default (50) would not save in 3 epochs
    train(first)
    last = tmp_path / "first" / "checkpoints" / "last.ckpt"
    assert torch.load(last, weights_only=False)["epoch"] == 2
    assert [p.name for p in (tmp_path / "first" / "checkpoints").glob("best-*")] == ["best-epoch0001.ckpt"]
    resumed = train(config(root, tmp_path / "second", "trainer.max_epochs=4", f"ckpt_path={last}"))
    assert resumed["epochs"] == 4
