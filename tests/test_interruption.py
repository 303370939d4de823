"""A run stopped by Ctrl-C or SIGTERM and resumed ends on the weights of the run never stopped (from a
reproducibility audit: the checkpoint written in the middle of a step resumed to 14.48 deg instead of 10.28)."""

from __future__ import annotations

import signal

import pytest
import torch
from test_train import config

from gyrodenoise.paths import portable_path
from gyrodenoise.train import train


@pytest.fixture
def root(tiny_asl_root):
    return tiny_asl_root


def _run(root, out, *extra):
    cfg = config(root, out, "seed=5", "trainer.max_epochs=5", "optim.scheduler.T_0=5", "model.dropout=0.1", *extra)
    cfg.callbacks.last_checkpoint.every_n_epochs = 50  # none written in 5 epochs: only the interruption's
    return train(cfg)


def _weights(folder):
    return torch.load(folder / "model.pt", weights_only=True)["state_dict"]


@pytest.mark.parametrize(("callback", "code"), [("InterruptAtEpoch", 130), ("TerminateAtEpoch", 143)])
def test_a_stopped_and_resumed_run_ends_on_the_uninterrupted_runs_weights(root, tmp_path, callback, code, capsys):
    whole = tmp_path / "whole"
    _run(root, whole)
    run = tmp_path / "run"
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(SystemExit) as stop:
            _run(root, run, f"+callbacks.interrupt._target_=test_damaged_inputs.{callback}")
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    assert stop.value.code == code
    assert (run / "checkpoints" / "interrupted.ckpt").is_file() and not (run / "model.pt").exists()
    # the handlers the fit found are back: a later Ctrl-C is the shell's again
    assert all(signal.getsignal(s) is h for s, h in handlers.items())
    capsys.readouterr()
    summary = _run(root, run)  # the same command in the same folder: auto_resume
    assert "auto_resume: " in capsys.readouterr().out and summary["epochs"] == 5
    a, b = _weights(whole), _weights(run)
    for k in a:
        torch.testing.assert_close(b[k], a[k], rtol=0, atol=0, msg=k)


def test_a_resume_with_another_seed_or_other_data_is_refused_and_a_resume_is_recorded(root, tmp_path, capsys):
    """The audit resumed with seed=5 and dataset.window=4800: both were accepted and recorded in summary.json, while
    the run went on with the first part's random stream, and half of it had trained on other crops."""
    from gyrodenoise.cli_errors import ConfigError

    first = config(root, tmp_path / "first", "seed=0", "trainer.max_epochs=2", "optim.scheduler.T_0=4")
    first.callbacks.last_checkpoint.every_n_epochs = 1
    train(first)
    last = tmp_path / "first" / "checkpoints" / "last.ckpt"
    common = ("trainer.max_epochs=4", "optim.scheduler.T_0=4", f"ckpt_path={last}")
    with pytest.raises(ConfigError, match=r"seed=0 there, 5 here"):
        train(config(root, tmp_path / "seed5", "seed=5", *common))
    with pytest.raises(ConfigError, match=r"dataset.window="):
        train(config(root, tmp_path / "window", "seed=0", "dataset.window=400", *common))
    # where the files are is not a setting of the run: a resume on another machine's mount is fine
    summary = train(config(root, tmp_path / "resumed", "seed=null", *common))
    assert summary["seed"] == 0  # seed=null resumed: the first part's seed
    # the path as reports write it (relative where the checkout lies beside pytest's folder, e.g. under /tmp)
    assert summary["resumed_from"] == {"checkpoint": portable_path(last), "epochs_done": 2}
    assert {"python", "torch", "lightning", "numpy"} <= set(summary["versions"])


def test_seed_null_draws_a_seed_and_records_it(root, tmp_path, capsys):
    summary = train(config(root, tmp_path / "run", "seed=null", "trainer.max_epochs=1", "optim.scheduler.T_0=1"))
    assert isinstance(summary["seed"], int) and summary["config"]["seed"] == summary["seed"]
    assert f"drew seed={summary['seed']}" in capsys.readouterr().out
    again = train(config(root, tmp_path / "again", f"seed={summary['seed']}", "trainer.max_epochs=1",
                         "optim.scheduler.T_0=1"))  # fmt: skip
    assert again["val"] == summary["val"]


def test_a_stop_in_the_last_epoch_finishes_the_run(root, tmp_path, capsys):
    """The training is complete there: a checkpoint would resume to nothing (it was written, and the run exited
    130 without its test and model file)."""
    run = tmp_path / "run"
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        summary = _run(root, run, "+callbacks.interrupt._target_=test_damaged_inputs.TerminateAtEpoch",
                       "+callbacks.interrupt.epoch=4")  # fmt: skip
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    assert summary["epochs"] == 5 and (run / "model.pt").is_file()
    assert not (run / "checkpoints" / "interrupted.ckpt").exists()
    assert "SIGTERM came in the training's last epoch" in capsys.readouterr().err


def test_a_checkpoint_of_a_version_without_a_setting_resumes_with_a_warning(root, tmp_path):
    """A later version that adds a data setting refused every older checkpoint ('window' absent there)."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.train import check_resumed_settings, resume_settings

    first = config(root, tmp_path / "first", "seed=0", "trainer.max_epochs=1", "optim.scheduler.T_0=2")
    first.callbacks.last_checkpoint.every_n_epochs = 1
    train(first)
    path = tmp_path / "first" / "checkpoints" / "last.ckpt"
    ckpt = torch.load(path, weights_only=False)
    settings = resume_settings(first)
    window = settings["dataset"]["window"]
    del ckpt["run_settings"]["dataset"]["window"]  # as written by a version without it
    torch.save(ckpt, path)
    hparams = dict(ckpt["hyper_parameters"])
    with pytest.warns(UserWarning, match=rf"without dataset.window \(here {window}\)"):
        assert check_resumed_settings(str(path), hparams, resume_settings(first)) == 1
    first.dataset.window = window // 2  # a setting the checkpoint recorded still has to match
    ckpt["run_settings"]["dataset"]["window"] = window
    torch.save(ckpt, path)
    with pytest.raises(ConfigError, match=rf"dataset.window={window} there, {window // 2} here"):
        check_resumed_settings(str(path), hparams, resume_settings(first))
