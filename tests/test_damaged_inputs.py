"""Damaged files and interrupted runs (found by a bad-input audit): each is named, rebuilt or refused, and an
interrupted rerun leaves no earlier run's summary beside its new outputs."""

from __future__ import annotations

import json
import os
import shutil
import signal
import warnings
from pathlib import Path

import lightning.pytorch as L
import numpy as np
import pytest
from _asl import write_asl_sequence
from test_train import config

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.readers import DataFormatWarning, read_imu
from gyrodenoise.models.build import build_model
from gyrodenoise.pretrained import ModelFileError, load_model, save_model
from gyrodenoise.train import train


@pytest.fixture
def root(tiny_asl_root) -> Path:
    return tiny_asl_root


def imu_file(root: Path, name: str = "a") -> Path:
    return root / name / "mav0" / "imu0" / "data.csv"


def test_a_byte_order_mark_is_not_data(root, tmp_path):
    f = tmp_path / "bom.csv"
    f.write_text("\ufeff" + imu_file(root).read_text(), encoding="utf-8")
    np.testing.assert_array_equal(read_imu(f).gyro, read_imu(imu_file(root)).gyro)


def test_a_file_cut_mid_line_is_named(root, tmp_path):
    f = tmp_path / "cut.csv"
    text = imu_file(root).read_text()
    f.write_text(text.rstrip("\n")[:-4])  # the last number loses digits, every column still there
    n_lines = text.count("\n")
    with pytest.warns(DataFormatWarning, match=f"cut.csv:{n_lines}: the file does not end with a line break"):
        read_imu(f)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataFormatWarning)
        read_imu(imu_file(root))  # a whole file: nothing said


def test_a_truncated_model_file_is_named(tmp_path):
    whole = save_model(build_model("denoiser", channels=(4, 8), dilations=(1, 2)), {"name": "denoiser",
                       "channels": (4, 8), "dilations": (1, 2)}, tmp_path / "m.pt", {})  # fmt: skip
    data = whole.read_bytes()
    for k, n in enumerate(np.linspace(100, len(data) - 100, 12).astype(int)):
        cut = tmp_path / f"cut{k}.pt"
        cut.write_bytes(data[:n])
        with pytest.raises(ModelFileError, match=f"cut{k}.pt: not a model file, or a truncated or damaged one"):
            load_model(cut)


def test_a_damaged_cache_file_is_rebuilt(root, tmp_path):
    cache = tmp_path / "cache"
    first = load_sequence(root, "a", cache_dir=cache)
    (npz,) = cache.glob("a-*.npz")
    npz.write_bytes(npz.read_bytes()[:5000])
    with pytest.warns(UserWarning, match="unreadable cache file"):
        again = load_sequence(root, "a", cache_dir=cache)
    np.testing.assert_array_equal(again.gyro, first.gyro)
    np.testing.assert_array_equal(load_sequence(root, "a", cache_dir=cache).gyro, first.gyro)  # rewritten whole


def test_a_sequence_cached_by_other_readers_is_read_again(root, tmp_path, monkeypatch):
    """A sequence cached before a reader changed (a check added since, a column read otherwise) was served as the old
    code had read it: the key held the files and the settings, not the readers. Their source is in the key now."""
    from gyrodenoise.data import cache

    monkeypatch.setattr(cache, "reader_digest", lambda: "the readers of an earlier version")
    first = load_sequence(root, "a", cache_dir=tmp_path / "cache")
    (npz,) = (tmp_path / "cache").glob("a-*.npz")
    with np.load(npz) as z:
        stale = dict(z)
    cache.atomic_save_npz(npz, **(stale | {"gyro": stale["gyro"] + 1.0}))  # what the earlier readers made of the file
    np.testing.assert_array_equal(load_sequence(root, "a", cache_dir=tmp_path / "cache").gyro, first.gyro + 1.0)
    monkeypatch.undo()  # the readers of this version
    np.testing.assert_array_equal(load_sequence(root, "a", cache_dir=tmp_path / "cache").gyro, first.gyro)
    assert len(list((tmp_path / "cache").glob("a-*.npz"))) == 2


def _package_imports(module: str) -> set[str]:
    """The modules of this package that `module` imports, at its top or in a function (`from gyrodenoise.data import
    asl_header` imports the module asl_header; `from gyrodenoise.data.readers import ImuData`, readers)."""
    import ast
    import importlib.util

    found = set()
    for node in ast.walk(ast.parse(Path(importlib.import_module(module).__file__).read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("gyrodenoise")}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("gyrodenoise"):
            package = hasattr(importlib.import_module(node.module), "__path__")
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                found.add(sub if package and importlib.util.find_spec(sub) else node.module)
    return found


def test_the_cache_key_holds_every_module_the_readers_import():
    """`cache.READER_MODULES` (whose source is in the cache key) holds the modules of the functions the cache calls to
    read a sequence and every module of this package they import: one left out could change unseen by the key."""
    from gyrodenoise.data import cache

    listed = set(cache.READER_MODULES)
    assert {f.__module__ for f in (cache.read_imu, cache.read_groundtruth, cache.build_sequence)} <= listed
    missing = set().union(*map(_package_imports, listed)) - listed
    assert not missing, f"the readers import {sorted(missing)}: add them to cache.READER_MODULES"


def test_a_truncated_checkpoint_to_resume_from_is_refused(root, tmp_path):
    bad = tmp_path / "last.ckpt"
    bad.write_bytes(b"PK\x03\x04" + b"\0" * 100)
    with pytest.raises(ConfigError, match="not a readable Lightning checkpoint"):
        train(config(root, tmp_path / "run", f"ckpt_path={bad}"))
    # the message states the run's own cadence of last.ckpt, not a fixed one
    every_7 = config(root, tmp_path / "run", f"ckpt_path={bad}", "callbacks.last_checkpoint.every_n_epochs=7")
    with pytest.raises(ConfigError, match=r"last.ckpt \(written every 7 epochs\)"):
        train(every_7)
    with pytest.raises(ConfigError, match=r"no\.ckpt: no such file; give"):  # not called damaged
        train(config(root, tmp_path / "run", f"ckpt_path={tmp_path / 'no.ckpt'}"))


class InterruptAtEpoch(L.Callback):
    """Ctrl-C during the fit: the signal itself, in the middle of epoch `epoch`'s end."""

    signum = signal.SIGINT

    def __init__(self, epoch: int = 1) -> None:
        self.epoch = epoch

    def on_train_epoch_end(self, trainer, module) -> None:
        if trainer.current_epoch == self.epoch:
            os.kill(os.getpid(), self.signum)


class TerminateAtEpoch(InterruptAtEpoch):
    """SIGTERM (a SLURM time limit, scancel) during the fit."""

    signum = signal.SIGTERM


class InterruptAtStart(L.Callback):
    """Ctrl-C while the fit sets up, before its first step."""

    def on_train_start(self, trainer, module) -> None:
        raise KeyboardInterrupt


class FirstEpoch(L.Callback):
    """Records the epoch a fit starts at (0 unless it resumed from a checkpoint)."""

    seen: list[int] = []

    def on_train_epoch_start(self, trainer, module) -> None:
        FirstEpoch.seen.append(trainer.current_epoch)


def test_an_interrupted_training_says_how_to_resume(root, tmp_path, capsys):
    handler = signal.getsignal(signal.SIGINT)
    cb = "+callbacks.interrupt._target_=test_damaged_inputs.InterruptAtEpoch"
    every_2 = "callbacks.last_checkpoint.every_n_epochs=2"
    try:
        with pytest.raises(SystemExit) as stop:
            train(config(root, tmp_path / "run", cb, every_2, "trainer.max_epochs=4"))
    finally:
        signal.signal(signal.SIGINT, handler)
    assert stop.value.code == 130 and signal.getsignal(signal.SIGINT) is handler
    err = capsys.readouterr().err
    assert "SIGINT: stopping at the end of this epoch" in err
    assert "interrupted at epoch 2: no model.pt written; resume with ckpt_path=" in err
    assert "interrupted.ckpt (written at the end of that epoch)" in err and "last.ckpt is written every 2 epochs" in err
    assert not (tmp_path / "run" / "model.pt").exists()
    # auto_resume=false starts afresh in that folder: Lightning's OnExceptionCheckpoint made fit() restore the
    # newest last/interrupted checkpoint there by itself (gyrodenoise.interruption_checkpoint)
    shutil.copytree(tmp_path / "run", tmp_path / "fresh")
    FirstEpoch.seen.clear()
    first = "+callbacks.first._target_=test_damaged_inputs.FirstEpoch"
    assert train(config(root, tmp_path / "fresh", first, every_2, "trainer.max_epochs=4", "auto_resume=false"))
    assert FirstEpoch.seen == [0, 1, 2, 3] and "auto_resume: " not in capsys.readouterr().out
    # resuming with other settings is refused: they would be recorded in summary.json and not used
    changed = config(root, tmp_path / "run", every_2, "trainer.max_epochs=4", "optim.lr=0.003")
    with pytest.raises(ConfigError, match=r"trained with other settings \(optim.lr=0.01 there, 0.003 here\)"):
        train(changed)
    # the same command in the same folder (a requeued cluster job) goes on from that checkpoint and finishes
    summary = train(config(root, tmp_path / "run", every_2, "trainer.max_epochs=4"))
    assert "auto_resume: " in capsys.readouterr().out and summary["epochs"] == 4
    assert not (tmp_path / "run" / "checkpoints" / "interrupted.ckpt").exists()  # removed at a normal end
    # a finished run's folder takes no second run: its checkpoints, logs and curves would be mixed with the new ones
    with pytest.raises(ConfigError, match="holds a finished run"):
        train(config(root, tmp_path / "run", every_2, "trainer.max_epochs=4"))


def test_an_interrupted_correct_rerun_leaves_no_earlier_summary(root, tmp_path, monkeypatch):
    import gyrodenoise.correct as correct

    out = tmp_path / "out"
    cal = save_model(build_model("calibrated"), {"name": "calibrated"}, tmp_path / "cal.pt", {"rate_hz": 200.0})
    assert correct.main([str(imu_file(root)), "-m", str(cal), "-o", str(out)]) == 0
    assert json.loads((out / "correct_summary.json").read_text())["model"]
    real_write = correct.write_text

    def stop_after_the_csv(path, text):
        if Path(path).name != "imu_corrected.csv":
            raise KeyboardInterrupt
        return real_write(path, text)

    monkeypatch.setattr(correct, "write_text", stop_after_the_csv)
    assert correct.main([str(imu_file(root)), "-m", str(cal), "-o", str(out)]) == 130  # Ctrl-C: one line, 130
    assert (out / "imu_corrected.csv").is_file()
    assert not (out / "correct_summary.json").exists() and not (out / "orientation.txt").exists()


def test_export_to_a_folder_is_refused_before_the_work(tmp_path, capsys):
    from gyrodenoise.export import main

    assert main(["euroc-calibrated", "--onnx", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    hint = f"give a file path, e.g. {tmp_path / 'model.onnx'}"
    assert err == f"error: --onnx {tmp_path}: cannot write: {tmp_path} is a folder: {hint}\n"


def test_a_truth_covering_part_of_the_recording_is_said(root, tmp_path):
    from gyrodenoise.data import consistency

    part = tmp_path / "part"
    write_asl_sequence(part / "a", seconds=6.0, seed=20)
    gt = part / "a" / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    lines = gt.read_text().splitlines(keepends=True)
    gt.write_text("".join(lines[: 1 + 400]))  # 2 s of truth for 6 s of IMU
    seq = load_sequence(part, "a", cache_dir="")
    with pytest.warns(consistency.DataConsistencyWarning, match=r"801 of 1201 IMU samples lie outside"):
        consistency.check(seq)
    gt.write_text("".join(lines[: 1 + 20]))  # 0.1 s: too short to train on, said in one line
    with pytest.raises(ConfigError, match="check that the ground truth covers the recording"):
        train(config(part, tmp_path / "run", "dataset.train_seqs=[a]", "dataset.test_seqs=[]", "test=false"))


def test_a_data_error_while_the_fit_sets_up_leaves_nothing_to_resume(root, tmp_path, capsys):
    """A file refused while the fit sets up wrote interrupted.ckpt of the untrained model with the default
    normalisation (mean 0, std 1): the rerun in that folder once the file was fixed resumed from it and trained
    without the data's statistics, and a resumed run failing so overwrote the checkpoint it resumed from
    (own-data walkthrough)."""
    from gyrodenoise.data.readers import DataFormatError

    data = tmp_path / "data"
    shutil.copytree(root, data)
    good = imu_file(data, "b").read_text()
    lines = good.splitlines(keepends=True)
    lines[40] = lines[40].split(",", 1)[0] + ",nan," + lines[40].split(",", 2)[2]
    imu_file(data, "b").write_text("".join(lines))
    run = tmp_path / "run"
    with pytest.raises(DataFormatError, match="NaN"):
        train(config(data, run))
    assert not (run / "checkpoints" / "interrupted.ckpt").exists()
    assert "weights_only" not in capsys.readouterr().err  # Lightning's note on its default, at every save
    # a real interruption's checkpoint survives a resumed run that fails in its set-up
    imu_file(data, "b").write_text(good)
    cfg = config(data, tmp_path / "first", "trainer.max_epochs=2")
    cfg.callbacks.last_checkpoint.every_n_epochs = 1
    train(cfg)
    ckpt = run / "checkpoints" / "interrupted.ckpt"
    ckpt.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(tmp_path / "first" / "checkpoints" / "last.ckpt", ckpt)
    before = ckpt.read_bytes()
    imu_file(data, "b").write_text("".join(lines))
    capsys.readouterr()
    with pytest.raises(DataFormatError, match="NaN"):
        train(config(data, run, "trainer.max_epochs=4"))
    assert "auto_resume: " in capsys.readouterr().out and ckpt.read_bytes() == before


def test_an_interruption_before_the_first_step_says_there_is_nothing_to_resume(root, tmp_path, capsys):
    handler = signal.getsignal(signal.SIGINT)
    try:
        with pytest.raises(SystemExit):
            train(config(root, tmp_path / "run", "+callbacks.interrupt._target_=test_damaged_inputs.InterruptAtStart"))
    finally:
        signal.signal(signal.SIGINT, handler)
    err = capsys.readouterr().err
    assert "interrupted before the first training step" in err and "nothing to resume" in err
    assert "ckpt_path=" not in err and not list((tmp_path / "run").glob("checkpoints/*.ckpt"))


def test_what_reading_a_file_said_is_said_again_when_it_comes_from_the_cache(root, tmp_path):
    """A repeated line kept once (or a last line without a line break) is still in the file on the next run, which
    loads the sequence from the cache: the reader's warning comes again, not only the first time."""
    data = tmp_path / "data"
    shutil.copytree(root / "a", data / "a")
    imu = imu_file(data)
    lines = imu.read_text().splitlines()
    imu.write_text("\n".join([*lines[:10], lines[9], *lines[10:]]) + "\n")  # line 10 written twice
    for _ in range(2):  # built, then from the cache
        with pytest.warns(DataFormatWarning, match=r"data.csv:11: 1 IMU line repeats the line before exactly"):
            load_sequence(data, "a", cache_dir=tmp_path / "cache")
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_sequence(root, "a", cache_dir=tmp_path / "cache")  # a clean file says nothing, from either path
        load_sequence(root, "a", cache_dir=tmp_path / "cache")


def test_a_resumed_run_keeps_the_csv_curves_before_its_interruption(root, tmp_path, capsys):
    """Lightning's CSVLogger deleted the metrics.csv it found: a run resumed in its folder lost its earlier curves."""
    import csv

    handler = signal.getsignal(signal.SIGINT)
    cb = "+callbacks.interrupt._target_=test_damaged_inputs.InterruptAtEpoch"
    settings = ["logger=csv", "trainer.max_epochs=4", "trainer.log_every_n_steps=1"]
    try:
        with pytest.raises(SystemExit):
            train(config(root, tmp_path / "run", cb, *settings))
    finally:
        signal.signal(signal.SIGINT, handler)
    train(config(root, tmp_path / "run", *settings))
    assert "curves before the resume are kept in" in capsys.readouterr().out
    (before,) = (tmp_path / "run" / "csv").glob("metrics_before_resume_*.csv")

    def epochs(path: Path) -> set[int]:
        return {int(r["epoch"]) for r in csv.DictReader(path.open()) if r.get("epoch")}

    assert epochs(before) == {0, 1} and epochs(tmp_path / "run" / "csv" / "metrics.csv") == {2, 3}


def test_a_sweeps_interrupted_job_is_told_to_rerun_alone(monkeypatch):
    """hydra.run.dir does not apply with -m, and the sweep's command would run every job again."""
    from types import SimpleNamespace

    from hydra.types import RunMode
    from omegaconf import OmegaConf

    from gyrodenoise import train as train_module

    job = SimpleNamespace(mode=RunMode.MULTIRUN, overrides=SimpleNamespace(task=["dataset=euroc", "seed=1"]))
    monkeypatch.setattr(train_module.HydraConfig, "initialized", staticmethod(lambda: True))
    monkeypatch.setattr(train_module.HydraConfig, "get", staticmethod(lambda: job))
    cfg = OmegaConf.create({"paths": {"output_dir": "multirun/x/1"}})
    assert train_module._rerun_in_folder(cfg) == (
        "rerun this job of the sweep alone: python -m gyrodenoise.train dataset=euroc seed=1 hydra.run.dir=multirun/x/1"
    )
    job.mode = RunMode.RUN
    assert train_module._rerun_in_folder(cfg) == "rerun the same command with hydra.run.dir=multirun/x/1"
