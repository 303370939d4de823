"""Bad output paths and option values of the command-line tools (found by a bad-input audit): each is refused in one
line naming the option and what to do, before the work, and nothing is written."""

from __future__ import annotations

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
        with pytest.raises(SystemExit) as e:
            main([str(model_file), flag, str(a_file / "out")])
        assert e.value.code == 2
        assert f"{flag} {a_file / 'out'}: {a_file} is a file, not a folder" in capsys.readouterr().err


def test_export_refuses_an_opset_it_cannot_write(model_file, tmp_path, capsys):
    pytest.importorskip("onnxscript", reason="pip install 'gyrodenoise[export]'")
    from gyrodenoise.export import main

    out = tmp_path / "m.onnx"
    assert main([str(model_file), "--onnx", str(out), "--opset", "3", "--no-check"]) == 2
    err = capsys.readouterr().err
    assert "--opset 3: the exporter could not convert the graph to ONNX opset 3" in err
    assert "nothing was written; give --opset 18 or higher" in err
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
