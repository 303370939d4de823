"""Bad output paths and option values of the command-line tools (found by a bad-input audit): each is refused in one
line naming the option and what to do, before the work, and nothing is written."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from _models import random_model

from gyrodenoise.atomic import output_path_problem, write_text
from gyrodenoise.pretrained import save_model

TINY = {"name": "denoiser", "channels": (4, 8), "kernel_size": 5, "dilations": (1, 2)}


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    m = random_model(seed=1, **{k: v for k, v in TINY.items() if k != "name"})
    return save_model(m, TINY, tmp_path_factory.mktemp("model") / "tiny.pt", meta={"rate_hz": 200.0})


@pytest.fixture
def a_file(tmp_path) -> Path:
    f = tmp_path / "afile"
    f.write_text("not a folder\n")
    return f


def test_an_output_path_under_a_file_is_named(a_file):
    assert output_path_problem(a_file.parent / "new" / "x.csv") is None
    assert (
        output_path_problem(a_file / "x.csv")
        == f"{a_file} is a file, not a folder: {a_file / 'x.csv'} cannot be written under it"
    )
    assert output_path_problem(a_file, folder=True) == f"{a_file} is a file: give a folder"
    assert output_path_problem(a_file.parent) == f"{a_file.parent} is a folder: give a file path"
    with pytest.raises(NotADirectoryError, match=f"{a_file} is a file, not a folder"):  # not mkdir's bare errno
        write_text(a_file / "sub" / "x.txt", "x")


def test_correct_refuses_an_output_folder_that_is_a_file_before_the_work(tiny_asl_root, a_file, model_file, capsys):
    from gyrodenoise.correct import main

    imu = tiny_asl_root / "a" / "mav0" / "imu0" / "data.csv"
    assert main([str(imu), "-m", str(model_file), "-o", str(a_file)]) == 2
    assert f"-o {a_file}: {a_file} is a file: give a folder" in capsys.readouterr().err
    assert (
        main([str(imu), "-m", str(model_file), "--out-csv", str(a_file / "x.csv"), "-o", str(a_file.parent / "o")]) == 2
    )
    assert f"{a_file} is a file, not a folder" in capsys.readouterr().err
    assert not (a_file.parent / "o").exists()


def test_export_refuses_an_output_under_a_file(model_file, a_file, capsys):
    from gyrodenoise.export import main

    for flag in ("--onnx", "--pt2", "--c"):
        assert main([str(model_file), flag, str(a_file / "out")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: {flag} {a_file / 'out'}: cannot write: {a_file} is a file, not a folder")
        assert err.count("\n") == 1
    assert main([str(model_file), "--c", str(a_file)]) == 2  # a folder of C files asked, a file given
    assert capsys.readouterr().err == f"error: --c {a_file}: cannot write: {a_file} is a file: give a folder\n"


def test_export_refuses_an_opset_it_cannot_write(model_file, tmp_path, capsys):
    pytest.importorskip("onnxscript", reason="pip install 'gyrodenoise[export]'")
    from gyrodenoise.export import main

    out = tmp_path / "m.onnx"
    # onnxscript logged its failed conversion with the ONNX C API's traceback before this line said it: dropped
    import logging

    seen: list[logging.LogRecord] = []
    listener = logging.Handler(logging.WARNING)
    listener.emit = seen.append
    converter_log = logging.getLogger("onnxscript.version_converter")
    converter_log.addHandler(listener)
    try:
        assert main([str(model_file), "--onnx", str(out), "--opset", "3", "--no-check"]) == 2
    finally:
        converter_log.removeHandler(listener)
    assert not [r.getMessage() for r in seen if r.exc_info], [r.getMessage() for r in seen]
    err = capsys.readouterr().err
    assert "--opset 3: the exporter could not convert the graph to ONNX opset 3" in err
    newest = __import__("onnx").defs.onnx_opset_version()
    assert f"nothing was written; give --opset from 18 to {newest}, the installed onnx's newest" in err
    assert not out.exists()
    # one above the newest the installed onnx knows was told 'give --opset 18 or higher' too: 99 is higher
    import onnx

    newest = onnx.defs.onnx_opset_version()
    assert main([str(model_file), "--onnx", str(out), "--opset", str(newest + 1), "--no-check"]) == 2
    err = capsys.readouterr().err
    assert f"give --opset from 18 to {newest}, the installed onnx's newest" in err and "or higher" not in err
    assert not out.exists()


def test_cross_validation_refuses_an_output_prefix_under_a_file(a_file, capsys):
    from gyrodenoise.cross_validation import main

    with pytest.raises(SystemExit):
        main([str(a_file.parent), "--out", str(a_file / "cv")])
    assert f"--out {a_file / 'cv'}: {a_file} is a file, not a folder" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, said",
    [
        (["--out", "{file}"], "--out {file}: {file} is a file: give a folder"),
        (["--min-gain", "5"], "--min-gain 5: a share between 0 and 1"),
        (["--null-draws", "-1"], "--null-draws -1: 0 (the fixed --bic-threshold alone) or more"),
        (["--network", "{file}"], "--network: {file}: not a model file"),
        (["--network", "nosuchmodel"], "--network: model 'nosuchmodel': neither a file nor a shipped model"),
    ],
)
def test_discrepancy_refuses_bad_options_before_the_work(tmp_path, a_file, capsys, extra, said):
    from gyrodenoise.discrepancy.__main__ import parse_args

    argv = ["--root", str(tmp_path), "--fit", "a", "--holdout", "b", "--out", str(tmp_path / "out")]
    with pytest.raises(SystemExit) as e:
        parse_args(argv + [x.format(file=a_file) for x in extra])
    assert e.value.code == 2
    assert said.format(file=a_file) in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "override, said",
    [
        ("dataset.train_seqs=a", r"dataset.train_seqs='a' is one name, not a list: give 'dataset.train_seqs=\[a\]'"),
        ("dataset.test_seqs=c", r"dataset.test_seqs='c' is one name, not a list"),
        ("dataset.sensor.rate_hz=abc", r"dataset.sensor.rate_hz='abc': a number >= 0 in SI units"),
        ("dataset.sensor.gyro_noise_density=-1", r"dataset.sensor.gyro_noise_density=-1: a number >= 0"),
    ],
)
def test_a_dataset_setting_of_the_wrong_kind_is_named(tiny_asl_root, override, said):
    """A sequence name without brackets was read letter by letter ('sequence folder(s) not found: a'); a rate that is
    no number stopped in the noise formula with a TypeError naming only 'dataset'."""
    import hydra
    from test_train import tiny_dataset

    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.config import compose_config

    cfg = compose_config("train", [*tiny_dataset(tiny_asl_root), "dataset=asl_folder", override])
    with pytest.raises(Exception) as e:
        hydra.utils.instantiate(cfg.dataset)
    error = e.value.__cause__ if isinstance(e.value.__cause__, ConfigError) else e.value  # Hydra wraps it
    assert isinstance(error, ConfigError)
    assert re.search(said, str(error))


@pytest.mark.parametrize("window", ["-32", "0", "null_not"])
def test_a_crop_window_that_is_not_a_positive_number_of_samples_is_named(tiny_asl_root, window):
    from test_train import tiny_dataset

    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.config import compose_config
    from gyrodenoise.train import check_choices

    cfg = compose_config("train", [*tiny_dataset(tiny_asl_root), f"dataset.window={window}"])
    with pytest.raises(
        ConfigError, match=r"dataset.window=.*: the samples per training crop, a whole multiple of the "
    ):
        check_choices(cfg)


@pytest.mark.parametrize("value", [[7, "x"], 7, [0], [float("nan")]])
def test_roe_distances_that_are_not_distances_are_named(value):
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.evaluate import roe_distances

    with pytest.raises(ConfigError, match=r"roe_distances=.*: a list of travelled distances in metres, each > 0"):
        roe_distances(value)
    assert roe_distances([7, 21.5]) == [7.0, 21.5]


@pytest.mark.parametrize("override", ["figures=fals", "trajectories=0"])
def test_an_evaluate_switch_that_is_not_true_or_false_is_named(tmp_path, override):
    """'figures=fals' was a non-empty string, so the figures were drawn."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.config import compose_config
    from gyrodenoise.evaluate import evaluate

    key = override.split("=")[0]
    with pytest.raises(ConfigError, match=rf"{key}=.*: give {key}=true or {key}=false"):
        evaluate(compose_config("evaluate", [override, f"out_dir={tmp_path}"]))


@pytest.mark.parametrize(
    ("override", "said"),
    [
        ("optim.lr=abc", "optim.lr='abc': give a number, e.g. optim.lr=0.01"),
        ("seed=abc", "seed='abc': give a whole number"),
        ("trainer.max_epochs=2.5", "trainer.max_epochs=2.5: give a whole number"),
    ],
)
def test_a_setting_that_is_not_a_number_ends_in_one_line(override, said):
    """'optim.lr=abc' ended in a TypeError from a comparison deep in the optimiser, 'seed=abc' in a ValueError."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.config import compose_config
    from gyrodenoise.train import check_choices

    with pytest.raises(ConfigError, match=re.escape(said)):
        check_choices(compose_config("train", [override, "paths.output_dir=unused"]))


def test_discrepancy_root_defaults_to_the_data_folder_like_the_other_tools(tmp_path, monkeypatch, capsys):
    """--root was required where the other tools read $GYRODENOISE_DATA (a fresh-user audit)."""
    from gyrodenoise.discrepancy.__main__ import parse_args

    argv = ["--fit", "a", "--holdout", "b", "--out", str(tmp_path / "out")]
    monkeypatch.setenv("GYRODENOISE_DATA", str(tmp_path))
    assert parse_args(argv).root == tmp_path / "euroc"
    monkeypatch.delenv("GYRODENOISE_DATA")
    with pytest.raises(SystemExit):
        parse_args(argv)
    assert "--root DIR: the folder of ASL sequences (or set GYRODENOISE_DATA" in capsys.readouterr().err


@pytest.fixture
def unwritable(tmp_path) -> Path:
    """A folder no file can be made in: a read-only one, or (as root, whom permissions do not stop) /proc."""
    import os
    import tempfile

    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    for candidate in (folder, Path("/proc")):
        try:
            os.remove(tempfile.mkstemp(dir=candidate)[1])
        except OSError:
            yield candidate
            break
    else:
        pytest.skip("no folder here refuses a new file")
    folder.chmod(0o755)


def test_an_output_in_a_folder_that_cannot_be_written_is_one_line_before_the_work(
    unwritable, tiny_asl_root, model_file, tmp_path, capsys
):
    """An output in a read-only or forbidden folder passed the checks and ended correct, export and ensemble with
    PermissionError's traceback when the results were written (export after its ~20 s of export, ensemble reference
    after reading the training data). Refused first, naming the option."""
    from gyrodenoise import correct, ensemble, export

    assert output_path_problem(unwritable / "x.csv").startswith(f"{unwritable} cannot be written (")
    assert output_path_problem(unwritable, folder=True).startswith(f"{unwritable} cannot be written (")
    assert output_path_problem(unwritable / "new" / "x.csv").startswith(f"{unwritable} cannot be written (")
    imu = tiny_asl_root / "a" / "mav0" / "imu0" / "data.csv"
    runs = [
        (correct.main, [str(imu), "-m", str(model_file), "--out-csv", str(unwritable / "x.csv"), "-o", str(tmp_path)],
         "--out-csv"),
        (correct.main, [str(imu), "-m", str(model_file), "-o", str(unwritable / "out")], "-o"),
        (export.main, [str(model_file), "--pt2", str(unwritable / "m.pt2")], "--pt2"),
        (export.main, [str(model_file), "--onnx", str(unwritable / "m.onnx")], "--onnx"),
        (export.main, [str(model_file), "--c", str(unwritable / "c")], "--c"),
        (ensemble.main, ["build", str(model_file), "--out", str(unwritable / "e.pt")], "--out"),
    ]  # fmt: skip
    for main, args, flag in runs:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert err.startswith("error: ") and f"{flag} {unwritable}" in err and "cannot be written" in err, err
        assert err.count("\n") == 1 and "Traceback" not in err, err
