"""The discrepancy workflow over leave-one-out splits (gyrodenoise.discrepancy.splits)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from gyrodenoise.discrepancy.splits import agreement, main


def test_agreement_keeps_what_every_split_names():
    rows = [
        {"held_out": "a", "named": ["quantization", "time_offset"], "decided": True},
        {"held_out": "b", "named": ["quantization"], "decided": False},
    ]
    assert agreement(rows) == {
        "named_in_every_split": ["quantization"],
        "named_in_some_splits": ["time_offset"],
        "undecided_splits": ["b"],
    }


def test_splits_run_each_sequence_held_out_once(tmp_path):
    """End to end on two test-world flights (null sensor, Vicon-like truth): one report per split and a summary."""
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    for name, seed in (("a", 1), ("b", 2)):
        make_sequence(tmp_path / "data", "procedural", None, duration=30.0, seed=seed, name=name,
                      mocap=MOCAP_PRESETS["vicon"])  # fmt: skip
    out = tmp_path / "out"
    argv = ["--sequences", "a", "b", "--out", str(out), "--root", str(tmp_path / "data"), "--null-draws", "0"]
    assert main([*argv, "--candidates", "scale_factor,quantization"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [(r["held_out"], r["fit"]) for r in summary["splits"]] == [("a", ["b"]), ("b", ["a"])]
    assert (out / "a" / "report.md").is_file() and (out / "b" / "report.md").is_file()
    assert "scale_factor" not in summary["named_in_every_split"]  # a null sensor has no scale factor
    assert "Named in every split" in (out / "summary.md").read_text()
    code = summary["splits"][0]["code"]  # the code that ran, in the summary's first line as in each report
    assert code.startswith("gyrodenoise ") and f"{code}; per split's wall time" in (out / "summary.md").read_text()


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["--sequences", "a"], "at least 2 different sequences"),
        (["--sequences", "a", "b", "--fit", "a"], "give --sequences only"),
        # ran the split with a held out twice, then failed on the third (--fit a a) after the minutes of two runs
        (["--sequences", "a", "a", "b"], "--sequences names a more than once: give each sequence once"),
    ],
)
def test_splits_refuse_what_they_cannot_split(argv, said, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main([*argv, "--out", str(tmp_path)])
    assert said in capsys.readouterr().err


def fake_split(out: Path, failing: str | None = None, models: list | None = None) -> Callable[..., int]:
    """A stand-in for one split's run (`splits.discrepancy_main`): writes a report.json into OUT/<held out>, or returns
    2 where the sequence held out is `failing`; the `--network` model each run was given goes into `models`."""
    from gyrodenoise.discrepancy.splits import GAPS

    gap = dict.fromkeys(GAPS, 1.0)
    report = {"named_effects": [], "verdict": "v", "gap_before": gap, "gap_after": gap, "wall_time_s": 1.0,
              "machine": "m"}  # fmt: skip

    def one_split(argv: list[str], network_model=None) -> int:
        if models is not None:
            models.append(network_model)
        held = argv[argv.index("--holdout") + 1]
        if held == failing:
            return 2
        (out / held).mkdir(parents=True, exist_ok=True)
        (out / held / "report.json").write_text(json.dumps(report))
        return 0

    return one_split


def test_a_rerun_that_stops_leaves_no_earlier_summary_beside_its_own_reports(tmp_path, monkeypatch, capsys):
    """A rerun whose second split failed (or was stopped) left the earlier run's summary.md and summary.json beside
    the first split's new report: a summary that looked whole, of another run, linking to a report it did not hold."""
    import gyrodenoise.discrepancy.splits as splits

    out = tmp_path / "out"
    out.mkdir()
    for name in ("summary.json", "summary.md"):
        (out / name).write_text("the earlier run's")
    monkeypatch.setattr(splits, "discrepancy_main", fake_split(out, failing="b"))
    with pytest.raises(SystemExit):
        main(["--sequences", "a", "b", "--root", str(tmp_path), "--out", str(out)])
    assert "the split with b held out failed" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["a"]
    first = tmp_path / "first"  # a split that fails first leaves an earlier run's outputs as they were
    first.mkdir()
    (first / "summary.md").write_text("the earlier run's")
    monkeypatch.setattr(splits, "discrepancy_main", lambda argv, network_model=None: 2)
    with pytest.raises(SystemExit):
        main(["--sequences", "a", "b", "--root", str(tmp_path), "--out", str(first)])
    assert (first / "summary.md").read_text() == "the earlier run's"


@pytest.mark.parametrize(
    ("passed_on", "said"),
    [(["--min-gain", "5"], "--min-gain 5: a share between 0 and 1"), (["--no-such-option"], "unrecognized arguments")],
)
def test_an_option_passed_on_is_refused_under_the_splits_name(passed_on, said, tmp_path, capsys):
    """A wrong option for the splits' runs was refused by the first split's parser: `python -m gyrodenoise.discrepancy:
    error: ...` under its usage, which asks for --fit and --holdout (options the splits refuse)."""
    with pytest.raises(SystemExit) as e:
        main(["--sequences", "a", "b", "--root", str(tmp_path), "--out", str(tmp_path / "out"), *passed_on])
    err = capsys.readouterr().err
    assert e.value.code == 2 and f"python -m gyrodenoise.discrepancy.splits: error: {said}" in err, err
    assert err.startswith("usage: python -m gyrodenoise.discrepancy.splits ") and "--fit" not in err, err
    assert not (tmp_path / "out").exists()


def test_ctrl_c_is_one_line_and_status_130(tmp_path, monkeypatch, capsys):
    """Ctrl-C in a split's run was said by the run and followed by 'error: the split with a held out failed'; between
    the runs (writing the summary) it ended in KeyboardInterrupt's traceback. Now one line and 130, as the others."""
    import gyrodenoise.discrepancy.splits as splits
    from gyrodenoise.notices import INTERRUPTED, interrupt_in_one_line

    def interrupted(argv: list[str], network_model=None) -> int:
        raise KeyboardInterrupt

    argv = ["--sequences", "a", "b", "--root", str(tmp_path), "--out", str(tmp_path / "out")]
    monkeypatch.setattr(splits, "discrepancy_main", interrupt_in_one_line(interrupted))
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 130 and capsys.readouterr().err == f"{INTERRUPTED}\n"
    monkeypatch.setattr(splits, "discrepancy_main", fake_split(tmp_path / "out"))
    monkeypatch.setattr(splits, "agreement", lambda rows: interrupted([]))
    assert main(argv) == 130 and capsys.readouterr().err == f"{INTERRUPTED}\n"
    assert not (tmp_path / "out" / "summary.json").exists()


def test_the_network_is_loaded_once_for_all_the_splits(tmp_path, monkeypatch):
    """Each split's run loaded --network again (and said its warnings again): N + 1 loads for N splits."""
    import gyrodenoise.discrepancy.splits as splits
    import gyrodenoise.pretrained as pretrained

    loads, load = [], pretrained.load_model
    monkeypatch.setattr(pretrained, "load_model", lambda model, *a, **kw: loads.append(model) or load(model, *a, **kw))
    models: list = []
    monkeypatch.setattr(splits, "discrepancy_main", fake_split(tmp_path / "out", models=models))
    argv = ["--sequences", "a", "b", "c", "--network", "euroc", "--root", str(tmp_path), "--out", str(tmp_path / "out")]
    assert main(argv) == 0
    assert loads == ["euroc"] and len(models) == 3 and all(m is models[0] and m is not None for m in models)
