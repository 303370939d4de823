"""An IMU at another rate than 200 Hz, or a model used off its training rate: the framework says so, in training,
evaluation, correction and streaming, and resampling down filters instead of aliasing."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from _asl import write_asl_sequence
from _models import random_imu, random_model
from test_correct import model_file, run, synth, write_asl  # noqa: F401 - model_file is a fixture

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.data.datamodule import ImuDataModule
from gyrodenoise.data.imu_csv import ImuRecording, resample
from gyrodenoise.models import build_model
from gyrodenoise.pretrained import load_model, other_rate_warning, save_model
from gyrodenoise.stream_clock import StreamTimeError
from gyrodenoise.streaming import StreamingCorrector


def test_training_sequences_at_different_rates_stop_the_run(tmp_path):
    write_asl_sequence(tmp_path / "slow", seconds=6.0, seed=1, rate_hz=100.0)
    write_asl_sequence(tmp_path / "fast", seconds=6.0, seed=2, rate_hz=400.0)
    dm = ImuDataModule(name="mine", root=str(tmp_path), train_seqs=["slow", "fast"], test_seqs=[], window=256)
    with pytest.raises(ConfigError, match=r"different rates \(fast 400 Hz, slow 100 Hz\)"):
        dm.setup("fit")


@pytest.mark.parametrize(
    ("increments", "nearest"), [([80, 160], "[64, 128]"), ([16, 24], "[16, 32]"), ([0, 16], "[1, 16]")]
)
def test_increments_scaled_to_another_rate_get_the_nearest_powers_of_two(tmp_path, increments, nearest):
    """80/160 ms at 1 kHz, scaled as own-data.md says, printed Hydra's 'Error in call to target ... ValueError'
    naming neither loss.increments nor what to give (own-data walkthrough)."""
    said = (
        re.escape(f"loss.increments={increments}: ") + ".*powers of two.*" + re.escape(f"'loss.increments={nearest}'")
    )
    with pytest.raises(ConfigError, match=said):
        ImuDataModule(name="mine", root=str(tmp_path), train_seqs=["a"], test_seqs=[], increments=increments)


def test_a_test_sequence_at_another_rate_warns(tmp_path):
    write_asl_sequence(tmp_path / "a", seconds=6.0, seed=1)
    write_asl_sequence(tmp_path / "b", seconds=6.0, seed=2, rate_hz=400.0)
    dm = ImuDataModule(name="mine", root=str(tmp_path), train_seqs=["a"], test_seqs=["b"], window=256)
    with pytest.warns(UserWarning, match="b samples at 400 Hz, the training data at 200 Hz"):
        dm.setup(None)


def test_evaluate_names_sequences_off_the_model_rate():
    net, cal = random_model(), build_model("calibrated")
    meta = {"name": "mine", "rate_hz": 200.0}
    msg = other_rate_warning(net, meta, {"a": 201.0, "b": 400.0})
    assert msg is not None and "trained at 200 Hz but b 400 Hz" in msg and "a 201" not in msg
    assert other_rate_warning(net, meta, {"a": 201.0}) is None
    assert other_rate_warning(cal, meta, {"b": 400.0}) is None  # no memory: the rate does not matter
    assert other_rate_warning(net, {"name": "old"}, {"b": 400.0}) is None  # unknown training rate


def test_a_loaded_model_streams_against_its_training_rate(tmp_path):
    path = save_model(random_model(), {"name": "denoiser"}, tmp_path / "m.pt", meta={"rate_hz": 200.0})
    sc = StreamingCorrector(load_model(path)[0])  # the plain constructor, not .load: the file's rate all the same
    imu = random_imu(3)
    sc.push(imu[0], t_ns=0)
    # twice the model's rate: half a period, which the old bound (0.5 periods) let through
    with pytest.raises(StreamTimeError, match="this sample comes 2.5 ms .* look like a 400 Hz stream"):
        sc.push(imu[1], t_ns=2_500_000)
    sc.push(imu[1], t_ns=5_000_000)


def test_downsampling_filters_and_keeps_the_integrated_angle():
    rng = np.random.default_rng(0)
    n = 50_000
    t_ns = np.arange(n, dtype=np.int64) * 1_000_000  # 1 kHz
    gyro = rng.normal(0, 0.1, (n, 3)) + [0.01, 0.2, -0.3]
    rec = ImuRecording(t_ns=t_ns, gyro=gyro, acc=gyro.copy(), lines=np.arange(n), path="x", columns="", units={})
    out = resample(rec, 200.0)
    assert np.all(np.diff(out.t_ns) == 5_000_000)
    # white noise averaged over 5 samples: std / sqrt(5) (point interpolation kept 0.1)
    np.testing.assert_allclose(out.gyro.std(0), 0.1 / np.sqrt(5), rtol=0.1)
    np.testing.assert_allclose(out.gyro.sum(0) * 0.005, gyro.sum(0) * 0.001, atol=2e-3)
    # a slow signal passes unchanged
    slow = np.sin(2 * np.pi * 0.5 * t_ns * 1e-9)[:, None].repeat(3, 1)
    rec_slow = ImuRecording(t_ns=t_ns, gyro=slow, acc=slow, lines=np.arange(n), path="x", columns="", units={})
    expect = np.sin(2 * np.pi * 0.5 * resample(rec_slow, 200.0).t_ns * 1e-9)
    np.testing.assert_allclose(resample(rec_slow, 200.0).gyro[1:-1, 0], expect[1:-1], atol=1e-4)


def test_a_calibrated_model_is_not_told_to_resample(tmp_path, capsys):
    cal = save_model(build_model("calibrated"), {"name": "calibrated"}, tmp_path / "cal.pt", meta={"rate_hz": 200.0})
    t_ns, gyro, acc = synth(n=1500, rate=100.0)
    f = write_asl(tmp_path / "r100.csv", t_ns, gyro, acc)
    code, _, err = run([f, "-m", cal, "-o", tmp_path / "a"], capsys)
    assert code == 0 and "--resample" not in err


def test_increments_shorter_than_two_truth_periods_warn(tmp_path):
    write_asl_sequence(tmp_path / "a", seconds=6.0, seed=1)  # IMU and truth at 200 Hz
    common = {
        "name": "mine",
        "root": str(tmp_path),
        "train_seqs": ["a"],
        "test_seqs": [],
        "window": 256,
        "train_duration_s": 4.0,
    }
    ok = ImuDataModule(**common, increments=(2, 4))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 10 ms: two truth periods, no warning
        ok.setup("fit")
    short = ImuDataModule(**common, increments=(1, 2))
    with pytest.warns(UserWarning, match="shortest loss increment, 1 samples, spans 5 ms .* Lengthen loss.increments"):
        short.setup("fit")


def test_a_calibrated_model_streams_at_any_rate(tmp_path):
    path = save_model(build_model("calibrated"), {"name": "calibrated"}, tmp_path / "c.pt", meta={"rate_hz": 200.0})
    sc = StreamingCorrector(load_model(path)[0])
    imu = random_imu(3)
    for k in range(3):  # 400 Hz: each sample is corrected alone, the rate does not matter
        sc.push(imu[k], t_ns=k * 2_500_000)
