"""The discrepancy CLI checks each sequence's IMU against its truth, as training does (`data.consistency`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gyrodenoise.discrepancy.__main__ import main


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


def test_a_truth_read_in_the_wrong_quaternion_order_is_flagged_in_the_report(world, tmp_path, capsys):
    def xyzw(r):  # the file holds w, x, y, z after the position; store x, y, z, w instead
        r = r.copy()
        r[:, 3:7] = r[:, [4, 5, 6, 3]]
        return r

    damaged_copy(world, tmp_path / "data", "b", truth=xyzw)
    assert main(argv(tmp_path / "data", tmp_path / "out")) == 0
    err = capsys.readouterr().err
    assert err.count("quaternion order") == 1 and "warning: b (" in err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert len(report["data_warnings"]) == 1 and "quaternion order" in report["data_warnings"][0]
    assert "**Data check:** b (" in (tmp_path / "out" / "report.md").read_text()


def test_consistent_sequences_leave_no_data_warning(world, tmp_path, capsys):
    assert main(argv(world, tmp_path / "out")) == 0
    assert "warning:" not in capsys.readouterr().err
    assert json.loads((tmp_path / "out" / "report.json").read_text())["data_warnings"] == []
