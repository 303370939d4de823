"""A bad data folder or model path ends the Hydra commands with one clear line and status 2, not a trace."""

import os
import subprocess
import sys

import pytest

from gyrodenoise.cli_errors import user_errors
from gyrodenoise.data.readers import DataFormatError


def test_train_with_missing_data_folder_prints_one_line(tmp_path):
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    proc = subprocess.run(
        [sys.executable, "-m", "gyrodenoise.train", "dataset=euroc", f"dataset.root={tmp_path / 'nowhere'}",
         "logger=none", f"hydra.run.dir={tmp_path / 'run'}"],
        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=180,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "MH_01_easy" in proc.stderr and "not found" in proc.stderr and "Set dataset.root" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert "error: " in (tmp_path / "run" / "train.log").read_text()  # the run folder says why it is empty


@pytest.mark.parametrize("error", [DataFormatError("imu.csv, line 3: 4 fields"), FileNotFoundError("x.pt: no file")])
def test_user_errors_exit_2_with_the_message(error, monkeypatch, capsys):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as exit_info, user_errors():
        raise error
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.startswith(f"error: {error}\n")


def test_a_full_disk_is_one_line_naming_the_file_and_other_os_errors_keep_the_trace(monkeypatch, capsys):
    import errno

    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as exit_info, user_errors():
        raise OSError(errno.ENOSPC, "No space left on device", "/run/checkpoints/last.ckpt")
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: /run/checkpoints/last.ckpt: No space left on device. Free space")
    assert "hydra.run.dir" in err
    with pytest.raises(OSError), user_errors():
        raise OSError(errno.EIO, "I/O error")


def test_full_error_switch_and_other_errors_keep_the_trace(monkeypatch):
    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    with pytest.raises(FileNotFoundError), user_errors():
        raise FileNotFoundError("x")
    monkeypatch.delenv("HYDRA_FULL_ERROR")
    with pytest.raises(RuntimeError), user_errors():  # a bug is not a user error: its trace stays
        raise RuntimeError("bug")


def test_missing_value_gpu_on_a_cpu_machine_and_a_misspelt_sequence_say_what_to_do(tmp_path, monkeypatch, capsys):
    from hydra.errors import InstantiationException
    from omegaconf import OmegaConf

    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit), user_errors():
        OmegaConf.create({"dataset": {"root": "???"}}).dataset.root  # noqa: B018
    assert "dataset.root has no value" in capsys.readouterr().err
    with pytest.raises(SystemExit), user_errors():
        raise InstantiationException(
            "Error in call to target Trainer: MisconfigurationException('No supported gpu backend found!')"
        )
    assert "leave out trainer=gpu" in capsys.readouterr().err
    with pytest.raises(InstantiationException), user_errors():  # another instantiation error is not ours to word
        raise InstantiationException("Error in call to target X: TypeError('bad')")

    import hydra

    from gyrodenoise.config import compose_config

    (tmp_path / "MH_01_easy" / "mav0").mkdir(parents=True)
    cfg = compose_config("train", ["dataset=euroc", f"dataset.root={tmp_path}", "dataset.train_seqs=[MH_01_easyy]"])
    with pytest.raises(FileNotFoundError, match="MH_01_easyy: did you mean MH_01_easy\\? The folder holds MH_01_easy"):
        hydra.utils.instantiate(cfg.dataset).check_sequences()


def test_discrepancy_cli_names_a_wrong_sequence_in_one_line(tmp_path, capsys):
    from gyrodenoise.discrepancy.__main__ import main

    (tmp_path / "V1_02_medium" / "mav0").mkdir(parents=True)
    code = main(["--root", str(tmp_path), "--fit", "V1_02_mediun", "--holdout", "x", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "Did you mean V1_02_medium?" in err and "Traceback" not in err
    with pytest.raises(SystemExit):
        main(["--root", str(tmp_path), "--fit", "a", "--holdout", "b", "--knot-spacing", "0", "--out", "o"])
    assert "--knot-spacing 0.0: must be positive" in capsys.readouterr().err


def test_a_misspelt_config_key_is_named_with_the_key_it_was_meant_to_be(tmp_path):
    from gyrodenoise.cli_errors import misspelt_key_message

    def said(*overrides: str, config: str = "train") -> str | None:
        return misspelt_key_message(config, list(overrides))

    assert said("dataset=euroc", "trainer.max_epoch=3").endswith("did you mean trainer.max_epochs?")
    assert said("max_epochs=3").endswith("did you mean trainer.max_epochs?")  # the group left out
    assert said("sed=3").endswith("did you mean seed?")
    assert said("dataset=tumvi", "dataset.train_seq=[a]").endswith("did you mean dataset.train_seqs?")
    far = said("dataset.sequnces=[a]")
    assert "dataset has name, root, train_seqs" in far and "+key=value" in far
    # a sweep's keys too, by their first value (Hydra's own message advised '+model.dropot', which trains and
    # ignores the key)
    assert said("-m", "model.dropot=0.1,0.2").endswith("did you mean model.dropout?")
    assert said("--multirun", "optim.lrr=range(1,3)", "seed=0,1").endswith("did you mean optim.lr?")
    # right keys, '+' additions, good sweeps and Hydra's own options are not ours to judge
    for fine in [("trainer.max_epochs=3",), ("+trainer.foo=1",), ("-m", "seed=1,2"), ("hydra.run.dir=x",)]:
        assert said(*fine) is None, fine
    assert said("-m", "model=denoiser,calibrated", "loss.increments=[8,16],[16,32]") is None
    assert said("weights=x", config="evaluate") is None
    # a list of a group's options: Hydra names only the option it could not load; the options are listed here
    listed = said("logger=[tensorboard,mlflw]")
    assert listed.startswith("logger=[tensorboard,mlflw]: 'logger' has no option mlflw: did you mean mlflow?")
    assert "csv, mlflow, none, tensorboard" in listed and said("logger=[tensorboard,csv]") is None

    # end to end: one line and status 2, before Hydra's advice to add the key with '+'
    proc = subprocess.run(
        [sys.executable, "-m", "gyrodenoise.train", "trainer.max_epoch=3", f"hydra.run.dir={tmp_path / 'run'}"],
        capture_output=True, text=True, cwd=tmp_path, env={**os.environ, "HYDRA_FULL_ERROR": "0"}, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert (
        proc.stderr.strip()
        == "error: trainer.max_epoch is not a key of the 'train' config: did you mean trainer.max_epochs?"
    )


@pytest.mark.parametrize("threads", ["one", 0, -2, 2.5, True])
def test_a_thread_count_that_is_not_a_whole_number_ends_in_one_line(threads, monkeypatch, capsys):
    import torch

    from gyrodenoise.cli_errors import set_torch_threads

    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    before = torch.get_num_threads()
    with pytest.raises(SystemExit), user_errors():
        set_torch_threads(threads)
    assert f"threads={threads!r}: a whole number >= 1" in capsys.readouterr().err
    assert torch.get_num_threads() == before
    set_torch_threads(None)  # null: torch's default, untouched
    assert torch.get_num_threads() == before


def test_a_root_one_level_off_is_named_with_the_root_to_give(tiny_asl_root, tmp_path):
    import hydra

    from gyrodenoise.config import compose_config
    from gyrodenoise.data.sequence import sequence_folder

    with pytest.raises(FileNotFoundError, match=f"give its parent, {tiny_asl_root}, as the root"):
        sequence_folder(tiny_asl_root / "a", "a")  # the sequence folder itself
    (tmp_path / "mine").symlink_to(tiny_asl_root)
    with pytest.raises(FileNotFoundError, match=f"one level further down: give {tmp_path / 'mine'} as the root"):
        sequence_folder(tmp_path, "a")
    seqs = "dataset.train_seqs=[a] dataset.val_seqs=[a] dataset.test_seqs=[b]".split()
    cfg = compose_config("train", ["dataset=euroc", f"dataset.root={tiny_asl_root / 'a'}", *seqs])
    with pytest.raises(FileNotFoundError, match=f"give its parent, {tiny_asl_root}, as dataset.root"):
        hydra.utils.instantiate(cfg.dataset).check_sequences()


def test_the_projects_warnings_print_as_one_line_inside_a_command():
    """A data warning read like a crash: Python's '<site-packages path>:<line>: DataFormatWarning:' and the source
    line of the warnings.warn call (first-hour audit). Other packages' warnings keep Python's format. (Python's
    showwarning prints what formatwarning returns; pytest records warnings instead of printing them.)"""
    import warnings

    from gyrodenoise.data.readers import DataFormatWarning

    msg = "x.csv:3: the file does not end with a line break"
    with user_errors():
        assert warnings.formatwarning(msg, DataFormatWarning, "/site/readers.py", 84) == f"warning: {msg}\n"
        assert "DeprecationWarning: old" in warnings.formatwarning("old", DeprecationWarning, "/site/lib.py", 1)
    assert "DataFormatWarning: " + msg in warnings.formatwarning(msg, DataFormatWarning, "/site/readers.py", 84)


def test_a_refused_rerun_leaves_the_folders_hydra_record_as_it_was(tmp_path):
    run = tmp_path / "run"
    record = run / ".hydra"
    record.mkdir(parents=True)
    before = {"config.yaml": "seed: 1\n", "overrides.yaml": "- seed=1\n"}  # an older Hydra wrote no hydra.yaml
    for name, text in before.items():
        (record / name).write_text(text)
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    proc = subprocess.run(
        [sys.executable, "-m", "gyrodenoise.train", "select=best", "logger=none", f"hydra.run.dir={run}"],
        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=180,
    )  # fmt: skip
    assert proc.returncode == 2 and "select='best'" in proc.stderr, proc.stderr
    assert {p.name: p.read_text() for p in record.iterdir()} == before
    # a fresh folder holds no other run: the refused command's record stays, as Hydra wrote it
    proc = subprocess.run(
        [sys.executable, "-m", "gyrodenoise.train", "select=best", "logger=none", f"hydra.run.dir={tmp_path / 'new'}"],
        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=180,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "select=best" in (tmp_path / "new" / ".hydra" / "overrides.yaml").read_text()


@pytest.mark.parametrize(("module", "work"), [("evaluate", "evaluate"), ("fit_calibrated", "fit")])
def test_ctrl_c_in_a_hydra_command_is_one_line_and_status_130(module, work, tmp_path, monkeypatch, capsys):
    import importlib

    command = importlib.import_module(f"gyrodenoise.{module}")

    def interrupted(cfg):
        raise KeyboardInterrupt

    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.setattr(command, work, interrupted)
    monkeypatch.setattr(sys, "argv", [module, f"hydra.run.dir={tmp_path}"])
    with pytest.raises(SystemExit) as exit_info:
        command.main()
    assert exit_info.value.code == 130
    assert capsys.readouterr().err.strip().endswith("interrupted: no output of this run was left half-written")


def test_evaluate_keeps_its_console_log_with_its_outputs(tmp_path, monkeypatch):
    from gyrodenoise import evaluate

    monkeypatch.setattr(evaluate, "evaluate", lambda cfg: print("the table"))
    out = tmp_path / "out"
    monkeypatch.setattr(sys, "argv", ["evaluate", f"out_dir={out}", f"hydra.run.dir={tmp_path / 'hydra'}"])
    evaluate.main()
    assert "the table" in (out / "evaluate.log").read_text()


def test_a_sweep_asked_for_its_config_says_how_to_see_one_jobs():
    from gyrodenoise.cli_errors import flag_conflict_message

    assert flag_conflict_message(["-m", "seed=0,1", "--cfg", "hydra"]).startswith("-m and --cfg cannot be combined")
    assert (
        flag_conflict_message(["seed=0", "--cfg", "job"]) is None and flag_conflict_message(["-m", "seed=0,1"]) is None
    )
