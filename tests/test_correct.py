"""gyrodenoise.correct: own-data correction CLI, and one bad file per sanity check."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from _models import random_model

from gyrodenoise.correct import main
from gyrodenoise.data.checks import SanityCheckError, SanityWarning, run_checks
from gyrodenoise.data.imu_csv import G0, read_imu_csv
from gyrodenoise.data.readers import DataFormatError
from gyrodenoise.pretrained import resample_rate, save_model

TINY = {"name": "denoiser", "channels": (8, 16), "kernel_size": 5, "dilations": (1, 4)}
T0 = 1_600_000_000_000_000_000  # ns


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    cfg = {k: v for k, v in TINY.items() if k != "name"}
    m = random_model(seed=4, **cfg)
    return save_model(m, TINY, tmp_path_factory.mktemp("model") / "tiny.pt", meta={"rate_hz": 200.0})


def synth(n: int = 3000, rate: float = 200.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_ns, gyro rad/s, acc m/s^2): 2 s at rest, then smooth rotation with gravity in the acc."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    moving = (t > 2.0)[:, None]
    gyro = moving * 0.6 * np.sin(2 * np.pi * np.array([0.3, 0.5, 0.7]) * t[:, None]) + rng.normal(0, 2e-3, (n, 3))
    acc = np.array([0.0, 0.0, G0]) + moving * 0.5 * np.sin(2 * np.pi * 0.4 * t)[:, None] + rng.normal(0, 0.02, (n, 3))
    return T0 + np.round(t * 1e9).astype(np.int64), gyro, acc


def write_asl(path, t_ns, gyro, acc):
    with open(path, "w") as fh:
        fh.write("#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n")
        for t, w, a in zip(t_ns.tolist(), gyro.tolist(), acc.tolist(), strict=True):
            fh.write(f"{t},{w[0]!r},{w[1]!r},{w[2]!r},{a[0]!r},{a[1]!r},{a[2]!r}\n")
    return path


def run(args, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def read_out(folder):
    d = np.loadtxt(folder / "imu_corrected.csv", delimiter=",", comments="#", dtype=np.float64)
    q = np.loadtxt(folder / "orientation.txt", comments="#")
    return d, q


# ------------------------------------------------------------------ working inputs


def test_asl_file_batch_equals_streaming(tmp_path, model_file, capsys):
    f = write_asl(tmp_path / "data.csv", *synth())
    code, out, err = run([f, "-m", model_file, "-o", tmp_path / "b"], capsys)
    assert code == 0, err
    assert err == ""  # a clean recording gives no warning
    run([f, "-m", model_file, "-o", tmp_path / "s", "--engine", "streaming"], capsys)
    (db, qb), (ds, qs) = read_out(tmp_path / "b"), read_out(tmp_path / "s")
    assert db.shape == (3000, 7) and qb.shape == (3000, 8)
    assert np.abs(db[:, 1:4] - ds[:, 1:4]).max() < 1e-5
    assert np.abs(qb - qs).max() < 1e-5
    np.testing.assert_array_equal(qb[0, 1:], [0, 0, 0, 0, 0, 0, 1])  # identity start, TUM order
    t_in = np.loadtxt(f, delimiter=",", comments="#", dtype=np.int64, usecols=0)
    assert (np.loadtxt(tmp_path / "b" / "imu_corrected.csv", delimiter=",", dtype=np.int64, usecols=0) == t_in).all()
    assert abs(qb[1, 0] - t_in[1] * 1e-9) < 1e-6


def test_custom_csv_with_units_gives_the_same_correction(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    ref = write_asl(tmp_path / "ref.csv", t_ns, gyro, acc)
    custom = tmp_path / "phone.csv"
    with open(custom, "w") as fh:
        fh.write("ax;ay;az;time_us;gx;gy;gz\n")
        for t, w, a in zip(t_ns.tolist(), np.degrees(gyro).tolist(), (acc / G0).tolist(), strict=True):
            fh.write(f"{a[0]!r};{a[1]!r};{a[2]!r};{t / 1000:.3f};{w[0]!r};{w[1]!r};{w[2]!r}\n")
    args = ["--columns", "time_us,gx,gy,gz,ax,ay,az", "--time-unit", "us", "--gyro-unit", "deg/s", "--acc-unit", "g"]
    assert run([custom, "-m", model_file, "-o", tmp_path / "c", *args], capsys)[0] == 0
    assert run([ref, "-m", model_file, "-o", tmp_path / "r"], capsys)[0] == 0
    (dc, _), (dr, _) = read_out(tmp_path / "c"), read_out(tmp_path / "r")
    assert np.abs(dc[:, 1:] - dr[:, 1:]).max() < 1e-5


def test_initial_orientation_from_gravity(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    tilt = np.array([0.0, np.sin(0.3), np.cos(0.3)]) * G0  # tilted by 0.3 rad about x
    acc = acc - [0, 0, G0] + tilt
    f = write_asl(tmp_path / "data.csv", t_ns, gyro, acc)
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "o", "--initial-orientation", "gravity"], capsys)
    assert code == 0 and "initial-orientation" not in err  # synth() rests for its first 2 s
    _, q = read_out(tmp_path / "o")
    from scipy.spatial.transform import Rotation

    up = Rotation.from_quat(q[0, 4:]).apply(tilt / G0)
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-2)
    moving = write_asl(tmp_path / "moving.csv", t_ns[400:], gyro[400:], acc[400:])  # starts in motion
    code, _, err = run([moving, "-m", model_file, "-o", tmp_path / "m", "--initial-orientation", "gravity"], capsys)
    assert code == 0 and "gravity takes roll and pitch from the first 0.5 s, but the IMU moves there" in err


def test_real_euroc_slice_batch_equals_streaming(euroc_root, tmp_path, model_file, capsys):
    lines = (euroc_root / "MH_02_easy" / "mav0" / "imu0" / "data.csv").read_text().splitlines()[:2001]
    f = tmp_path / "data.csv"
    f.write_text("\n".join(lines) + "\n")
    for engine in ("batch", "streaming"):
        code, _, err = run([f, "-m", model_file, "-o", tmp_path / engine, "--engine", engine], capsys)
        assert code == 0, err
    (db, qb), (ds, qs) = read_out(tmp_path / "batch"), read_out(tmp_path / "streaming")
    assert np.abs(db[:, 1:4] - ds[:, 1:4]).max() < 1e-5
    assert np.abs(qb[:, 4:] - qs[:, 4:]).max() < 1e-5


# ------------------------------------------------------------------ one bad file per check


def bad_file(tmp_path, name="bad.csv", **changes):
    t_ns, gyro, acc = synth()
    t_ns = changes.get("t_ns", t_ns)
    gyro = changes.get("gyro", gyro)
    acc = changes.get("acc", acc)
    return write_asl(tmp_path / name, t_ns, gyro, acc)


def expect_error(capsys, args, *needles):
    code, _, err = run(args, capsys)
    assert code == 2
    for needle in needles:
        assert needle in err, err
    return err


def test_a_ground_truth_file_is_refused_by_its_header(tmp_path, model_file, capsys):
    """An ASL ground-truth file has 7+ numeric columns and |q| = 1 passes for an accelerometer in g: following that
    advice gave a 'corrected' output of poses. Its header names it."""
    f = tmp_path / "data.csv"
    rows = "\n".join(f"{i * 5_000_000},{i},0,0,1,0,0,0" for i in range(400))
    header = "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []"
    f.write_text(header + "\n" + rows + "\n")
    for extra in ([], ["--acc-unit", "g"]):
        expect_error(capsys, [f, "-m", model_file, "-o", tmp_path / "o", *extra], "pose (ground-truth) file", "imu0")


def test_a_datasets_folder_names_its_sequence_folders(tmp_path, model_file, capsys):
    """dataset.root given instead of one of its sequences: the error said only which files the folder lacks."""
    for name in ("walk_2", "walk_1"):
        (tmp_path / "root" / name / "mav0" / "imu0").mkdir(parents=True)
        write_asl(tmp_path / "root" / name / "mav0" / "imu0" / "data.csv", *synth(n=50))
    (tmp_path / "root" / "notes").mkdir()
    expect_error(capsys, [tmp_path / "root", "-m", model_file, "-o", tmp_path / "o"],
                 "It holds the sequence folders walk_1, walk_2: give one of them")  # fmt: skip


def test_an_unreadable_folder_beside_the_sequences_keeps_the_hint(tmp_path, model_file, capsys, monkeypatch):
    """A drive's lost+found beside the sequences: on Python 3.11 is_file() raises PermissionError there (root here
    reads everything, so the refusal is played), which replaced the folder's one-line message with a traceback."""
    import pathlib

    (tmp_path / "root" / "walk_1" / "mav0" / "imu0").mkdir(parents=True)
    write_asl(tmp_path / "root" / "walk_1" / "mav0" / "imu0" / "data.csv", *synth(n=50))
    (tmp_path / "root" / "lost+found").mkdir()
    is_file = pathlib.Path.is_file

    def refusing(self, *args, **kwargs):
        if "lost+found" in self.parts:
            raise PermissionError(13, "Permission denied", str(self))
        return is_file(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "is_file", refusing)
    expect_error(capsys, [tmp_path / "root", "-m", model_file, "-o", tmp_path / "o"],
                 "It holds the sequence folders walk_1: give one of them")  # fmt: skip


def test_a_file_that_is_not_a_model_is_refused_in_one_line(tmp_path, capsys):
    f = bad_file(tmp_path)
    summary = tmp_path / "summary.json"
    summary.write_text('{"a": 1}')
    for not_a_model in (f, summary):  # an IMU CSV, a run's summary
        err = expect_error(capsys, [f, "-m", not_a_model, "-o", tmp_path / "o"], "not a model file", "shipped model")
        assert "weights_only" not in err and "Traceback" not in err


def test_gyro_in_deg_s(tmp_path, model_file, capsys):
    f = bad_file(tmp_path, gyro=np.degrees(synth()[1]))
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], str(f), "column 2", "--gyro-unit deg/s")
    assert run([f, "-m", model_file, "-o", tmp_path, "--gyro-unit", "deg/s"], capsys)[0] == 0


def test_gyro_rad_s_read_as_deg_s_warns(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    acc = acc + np.random.default_rng(1).normal(0, 2.0, acc.shape) * (np.arange(len(acc)) > 400)[:, None]
    f = write_asl(tmp_path / "g.csv", t_ns, gyro, acc)
    code, _, err = run([f, "-m", model_file, "-o", tmp_path, "--gyro-unit", "deg/s", "--force"], capsys)
    assert code == 0 and "--gyro-unit deg/s" in err


@pytest.mark.parametrize(
    ("scale", "hint"),
    [(1 / G0, "--acc-unit g"), (1000 / G0, "--acc-unit mg"), (0.0, "--columns"), (3.0, "--acc-unit")],
)
def test_acc_norm_not_g_at_rest(tmp_path, model_file, capsys, scale, hint):
    t_ns, gyro, acc = synth()
    f = write_asl(tmp_path / "acc.csv", t_ns, gyro, acc * scale if scale else acc - acc.mean(0))
    err = expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], str(f), "column 5", hint)
    assert "at rest" in err or "no rest" in err


def test_a_corrupted_sample_is_refused_and_a_clipped_gyro_warns(tmp_path, model_file, capsys):
    """One finite but impossible value passed the unit check (a 99th percentile) and spoiled ~2.5 s of outputs
    (a 'mean correction' of 2e26 deg/s); a gyro clipped at its range was corrected without a word."""
    gyro = synth()[1]
    gyro[1500, 2] = 1e30
    f = bad_file(tmp_path, gyro=gyro)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path / "o"], f"{f}:1502", "beyond what any IMU measures")
    gyro = synth()[1]
    gyro[:, 2] = np.clip(gyro[:, 2], -0.5, 0.5)
    code, _, err = run([bad_file(tmp_path, "clipped.csv", gyro=gyro), "-m", model_file, "-o", tmp_path / "c"], capsys)
    assert code == 0 and "column 4" in err and "looks saturated" in err and "0.5 rad/s" in err
    code, _, err = run([bad_file(tmp_path, "clean.csv"), "-m", model_file, "-o", tmp_path / "n"], capsys)
    assert code == 0 and "saturated" not in err


def test_a_quantized_gyro_at_rest_is_not_called_clipped(tmp_path, model_file, capsys):
    """A still recording of a quantized gyro repeats its largest value, a few steps, in many runs: that is not a
    clipped range (a false warning on a 50-row EuRoC slice); the same gyro clipped at 0.5 rad/s still warns."""
    step = np.radians(0.04)  # EuRoC's ADIS16448 step
    t_ns, gyro, acc = synth()
    still = np.round(np.random.default_rng(3).normal(0.0, step, gyro.shape) / step) * step
    code, _, err = run(
        [write_asl(tmp_path / "still.csv", t_ns, still, acc), "-m", model_file, "-o", tmp_path / "s"], capsys
    )
    assert code == 0 and "saturated" not in err
    clipped = np.round(np.clip(gyro, -0.5, 0.5) / step) * step
    code, _, err = run(
        [write_asl(tmp_path / "clip.csv", t_ns, clipped, acc), "-m", model_file, "-o", tmp_path / "c"], capsys
    )
    assert code == 0 and "looks saturated" in err


def test_acc_m_s2_read_as_g(tmp_path, model_file, capsys):
    f = bad_file(tmp_path)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path, "--acc-unit", "g"], "--acc-unit m/s^2")


def test_gyro_and_acc_units_wrong_together_are_told_together(tmp_path, model_file, capsys):
    f = bad_file(tmp_path, gyro=np.degrees(synth()[1]), acc=synth()[2] / G0)
    err = expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], "2 problems", "--gyro-unit deg/s", "--acc-unit g")
    assert run([f, "-m", model_file, "-o", tmp_path, "--gyro-unit", "deg/s", "--acc-unit", "g"], capsys)[0] == 0, err


def test_force_turns_unit_errors_into_warnings(tmp_path, model_file, capsys):
    f = bad_file(tmp_path, acc=synth()[2] / G0)
    code, _, err = run([f, "-m", model_file, "-o", tmp_path, "--force"], capsys)
    assert code == 0 and "warning:" in err and "--acc-unit g" in err


def test_wrong_time_unit(tmp_path, model_file, capsys):
    t_ns = synth()[0]
    f = bad_file(tmp_path, t_ns=(t_ns - T0) // 1000 + T0 // 1000)  # stamps in us, read as ns
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], str(f), "column 1", "--time-unit us")
    assert run([f, "-m", model_file, "-o", tmp_path, "--time-unit", "us"], capsys)[0] == 0


def test_stamps_in_bursts_are_not_called_a_time_unit(tmp_path, model_file, capsys):
    """A driver that stamps each FIFO read (10 samples 1 µs apart every 50 ms): not a unit to change."""
    k = np.arange(len(synth()[0]))
    f = bad_file(tmp_path, t_ns=T0 + (k // 10) * 50_000_000 + (k % 10) * 1_000)
    err = expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], str(f), "in bursts", "its own time")
    assert "--time-unit" not in err


def test_rate_differs_from_model_warns_then_resamples(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth(n=1500, rate=100.0)
    f = write_asl(tmp_path / "r100.csv", t_ns, gyro, acc)
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "a"], capsys)
    assert code == 0 and "100 Hz" in err and "200 Hz" in err and "--resample" in err
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "a", "--strict"], capsys)  # the model does not fit
    assert code == 3 and "1 warning(s) above that the model does not fit" in err
    code, out, err = run([f, "-m", model_file, "-o", tmp_path / "b", "--resample"], capsys)
    assert code == 0 and "resampled to 200 Hz" in out and err == ""
    d, _ = read_out(tmp_path / "b")
    t = np.loadtxt(tmp_path / "b" / "imu_corrected.csv", delimiter=",", dtype=np.int64, usecols=0)
    assert len(d) == 2999 and (np.diff(t) == 5_000_000).all()


def test_gap_warns_with_line(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    keep = np.ones(len(t_ns), bool)
    keep[1000:1100] = False  # 0.5 s missing
    f = write_asl(tmp_path / "gap.csv", t_ns[keep], gyro[keep], acc[keep])
    code, _, err = run([f, "-m", model_file, "-o", tmp_path], capsys)
    assert code == 0
    assert f"{f}:1002" in err and "1 gap(s)" in err and "--resample" in err  # line 1002: after header + 1000
    # --resample at the model's own rate interpolates over the gap onto a uniform grid (it did nothing before)
    code, out, err = run([f, "-m", model_file, "-o", tmp_path / "r", "--resample"], capsys)
    assert code == 0 and "gap" not in err and "resampled to 200 Hz" in out
    t = np.loadtxt(tmp_path / "r" / "imu_corrected.csv", delimiter=",", dtype=np.int64, usecols=0)
    assert (np.diff(t) == 5_000_000).all()


def test_missing_samples_are_said_one_as_a_note_two_as_a_gap(tmp_path, model_file, capsys):
    """A fresh-user audit dropped single lines: nothing was said (steps of 2 periods), and two in a row (3 periods)
    passed too, where the streaming corrector refuses them (its gap is 2.5 periods)."""
    t_ns, gyro, acc = synth()
    keep = np.ones(len(t_ns), bool)
    keep[[500, 900]] = False
    f = write_asl(tmp_path / "one.csv", t_ns[keep], gyro[keep], acc[keep])
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "a"], capsys)
    assert code == 0 and f"note: {f}:502: 2 single missing sample(s)" in err and "gap(s)" not in err
    keep[1500:1502] = False
    f = write_asl(tmp_path / "two.csv", t_ns[keep], gyro[keep], acc[keep])
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "b"], capsys)
    assert code == 0 and "1 gap(s)" in err and "2 single missing" in err


def test_time_in_seconds_read_as_ns_says_so(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    f = tmp_path / "seconds.csv"
    rows = [
        f"{t * 1e-9:.6f},{w[0]},{w[1]},{w[2]},{a[0]},{a[1]},{a[2]}" for t, w, a in zip(t_ns, gyro, acc, strict=True)
    ]
    f.write_text("t,wx,wy,wz,ax,ay,az\n" + "\n".join(rows) + "\n")
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:3", "fractional part", "--time-unit s")
    assert run([f, "-m", model_file, "-o", tmp_path / "s", "--time-unit", "s"], capsys)[0] == 0


def test_gyro_only_file_says_the_accelerometer_is_needed(tmp_path, model_file, capsys):
    t_ns, gyro, _ = synth()
    f = tmp_path / "gyro_only.csv"
    f.write_text("\n".join(f"{t},{w[0]},{w[1]},{w[2]}" for t, w in zip(t_ns, gyro, strict=True)) + "\n")
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:1: 4 columns", "accelerometer")


def test_duplicated_stamps(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    t_ns = t_ns.copy()
    t_ns[501] = t_ns[500]
    f = write_asl(tmp_path / "dup.csv", t_ns, gyro, acc)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:503", "line 502", "--drop-duplicates")
    code, _, err = run([f, "-m", model_file, "-o", tmp_path, "--drop-duplicates"], capsys)
    assert code == 0 and "dropped 1" in err
    assert len(read_out(tmp_path)[0]) == 2999


def test_a_line_repeated_exactly_is_kept_once(tmp_path, model_file, capsys):
    """A logger's sample written twice (same stamp, same values) was refused while training reads the same file
    (own-data walkthrough): one sample, kept once and said; --drop-duplicates is for stamps with other values."""
    t_ns, gyro, acc = synth()
    idx = np.insert(np.arange(len(t_ns)), [500, 800, 800], [499, 799, 799])
    f = write_asl(tmp_path / "rep.csv", t_ns[idx], gyro[idx], acc[idx])
    code, _, err = run([f, "-m", model_file, "-o", tmp_path], capsys)
    assert code == 0 and f"{f}:502: 3 lines repeat the line before exactly" in err and "copy of line 501" in err
    assert len(read_out(tmp_path)[0]) == len(t_ns)


def test_time_going_back(tmp_path, model_file, capsys):
    t_ns = synth()[0].copy()
    t_ns[[10, 11]] = t_ns[[11, 10]]
    f = bad_file(tmp_path, t_ns=t_ns)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:13", "Sort the file")


def test_nan_and_unknown_column(tmp_path, model_file, capsys):
    gyro = synth()[1].copy()
    gyro[7, 1] = np.nan
    f = bad_file(tmp_path, gyro=gyro)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:9", "column 3", "NaN")
    expect_error(capsys, [bad_file(tmp_path, "ok.csv"), "-m", model_file, "--columns", "timestamp,a,b,c,d,e,f"], "'a'")


def test_binary_file_is_named_with_what_to_do(tmp_path, model_file, capsys):
    f = tmp_path / "imu.bin"
    f.write_bytes(b"\x89\xb9PNG\r\n" + bytes(range(256)) * 20)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:1: byte 0x89 at offset 0", "not a UTF-8 text CSV")


def test_missing_model_lists_choices(tmp_path, capsys):
    expect_error(capsys, [bad_file(tmp_path), "-m", "no_such_model"], "neither a file nor a shipped model")


def test_checks_api_warns_with_warning_class(tmp_path):
    t_ns, gyro, acc = synth(n=1500, rate=100.0)
    rec = read_imu_csv(write_asl(tmp_path / "x.csv", t_ns, gyro, acc))
    with pytest.warns(SanityWarning, match="--resample"):
        run_checks(rec, 200.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, report, resample = run_checks(rec, 200.0, resample=True)
    assert resample and math.isclose(report.rate_hz, 100.0, rel_tol=1e-6)
    rec.gyro[:] *= 100
    with pytest.raises(SanityCheckError, match="deg/s"):
        run_checks(rec, 200.0)


def test_non_number_field_says_what_to_do(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    f = write_asl(tmp_path / "imu.csv", t_ns, gyro, acc)
    lines = f.read_text().splitlines()
    fields = lines[199].split(",")
    fields[3] = "abc"
    lines[199] = ",".join(fields)
    f.write_text("\n".join(lines) + "\n")
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], f"{f}:200: column 4 is 'abc'", "fix or remove")


def test_default_output_folder_is_under_outputs(tmp_path, model_file, capsys, monkeypatch):
    # an ASL sequence folder gives its name; the files land under outputs/, which git ignores
    seq = tmp_path / "data" / "MY_SEQ" / "mav0" / "imu0"
    seq.mkdir(parents=True)
    write_asl(seq / "data.csv", *synth())
    monkeypatch.chdir(tmp_path)
    code, out, _ = run([tmp_path / "data" / "MY_SEQ", "-m", model_file], capsys)
    assert code == 0
    folder = tmp_path / "outputs" / "correct" / "MY_SEQ"
    assert (folder / "imu_corrected.csv").is_file() and (folder / "correct_summary.json").is_file()
    assert str(Path("outputs", "correct", "MY_SEQ", "imu_corrected.csv")) in out


def test_output_file_that_is_a_folder_is_refused_before_the_work(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    f = write_asl(tmp_path / "imu.csv", t_ns, gyro, acc)
    (tmp_path / "tum").mkdir()
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path / "out", "--out-tum", tmp_path / "tum"], "is a folder")
    assert not (tmp_path / "out").exists()  # nothing half-written


def test_every_bad_line_is_reported_in_one_run(tmp_path, model_file, capsys):
    """A damaged file: its truncated line, non-number and NaN come in one error, in line order."""
    t_ns, gyro, acc = synth()
    f = write_asl(tmp_path / "imu.csv", t_ns, gyro, acc)
    lines = f.read_text().splitlines()
    lines[300] = lines[300][:20]  # truncated
    fields = lines[100].split(",")
    fields[2] = "x"
    lines[100] = ",".join(fields)
    fields = lines[500].split(",")
    fields[5] = "nan"
    lines[500] = ",".join(fields)
    f.write_text("\n".join(lines) + "\n")
    err = expect_error(capsys, [f, "-m", model_file, "-o", tmp_path], "3 lines to fix in all")
    first, second = err.index(f"{f}:101: column 3 is 'x'"), err.index(f"{f}:301: ")
    assert first < second < err.index(f"{f}:501: column 6 (a_y) is nan")


def test_the_sensor_a_model_learned_is_said():
    from gyrodenoise.correct import trained_on

    meta = {"dataset": "euroc", "sensor": {"model": "ADIS16448", "rate_hz": 200.0}}
    assert trained_on(meta) == "the euroc dataset's ADIS16448"
    assert trained_on({"sensor": {"model": "BMI160"}}) == "a BMI160" and trained_on({"dataset": "mine"}) is None


def test_the_placeholder_sensor_of_own_data_is_not_named_as_one():
    """A model trained with dataset=asl_folder and no dataset.sensor.model 'learned the errors of the handheld
    dataset's unknown' (correct's note), and its ONNX metadata and the other-IMU warning named 'unknown' as the
    sensor (own-data walkthrough)."""
    from gyrodenoise.correct import trained_on
    from gyrodenoise.export import onnx_metadata
    from gyrodenoise.models.build import build_model
    from gyrodenoise.pretrained import other_imu_warning

    meta = {"name": "model.pt", "dataset": "handheld", "sensor": {"model": "unknown", "rate_hz": 400.0}}
    assert trained_on(meta) is None
    assert "gyrodenoise.sensor" not in onnx_metadata(build_model("calibrated"), meta)
    assert "gyrodenoise.sensor" in onnx_metadata(build_model("calibrated"), {**meta, "sensor": {"model": "BMI088"}})
    assert "trained on handheld, not on euroc" in other_imu_warning(meta, "euroc", {"model": "ADIS16448"})
    from gyrodenoise.c_export import c_sources

    header = c_sources(build_model("calibrated"), meta)["gyrodenoise_model.h"]
    assert " * Sensor: not recorded\n" in header  # it said 'Sensor: unknown: learned the errors of this IMU model'


def test_a_second_run_into_the_same_folder_says_it_replaces_the_first(tmp_path, model_file, capsys):
    f = bad_file(tmp_path)
    assert run([f, "-m", model_file, "-o", tmp_path / "o"], capsys)[0] == 0
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "o"], capsys)
    assert code == 0 and "replacing the outputs of an earlier run" in err


def test_an_interrupted_rerun_leaves_none_of_the_earlier_outputs(tmp_path, model_file, capsys, monkeypatch):
    """The earlier run's CSV stayed, whole, beside nothing that said which model wrote it."""
    import gyrodenoise.correct as correct_module

    f = bad_file(tmp_path)
    assert run([f, "-m", model_file, "-o", tmp_path / "o"], capsys)[0] == 0

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(correct_module, "write_text", interrupted)
    code, _, err = run([f, "-m", model_file, "-o", tmp_path / "o"], capsys)
    assert code == 130 and err.strip().endswith("interrupted: no output of this run was left half-written")
    assert "Traceback" not in err and sorted(p.name for p in (tmp_path / "o").iterdir()) == []


def test_outputs_that_would_replace_the_input_or_each_other_are_refused(tmp_path, model_file, capsys):
    f = bad_file(tmp_path)
    before = f.read_bytes()
    expect_error(capsys, [f, "-m", model_file, "--out-csv", f], "--out-csv and the input are the same file")
    both = tmp_path / "o" / "x.txt"
    expect_error(capsys, [f, "-m", model_file, "--out-csv", both, "--out-tum", both], "--out-tum and --out-csv are")
    assert f.read_bytes() == before and not both.exists()
    # found before any folder is made: no file can be made in /proc (atomic.output_path_problem)
    expect_error(capsys, [f, "-m", model_file, "-o", "/proc/gyrodenoise_out"], "-o /proc/gyrodenoise_out: /proc cannot")


def _user_csv(path, header, t_ns, gyro, acc, order=(0, 1, 2, 3, 4, 5, 6), t_scale=1e-9, g_scale=1.0, a_scale=1.0):
    cols = np.column_stack([(t_ns - T0) * t_scale, gyro * g_scale, acc * a_scale])[:, list(order)]
    np.savetxt(path, cols, delimiter=",", header=header, comments="", fmt="%.12g")
    return path


def test_units_the_header_declares_are_read_and_said(tmp_path, model_file, capsys):
    """A header 't [s],gx [deg/s],...,ax [g]' was read as ns, rad/s, m/s^2 and refused one unit per rerun
    (first-hour audit); the units it declares are now read, a note says so, and a flag still overrides them."""
    t_ns, gyro, acc = synth()
    header = "t [s],gx [deg/s],gy [deg/s],gz [deg/s],ax [g],ay [g],az [g]"
    f = _user_csv(tmp_path / "phone.csv", header, t_ns, gyro, acc, g_scale=180 / math.pi, a_scale=1 / G0)
    code, out, _ = run([f, "-m", model_file, "-o", tmp_path / "a"], capsys)
    assert code == 0 and "note: read time in s, gyro in deg/s, acc in g, as the header declares" in out
    rec = read_imu_csv(f)
    np.testing.assert_allclose(rec.gyro, gyro, atol=1e-9)
    np.testing.assert_allclose(rec.acc, acc, atol=1e-9)
    assert rec.units_from_header == ["time", "gyro", "acc"] and abs(int(rec.t_ns[1] - rec.t_ns[0]) - 5_000_000) <= 1
    # a flag wins over the header (here wrongly: the gyro read as rad/s is 57 times too large and refused)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path / "b", "--gyro-unit", "rad/s"], "--gyro-unit deg/s")


def test_columns_whose_header_names_say_otherwise_get_the_columns_to_pass(tmp_path, model_file, capsys):
    t_ns, gyro, acc = synth()
    f = _user_csv(tmp_path / "swapped.csv", "time,ax,ay,az,gx,gy,gz", t_ns, gyro, acc, order=(0, 4, 5, 6, 1, 2, 3))
    err = expect_error(capsys, [f, "-m", model_file, "-o", tmp_path / "a", "--time-unit", "s"], "wx <- 'ax'")
    assert "Pass --columns 1,5,6,7,2,3,4 (read off the header)" in err
    code, _, _ = run(
        [f, "-m", model_file, "-o", tmp_path / "b", "--time-unit", "s", "--columns", "1,5,6,7,2,3,4"], capsys
    )
    assert code == 0


def test_axis_letters_glued_to_the_name_are_read(tmp_path, model_file, capsys):
    """A phone logger's 'accX [g],...,gyroX [deg/s],...,temp [C]' got 'Map them with --columns' and no columns to
    pass: the axis of accX/gyroZ (camelCase) was not read (own-data walkthrough)."""
    from gyrodenoise.data.asl_header import classify

    t_ns, gyro, acc = synth()
    header = "time [s],accX [g],accY [g],accZ [g],gyroX [deg/s],gyroY [deg/s],gyroZ [deg/s]"
    f = _user_csv(tmp_path / "phone.csv", header, t_ns, gyro, acc, order=(0, 4, 5, 6, 1, 2, 3), g_scale=180 / math.pi,
                  a_scale=1 / G0)  # fmt: skip
    err = expect_error(capsys, [f, "-m", model_file, "-o", tmp_path / "a"], "wx <- 'accX [g]'")
    assert "Pass --columns 1,5,6,7,2,3,4 (read off the header)" in err
    assert run([f, "-m", model_file, "-o", tmp_path / "b", "--columns", "1,5,6,7,2,3,4"], capsys)[0] == 0
    for name, kind_axis in [("rotationRateY", ("gyro", "y")), ("userAccelerationZ", ("acc", "z")),
                            ("GyrX", ("gyro", "x")), ("qW", ("quat", "w")), ("acc_max", ("acc", None))]:  # fmt: skip
        assert classify(name) == kind_axis, name


def test_a_header_column_of_no_axis_does_not_break_the_columns_read_off_it():
    """A 'gyro_norm' column (a kind, no axis) raised TypeError where --columns is read off a header."""
    from gyrodenoise.data.asl_header import columns_from_names

    assert columns_from_names(["t", "gyro_norm", "gx", "gy", "gz", "ax", "ay", "az"]) == "1,3,4,5,6,7,8"
    assert columns_from_names(["time", "ax", "ay", "az", "gx", "gy", "gz"]) == "1,5,6,7,2,3,4"


def test_a_time_column_named_in_seconds_is_the_time_and_its_unit():
    """'time_s', 't_sec', 'seconds' (a fresh-user audit): neither the time column nor a unit, so no --columns was read
    off the header and --time-unit s had to be given by hand; a frame's S (w_RS_S) stays no unit."""
    from gyrodenoise.data.asl_header import _split, columns_from_names, declared_units

    for name in ("time_s", "t_s", "timestamp_s", "time_sec", "seconds", "stamp_seconds"):
        names = [name, "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"]
        assert columns_from_names(names) == "1,5,6,7,2,3,4", name
        assert declared_units(name, names[4:], names[1:4]) == {"time": "s"}, name
    assert _split("w_RS_S_x [rad s^-1]") == ("w_rs_s_x", "rad s^-1") and _split("s") == ("s", "")


def test_stamps_in_exponent_form_that_lost_their_digits_are_refused(tmp_path):
    """'1.600000000000e+18' (ns written as floats by a spreadsheet or pandas): the samples' times were rounded to a
    millisecond and read without a word; 16 digits (1 µs) still read."""
    t, g, a = synth(600)
    lines = write_asl(tmp_path / "plain.csv", t, g, a).read_text().splitlines()

    def stamps_as(fmt: str, name: str) -> Path:
        rows = [fmt.format(float(line.split(",", 1)[0])) + "," + line.split(",", 1)[1] for line in lines[1:]]
        (tmp_path / name).write_text("\n".join([lines[0], *rows]) + "\n")
        return tmp_path / name

    with pytest.raises(DataFormatError, match=r"coarse.csv:2: the time column is '1.600000000000e\+18', in exponent "
                       r"form with too few digits: its last digit is worth 0.001 s"):  # fmt: skip
        read_imu_csv(stamps_as("{:.12e}", "coarse.csv"))
    np.testing.assert_allclose(read_imu_csv(stamps_as("{:.15e}", "fine.csv")).t_ns, t, atol=1000)


def test_a_csv_with_every_field_in_quotes_is_read(tmp_path):
    t, g, a = synth(300)
    plain = write_asl(tmp_path / "plain.csv", t, g, a)
    quoted = tmp_path / "quoted.csv"
    lines = plain.read_text().splitlines()
    quoted.write_text("".join(",".join(f'"{f}"' for f in line.split(",")) + "\n" for line in lines))
    rec = read_imu_csv(quoted, columns="timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z")
    np.testing.assert_array_equal(rec.t_ns, t)
    np.testing.assert_array_equal(rec.gyro, read_imu_csv(plain).gyro)


def test_nanosecond_stamps_read_as_seconds_are_refused_in_one_line(tmp_path, model_file, capsys):
    """ns stamps read as s (--time-unit s, or a header that says s) overflowed int64 with a traceback; the CLI and the
    array API now name the line and the unit to pass."""
    t, g, a = synth()
    f = write_asl(tmp_path / "ns.csv", t, g, a)
    expect_error(capsys, [f, "-m", model_file, "-o", tmp_path, "--time-unit", "s"], f"{f}:2", "int64", "--time-unit ns")
    from gyrodenoise.correct import correct_arrays

    with pytest.raises(DataFormatError, match="beyond what int64 nanoseconds hold.*time_unit='ns'"):
        correct_arrays(t, g, a, model_file, time_unit="s")


def test_decimal_stamps_are_read_exactly_and_a_nan_stamp_is_named(tmp_path):
    """'1600000000.005000' s read through a float moved the stamps by up to ~100 ns; they are exact now. A stamp
    'nan' stopped the reader with a bare StopIteration."""
    t, g, a = synth(400)
    lines = write_asl(tmp_path / "plain.csv", t, g, a).read_text().splitlines()
    seconds = [divmod(int(x.split(",", 1)[0]), 10**9) for x in lines[1:]]
    rows = [f"{s}.{ns // 1000:06d}," + x.split(",", 1)[1] for (s, ns), x in zip(seconds, lines[1:], strict=True)]
    assert rows[1].startswith("1600000000.005000,")
    (tmp_path / "s.csv").write_text("\n".join(["t [s],wx,wy,wz,ax,ay,az", *rows]) + "\n")
    rec = read_imu_csv(tmp_path / "s.csv")
    assert rec.units["time"] == "s"
    np.testing.assert_array_equal(rec.t_ns, t)  # exact to the ns
    rows[3] = "nan," + rows[3].split(",", 1)[1]
    (tmp_path / "nan.csv").write_text("\n".join(["t [s],wx,wy,wz,ax,ay,az", *rows]) + "\n")
    with pytest.raises(DataFormatError, match=r"nan.csv:5: column 1 is 'nan', not a finite time"):
        read_imu_csv(tmp_path / "nan.csv")


def test_a_one_member_ensemble_writes_no_spread_columns(tmp_path, model_file, capsys):
    """Its spread is 0 by construction, which read as perfect confidence; the C example writes no std columns for it
    either."""
    from gyrodenoise import ensemble as ensemble_cli
    from gyrodenoise.pretrained import ModelQualityWarning

    one = tmp_path / "one.pt"
    with pytest.warns(ModelQualityWarning, match="one member"):
        assert ensemble_cli.main(["build", str(model_file), "--out", str(one)]) == 0
    f = bad_file(tmp_path)
    for engine in ("batch", "streaming"):
        assert run([f, "-m", one, "-o", tmp_path / engine, "--engine", engine], capsys)[0] == 0
        header = (tmp_path / engine / "imu_corrected.csv").read_text().splitlines()[0]
        assert "w_std" not in header and header.count(",") == 6


def test_columns_from_python_may_be_a_list(tmp_path):
    t, g, a = synth(200)
    f = write_asl(tmp_path / "x.csv", t, g, a)
    by_list = read_imu_csv(f, columns=["timestamp [ns]", "w_x", "w_y", "w_z", "a_x", "a_y", "a_z"])
    np.testing.assert_array_equal(by_list.gyro, read_imu_csv(f, columns=[1, 2, 3, 4, 5, 6, 7]).gyro)


def test_resample_goes_to_the_nominal_rate_the_measured_one_is_close_to(tmp_path, capsys):
    """EuRoC's training stamps measure 200.0026 Hz: --resample gave 5 ms grids of 4,999,987 ns; a user asks for 200."""
    assert resample_rate({"rate_hz": 200.00256, "sensor": {"rate_hz": 200.0}}) == 200.0
    assert resample_rate({"rate_hz": 199.362, "sensor": {"rate_hz": 199.4}}) == 199.4
    assert resample_rate({"rate_hz": 100.0, "sensor": {"rate_hz": 200.0}}) == 100.0  # not what the data had
    assert resample_rate({"rate_hz": 200.0}) == 200.0 and resample_rate({"sensor": {"rate_hz": 50}}) == 50.0
    cfg = {k: v for k, v in TINY.items() if k != "name"}
    meta = {"rate_hz": 200.00256, "sensor": {"rate_hz": 200.0}}
    model = save_model(random_model(seed=4, **cfg), TINY, tmp_path / "m.pt", meta=meta)
    f = write_asl(tmp_path / "r100.csv", *synth(n=1500, rate=100.0))
    code, out, _ = run([f, "-m", model, "-o", tmp_path / "b", "--resample"], capsys)
    t = np.loadtxt(tmp_path / "b" / "imu_corrected.csv", delimiter=",", dtype=np.int64, usecols=0)
    assert code == 0 and "resampled to 200 Hz" in out and (np.diff(t) == 5_000_000).all()
