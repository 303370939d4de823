"""The command line a run records: as the user typed it, with portable paths."""

from pathlib import Path

from gyrodenoise.paths import invoked_command, portable_path


def test_module_run_is_recorded_as_python_dash_m():
    argv = [str(Path("/somewhere/site-packages/gyrodenoise/train.py")), "experiment=sim_quick", "seed=1"]
    assert invoked_command("train", argv) == "python -m gyrodenoise.train experiment=sim_quick seed=1"


def test_console_script_keeps_its_name_and_paths_become_portable():
    home_file = Path.home() / "data" / "euroc"
    cmd = invoked_command("train", ["/usr/bin/gyrodenoise-train", f"dataset.root={home_file}"])
    assert cmd == f"gyrodenoise-train dataset.root={portable_path(home_file)}" and str(home_file) not in cmd
    assert invoked_command("train", ["/x/train.py"]) == "python -m gyrodenoise.train"


def test_recorded_command_is_quoted_where_a_shell_needs_it():
    import shlex

    argv = ["/x/train.py", "dataset.train_seqs=[a,b]", "dataset.root=my data", "seed=1", "-o", "out/dir"]
    cmd = invoked_command("train", argv)
    assert cmd == "python -m gyrodenoise.train 'dataset.train_seqs=[a,b]' 'dataset.root=my data' seed=1 -o out/dir"
    assert shlex.split(cmd)[3:] == argv[1:]  # a shell gives the program the same arguments back


def test_json_outputs_are_strict_json(tmp_path):
    """NaN and inf (a Spearman of constant data, a ratio over zero) are written as null: JSON has no NaN token,
    and jq or a browser refuse a file with one."""
    import json

    import numpy as np
    import pytest
    import torch

    from gyrodenoise.atomic import write_json

    path = write_json(
        tmp_path / "r.json",
        {"a": float("nan"), "b": np.float32(np.inf), "c": np.arange(2), "d": torch.tensor(1.5), "e": (1, "x")},
    )
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {
        "a": None, "b": None, "c": [0, 1], "d": 1.5, "e": [1, "x"],
    }  # fmt: skip
