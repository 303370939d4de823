"""Other methods' trajectory files scored beside the gyro methods in `evaluate` (`+estimates.NAME=...`)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from _asl import write_asl_sequence
from scipy.spatial.transform import Rotation

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.config import compose_config
from gyrodenoise.evaluate import evaluate
from gyrodenoise.models.build import build_model
from gyrodenoise.pretrained import save_model
from gyrodenoise.trajectory_files import TrajectoryFileError, read_tum, tum_text


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """One 20-s synthetic sequence `seq` evaluated once; its written trajectories are the other methods' files."""
    tmp = tmp_path_factory.mktemp("external")
    root = tmp / "data"
    write_asl_sequence(root / "seq", seconds=20.0, seed=4)
    model = save_model(build_model("calibrated"), {"name": "calibrated"}, tmp / "cal.pt", {"rate_hz": 200.0})
    first = run(root, model, tmp / "first")
    return root, model, tmp, first


def run(root, model, out, *overrides: str) -> dict:
    return evaluate(
        compose_config(
            "evaluate",
            [
                "dataset=asl_folder",
                f"dataset.root={root}",
                "dataset.train_seqs=[]",
                "dataset.test_seqs=[seq]",
                f"weights.proposed={model}",
                f"weights.calibrated={model}",
                "threads=1",
                "figures=false",
                f"out_dir={out}",
                *overrides,
            ],
        )
    )


def rewrite(src, dst, keep=slice(None), turn=None, in_ns=False):
    """A TUM file rewritten: some lines kept, the world frame turned, stamps in ns."""
    t_ns, R = read_tum(src)
    t_ns, R = t_ns[keep], R[keep]
    if turn is not None:
        R = turn @ R
    text = tum_text(t_ns, R, "rewritten")
    if in_ns:  # "s.fffffffff" (9 digits) -> the same stamp in ns
        text = "\n".join(ln if ln.startswith("#") else ln.replace(".", "", 1) for ln in text.splitlines())
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text(text)
    return dst


def test_a_methods_own_trajectory_file_scores_as_the_method(scored):
    """evaluate's written raw-IMU trajectory, read back as an external estimate, has the raw IMU's AOE and ROE; in
    another world frame (a VIO's) and with stamps in ns it scores the same."""
    root, model, tmp, first = scored
    raw = tmp / "first" / "trajectories" / "seq" / "raw_IMU.txt"
    turned = Rotation.from_euler("zx", [90, 10], degrees=True).as_matrix()
    rewrite(raw, tmp / "turned" / "seq.txt", turn=turned)
    rewrite(raw, tmp / "ns" / "seq.txt", in_ns=True)
    template = tmp / "first" / "trajectories" / "*" / "raw_IMU.txt"
    summary = run(
        root, model, tmp / "second", f"+estimates.copy={template}", f"+estimates.turned={tmp / 'turned'}",
        f"+estimates.ns={tmp / 'ns'}",
    )  # fmt: skip
    want = first["aoe_deg"]["seq"]["raw IMU"]
    for name in ("copy", "turned", "ns"):
        np.testing.assert_allclose(summary["aoe_deg"]["seq"][name], want, atol=1e-6, err_msg=name)
        assert summary["external_estimates"][name]["seq"]["coverage"] == 1.0
    table = (tmp / "second" / "table.md").read_text()
    assert "| copy | turned | ns |" in table and "scored on" not in table
    roe = (tmp / "second" / "roe.csv").read_text().splitlines()
    raw_rows = [r.split(",")[2:] for r in roe if ",raw IMU," in r]
    assert raw_rows and raw_rows == [r.split(",")[2:] for r in roe if ",ns," in r]


def test_a_partial_file_is_scored_on_what_it_covers_and_says_so(scored):
    root, model, tmp, first = scored
    raw = tmp / "first" / "trajectories" / "seq" / "raw_IMU.txt"
    t_ns, _ = read_tum(raw)
    n = len(t_ns)
    half = rewrite(raw, tmp / "half" / "seq.txt", keep=slice(n // 2, None))
    gap = rewrite(raw, tmp / "gap" / "seq.txt", keep=np.r_[0 : n // 4, n // 2 : n])  # a 5-s lost track
    summary = run(root, model, tmp / "third", f"+estimates.half={half.parent}", f"+estimates.gap={gap.parent}")
    cover = {k: summary["external_estimates"][k]["seq"]["coverage"] for k in ("half", "gap")}
    assert 0.45 < cover["half"] < 0.55 and 0.7 < cover["gap"] < 0.8, cover
    table = (tmp / "third" / "table.md").read_text()
    assert "half on seq: scored on" in table and "gap on seq: scored on" in table
    # re-aligned at its own start, the second half drifts less than the raw IMU over the whole flight
    assert summary["aoe_deg"]["seq"]["half"][0] < first["aoe_deg"]["seq"]["raw IMU"][0]


@pytest.mark.parametrize(
    "body, message",
    [
        ("1.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n", "line 2: stamp 1.0 is not after the previous line's"),
        ("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 1 0 0 1\n", "line 2: the quaternion .* is not of unit length"),
        ("1.0,0,0,0,0,0,0,1\n", "line 1: 1 fields, expected 8"),
        ("# t x\n1.0 0 0 0 0 0 0 1\nabc 0 0 0 0 0 0 1\n", "line 3: not numbers"),
        ("1.0 0 0 0 0 0 0 1\n", "1 poses; a trajectory needs at least 2"),
    ],
)
def test_bad_trajectory_lines_are_named(tmp_path, body, message):
    f = tmp_path / "t.txt"
    f.write_text(body)
    with pytest.raises(TrajectoryFileError, match=f"{f}, " + message if "line" in message else message):
        read_tum(f)


def test_stamps_read_exactly_in_s_and_ns(tmp_path):
    f = tmp_path / "t.txt"
    f.write_text("1403636580.838555648 0 0 0 0 0 0 1\n1403636580.843555 0 0 0 0 0 0 1\n")
    assert read_tum(f)[0].tolist() == [1403636580838555648, 1403636580843555000]
    f.write_text("1403636580838555648 0 0 0 0 0 0 1\n1403636580843555000 0 0 0 0 0 0 1\n")
    assert read_tum(f)[0].tolist() == [1403636580838555648, 1403636580843555000]


def test_negative_stamps_are_written_as_their_seconds():
    """-995,000,000 ns was written '-1.005000000' (floor division and remainder of a negative number): a recording whose
    clock reads below zero got its orientation.txt stamps wrong and out of order."""
    t_ns = np.array([-1_005_000_000, -995_000_000, -5_000_000, 0, 5_000_000])
    lines = tum_text(t_ns, np.repeat(np.eye(3)[None], len(t_ns), 0), "c").splitlines()[1:]
    assert [line.split()[0] for line in lines] == [
        "-1.005000000",
        "-0.995000000",
        "-0.005000000",
        "0.000000000",
        "0.005000000",
    ]


def test_a_file_saved_with_a_byte_order_mark_reads(tmp_path):
    """A TUM file saved by a Windows editor starts with a byte-order mark: its '# t tx ...' comment line was read as
    data ('9 fields, expected 8'), and a first pose line as 'not numbers'."""
    body = "1403636580.838555648 0 0 0 0 0 0 1\n1403636580.843555 0 0 0 0 0 0 1\n"
    f = tmp_path / "t.txt"
    for text in ("# t tx ty tz qx qy qz qw\n" + body, body):
        f.write_bytes(("\ufeff" + text).encode())
        assert read_tum(f)[0].tolist() == [1403636580838555648, 1403636580843555000]


def test_bad_estimate_settings_fail_before_the_work(scored, tmp_path):
    root, model, tmp, _ = scored
    with pytest.raises(FileNotFoundError, match=r"estimates.vio: no file .*nowhere/seq.txt"):
        run(root, model, tmp_path / "a", f"+estimates.vio={tmp_path / 'nowhere'}")
    with pytest.raises(ConfigError, match="'proposed' is one of evaluate's own methods"):
        run(root, model, tmp_path / "b", f"+estimates.proposed={tmp_path}")
    off = tmp_path / "off" / "seq.txt"
    off.parent.mkdir()
    off.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n")  # stamps relative to the start: not the IMU's clock
    with pytest.raises(TrajectoryFileError, match="cover none of seq's samples with ground truth"):
        run(root, model, tmp_path / "c", f"+estimates.vio={off.parent}")
    assert not (tmp_path / "c" / "results.json").exists()


def test_a_file_of_another_body_or_clock_is_named(scored, tmp_path):
    """Exact trajectories of another body (a camera), on a clock 0.2 s off, or rounded to 1 us: the first two scored
    92 and 8 deg in an independent check with no word, the last was 'scored on 100.0%' with a sample left out."""
    root, model, tmp, _ = scored
    t_ns, R = read_tum(tmp / "first" / "trajectories" / "seq" / "groundtruth.txt")
    cam = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    for name, t, rot in (("cam", t_ns, R @ cam), ("late", t_ns + 200_000_000, R), ("us", t_ns // 1000 * 1000, R)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "seq.txt").write_text(tum_text(t, rot, name))
    summary = run(root, model, tmp_path / "out", *(f"+estimates.{n}={tmp_path / n}" for n in ("cam", "late", "us")))
    said = " ".join(summary["warnings"])
    assert "cam on seq" in said and "90 deg away from the gyro's" in said and "camera-IMU extrinsic" in said
    late = next(w for w in summary["warnings"] if w.startswith("late on seq"))
    assert re.search(r"add -0\.(19|20)\d s to them", late), late  # the 0.2 s offset, to the IMU period
    assert "us on seq" not in said and summary["external_estimates"]["us"]["seq"]["coverage"] == 1.0
    assert summary["aoe_deg"]["seq"]["us"][0] < 1e-3


def test_estimate_errors_end_the_command_in_one_line(scored, tmp_path, capsys):
    from gyrodenoise.cli_errors import user_errors

    root, model, tmp, _ = scored
    bad = tmp_path / "bad" / "seq.txt"
    bad.parent.mkdir()
    bad.write_text("1.0,0,0,0,0,0,0,1\n")
    for override, said in (
        (f"+estimates.vio={bad.parent}", "line 1: 1 fields, expected 8"),
        (f"+estimates.proposed={bad.parent}", "'proposed' is one of evaluate's own methods"),
        (f"+estimates.vio={bad}", "is a file: give the folder that holds one <sequence>.txt per sequence"),
    ):
        with pytest.raises(SystemExit) as exit_, user_errors():
            run(root, model, tmp_path / "out", override)
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and err.startswith("error: ") and said in err and "Traceback" not in err


def test_a_validation_part_reads_its_recordings_file(scored, tmp_path):
    """split=val scores 'seq[10s:]', the part of recording 'seq' after its training seconds: the file is seq.txt
    (it looked for 'seq[10s:].txt'), and the part is scored on its own span of it."""
    root, model, tmp, _ = scored
    summary = evaluate(
        compose_config(
            "evaluate",
            [
                "dataset=asl_folder",
                f"dataset.root={root}",
                "dataset.train_seqs=[seq]",
                "dataset.train_duration_s=10",
                "split=val",
                f"weights.proposed={model}",
                f"weights.calibrated={model}",
                "threads=1",
                "figures=false",
                f"out_dir={tmp_path / 'val'}",
                f"+estimates.truth={tmp / 'first' / 'trajectories' / '*' / 'groundtruth.txt'}",
            ],
        )
    )
    (label,) = summary["aoe_deg"]
    assert label == "seq[10s:]" and summary["aoe_deg"][label]["truth"][0] < 1e-3
    assert summary["external_estimates"]["truth"][label]["coverage"] == 1.0
