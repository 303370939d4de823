"""The discrepancy CLI checks each sequence's IMU against its truth, as training does (`data.consistency`)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from gyrodenoise.discrepancy.__main__ import main, rate_problem
from gyrodenoise.discrepancy.compare import load_fit_context


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    """Two 30-s test-world flights (procedural motion, Vicon-like truth) in the ASL layout."""
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    root = tmp_path_factory.mktemp("world")
    for name, seed in (("a", 1), ("b", 2)):
        make_sequence(root, "procedural", None, duration=30.0, seed=seed, name=name, mocap=MOCAP_PRESETS["vicon"])
    return root


def rewrite(src: Path, dst: Path, change) -> None:
    """Copy an ASL csv with its value columns (all but the stamp) passed through `change`."""
    header, *lines = src.read_text().splitlines()
    stamps = [line.split(",", 1)[0] for line in lines]  # as text: int64 ns do not survive a float
    values = change(np.array([[float(v) for v in line.split(",")[1:]] for line in lines]))
    dst.parent.mkdir(parents=True, exist_ok=True)
    body = "\n".join(f"{t}," + ",".join(f"{v:.12g}" for v in row) for t, row in zip(stamps, values, strict=True))
    dst.write_text(header + "\n" + body + "\n")


def damaged_copy(world: Path, root: Path, name: str, imu=None, truth=None) -> None:
    for seq in ("a", "b"):
        for sub in ("imu0", "mocap0", "state_groundtruth_estimate0"):
            src = world / seq / "mav0" / sub / "data.csv"
            if src.is_file():
                change = {"imu0": imu, "mocap0": truth, "state_groundtruth_estimate0": truth}[sub]
                rewrite(src, root / seq / "mav0" / sub / "data.csv", change if seq == name and change else lambda r: r)


def argv(root: Path, out: Path) -> list[str]:
    return ["--root", str(root), "--fit", "a", "--holdout", "b", "--candidates", "scale_factor",
            "--null-draws", "0", "--out", str(out)]  # fmt: skip


def test_a_gyro_in_deg_s_is_refused_in_one_line(world, tmp_path, capsys):
    def deg(r):
        r = r.copy()
        r[:, 0:3] = np.degrees(r[:, 0:3])
        return r

    damaged_copy(world, tmp_path / "data", "a", imu=deg)
    assert main(argv(tmp_path / "data", tmp_path / "out")) == 2
    err = capsys.readouterr().err
    assert "looks like deg/s" in err and "imu0" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "report.md").exists()


def test_a_truth_read_in_the_wrong_quaternion_order_stops_the_workflow(world, tmp_path, capsys):
    """It was flagged in the report, and the workflow went on to name effects from rates compared about the wrong axes
    (a verdict and an error_model.yaml that meant nothing); it stops now, as a training does."""

    def xyzw(r):  # the file holds w, x, y, z after the position; store x, y, z, w instead
        r = r.copy()
        r[:, 3:7] = r[:, [4, 5, 6, 3]]
        return r

    damaged_copy(world, tmp_path / "data", "b", truth=xyzw)
    assert main(argv(tmp_path / "data", tmp_path / "out")) == 2
    err = capsys.readouterr().err
    assert "turns about other axes than the gyro" in err and "quaternion as w, x, y, z" in err
    assert not (tmp_path / "out" / "report.json").exists() and not (tmp_path / "out" / "error_model.yaml").exists()


def test_consistent_sequences_leave_no_data_warning(world, tmp_path, capsys):
    assert main(argv(world, tmp_path / "out")) == 0
    assert "warning:" not in capsys.readouterr().err
    assert json.loads((tmp_path / "out" / "report.json").read_text())["data_warnings"] == []


def test_arguments_that_would_skew_or_be_ignored_are_refused(world, tmp_path, capsys):
    """A sequence given twice counted its evidence twice (delta BIC doubled, standard errors / sqrt 2); a --gt-file for
    a sequence not in the run fell back to the default truth without a word."""
    with pytest.raises(SystemExit):
        main(["--root", str(world), "--fit", "a", "a", "--holdout", "b", "--out", str(tmp_path / "o")])
    assert "--fit names a more than once" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*argv(world, tmp_path / "o"), "--gt-file", "c=mocap0/data.csv"])
    assert "c is not among this run's sequences (a, b)" in capsys.readouterr().err


def test_a_slow_truth_and_a_short_recording_get_one_line_each(world, tmp_path, capsys):
    """A 20 Hz truth (EuRoC's recomputed V1_01) ended in a spline's 'nc > m' traceback; 8 samples in an IndexError."""
    # every tenth truth sample: 10 Hz
    for seq in ("a", "b"):
        for sub in ("imu0", "state_groundtruth_estimate0"):
            src = world / seq / "mav0" / sub / "data.csv"
            header, *lines = src.read_text().splitlines()
            lines = lines[::10] if sub != "imu0" else lines
            (tmp_path / "slow" / seq / "mav0" / sub).mkdir(parents=True)
            (tmp_path / "slow" / seq / "mav0" / sub / "data.csv").write_text("\n".join([header, *lines]) + "\n")
            header, *lines = src.read_text().splitlines()
            (tmp_path / "short" / seq / "mav0" / sub).mkdir(parents=True)
            kept = lines[100:108] if sub == "imu0" else lines  # 8 IMU samples inside the truth's span
            (tmp_path / "short" / seq / "mav0" / sub / "data.csv").write_text("\n".join([header, *kept]) + "\n")
            kept = lines[100:1300] if sub == "imu0" else lines  # 6 s: its 10-s drifts were NaN without a word
            (tmp_path / "6s" / seq / "mav0" / sub).mkdir(parents=True)
            (tmp_path / "6s" / seq / "mav0" / sub / "data.csv").write_text("\n".join([header, *kept]) + "\n")
    assert main(argv(tmp_path / "slow", tmp_path / "o")) == 2
    assert "sampled at 10 Hz, too slow for knots every 0.05 s" in capsys.readouterr().err
    assert main(argv(tmp_path / "short", tmp_path / "o")) == 2
    err = capsys.readouterr().err
    assert "too short" in err and "Traceback" not in err
    assert main(argv(tmp_path / "6s", tmp_path / "o")) == 2
    assert "overlap for 5.0 s (less 0.5 s at each end), shorter than the 10 s" in capsys.readouterr().err


def test_a_rerun_into_the_same_folder_leaves_none_of_the_earlier_files(world, tmp_path, capsys):
    """A rerun kept the earlier run's figures (drift.png of a longer recording) beside the new report."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.json").write_text(json.dumps({"command": "python -m gyrodenoise.discrepancy --earlier"}))
    (out / "drift.png").write_bytes(b"earlier")
    (out / "mine.txt").write_text("the user's")
    assert main(argv(world, out)) == 0
    assert (
        "the outputs of an earlier run in" in (err := capsys.readouterr().err) and "when this run has finished" in err
    )
    assert (out / "mine.txt").read_text() == "the user's"
    assert not (out / "drift.png").is_file() or (out / "drift.png").read_bytes() != b"earlier"
    # report.md links the figures this run drew, and only them (it linked drift.png and gap.png whether drawn or not)
    linked = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", (out / "report.md").read_text())
    drawn = json.loads((out / "report.json").read_text())["plots"]
    assert linked and sorted(linked) == sorted(drawn) and all((out / f).is_file() for f in linked)
    from gyrodenoise.discrepancy.report import markdown

    rep = json.loads((out / "report.json").read_text())  # a run whose recordings held no drift window to draw
    rep["plots"] = [f for f in drawn if f != "drift.png"]
    assert "drift.png" not in markdown(rep) and "(gap.png)" in markdown(rep)


def test_a_failed_rerun_leaves_the_earlier_outputs_as_they_were(world, tmp_path, monkeypatch):
    """The earlier run's outputs were removed when a rerun started, so one that failed (or was stopped) lost them."""
    import gyrodenoise.discrepancy.__main__ as cli

    out = tmp_path / "out"
    out.mkdir()
    earlier = {"report.json": '{"command": "earlier"}', "drift.png": "earlier", "report.md": "earlier"}
    for name, text in earlier.items():
        (out / name).write_text(text)

    def fail(*args, **kwargs):
        raise RuntimeError("stopped while writing")

    monkeypatch.setattr(cli, "write_simulator_model", fail)  # after the report and figures were written
    with pytest.raises(RuntimeError, match="stopped while writing"):
        main(argv(world, out))
    assert {p.name: p.read_text() for p in out.iterdir()} == earlier  # no staging folder left either
    monkeypatch.undo()
    fresh = tmp_path / "fresh" / "out"
    with pytest.raises(RuntimeError):
        monkeypatch.setattr(cli, "write_simulator_model", fail)
        main(argv(world, fresh))
    assert not (tmp_path / "fresh").exists()  # the folders the failed run made are gone


def test_splits_stop_at_a_failed_split(world, tmp_path, capsys):
    """A split that failed was followed by the next one and a summary built from whatever report.json was there."""
    import shutil

    from gyrodenoise.discrepancy.splits import main as splits_main

    shutil.copytree(world, tmp_path / "data")
    shutil.rmtree(tmp_path / "data" / "b" / "mav0" / "state_groundtruth_estimate0")
    with pytest.raises(SystemExit) as e:
        splits_main(["--sequences", "a", "b", "--root", str(tmp_path / "data"), "--out", str(tmp_path / "s")])
    assert e.value.code == 2
    assert "the split with a held out failed (above): the splits stop here" in capsys.readouterr().err
    assert not (tmp_path / "s" / "summary.json").exists()


def test_recordings_of_other_rates_and_a_network_of_another_rate_are_refused_in_one_line(
    world, tmp_path, capsys, monkeypatch
):
    """A 100 Hz recording beside 200 Hz ones went through the run read at the first fit sequence's rate (its spectra,
    Allan deviations and noise floor, and the simulator model's rate_hz), and a --network model trained at 200 Hz was
    regressed on 100 Hz recordings, where its convolutions see twice the time: both without a word. The model is read
    once (the option check, the rate check and the regression each read the file)."""
    import gyrodenoise.pretrained as pretrained
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    loads, load = [], pretrained.load_model
    monkeypatch.setattr(pretrained, "load_model", lambda model, *a, **kw: loads.append(model) or load(model, *a, **kw))

    for name, seed in (("c", 3), ("d", 4)):
        make_sequence(world.parent / "slow_world", "procedural", None, duration=15.0, seed=seed, name=name,
                      imu_rate_hz=100.0, mocap=MOCAP_PRESETS["vicon"], overwrite=True)  # fmt: skip
        (tmp_path / "data").mkdir(exist_ok=True)
        (tmp_path / "data" / name).symlink_to(world.parent / "slow_world" / name)
    (tmp_path / "data" / "a").symlink_to(world / "a")
    out = tmp_path / "out"
    assert main(["--root", str(tmp_path / "data"), "--fit", "a", "--holdout", "c", "--null-draws", "0",
                 "--out", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "sampled at different rates (a 200 Hz, c 100 Hz)" in err and "Traceback" not in err
    assert main(["--root", str(tmp_path / "data"), "--fit", "c", "--holdout", "d", "--null-draws", "0",
                 "--network", "euroc", "--out", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert err.startswith("error: --network euroc: model euroc was trained at 200 Hz but c 100 Hz, d 100 Hz") and (
        "or leave out --network" in err
    )
    assert not out.exists() and loads == ["euroc"]
    # called without the loaded model (a script's own check), the model is loaded, not the check skipped
    slow = [load_fit_context(tmp_path / "data", n) for n in ("c", "d")]
    assert "trained at 200 Hz but c 100 Hz" in rate_problem(slow[:1], slow[1:], "euroc")


@pytest.mark.parametrize(
    ("flag", "said"),
    [
        (["--seed", "-1"], "--seed -1: a non-negative integer"),  # numpy's ValueError traceback after the selection
        (["--bic-threshold", "nan"], "--bic-threshold nan: a finite BIC decrease"),  # named nothing, without a word
    ],
)
def test_a_seed_or_threshold_the_run_cannot_use_is_refused_in_one_line(flag, said, world, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main([*argv(world, tmp_path / "out"), *flag])
    assert said in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_knot_spacing_that_leaves_no_band_to_compare_is_one_line(world, tmp_path, capsys):
    """A slow truth spline (--knot-spacing 0.5: a corner near 1 Hz) pins the trusted band at 1 Hz, where the spectral
    rows start: the fit had no rows and ended in numpy's LinAlgError ('Eigenvalues did not converge')."""
    assert main([*argv(world, tmp_path / "out"), "--knot-spacing", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "--knot-spacing 0.5" in err and "Traceback" not in err, err
    assert not (tmp_path / "out" / "report.md").exists()
