"""A refused rerun in a run's folder leaves the folder's Hydra record as it was (gyrodenoise.run_record); the
subprocess test of a refusal by train itself is in test_cli_errors.py."""

from __future__ import annotations

import hydra
import pytest
from hydra.errors import InstantiationException
from omegaconf import OmegaConf

from gyrodenoise.run_record import KeepRunRecord, restored_on_refusal


def test_a_refusal_inside_a_config_target_restores_the_record(tmp_path):
    """The data module's ConfigError (loss.increments not powers of two, a cv_fold out of range, ...) reaches the
    task as the cause of Hydra's InstantiationException: still a refusal, the folder's record is put back."""
    record = tmp_path / ".hydra"
    record.mkdir()
    (record / "overrides.yaml").write_text("- seed=1\n")
    cfg = OmegaConf.create({"hydra": {"output_subdir": ".hydra", "run": {"dir": str(tmp_path)}}})
    KeepRunRecord().on_run_start(cfg)
    (record / "overrides.yaml").write_text("- loss.increments=[80,160]\n")  # what Hydra wrote for the rerun
    (record / "config.yaml").write_text("loss: {increments: [80, 160]}\n")
    data = {
        "_target_": "gyrodenoise.data.datamodule.ImuDataModule",
        "name": "mine",
        "root": str(tmp_path),
        "train_seqs": ["a"],
        "test_seqs": [],
        "increments": [80, 160],
    }
    with pytest.raises(InstantiationException, match="powers of two"), restored_on_refusal():
        hydra.utils.instantiate(data)
    assert {p.name: p.read_text() for p in record.iterdir()} == {"overrides.yaml": "- seed=1\n"}


def test_other_errors_keep_the_new_record(tmp_path):
    """A task that ran and failed otherwise (not a refusal) keeps the record of the command that ran."""
    record = tmp_path / ".hydra"
    record.mkdir()
    (record / "overrides.yaml").write_text("- seed=1\n")
    KeepRunRecord().on_run_start(
        OmegaConf.create({"hydra": {"output_subdir": ".hydra", "run": {"dir": str(tmp_path)}}})
    )
    (record / "overrides.yaml").write_text("- seed=2\n")
    with pytest.raises(RuntimeError), restored_on_refusal():
        raise RuntimeError("diverged")
    assert (record / "overrides.yaml").read_text() == "- seed=2\n"
